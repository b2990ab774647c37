// sandpatch stress: many granular simulations sharing the pool (Leach & Marais §6.3, figures
// 10, 12, 14: frame time against time while simulations come, run and fall asleep).
//
// The stress scene: the SCENE's terrain, materials and simulation settings with N copies of its
// first body on a grid around that body's position (same height above the ground), the k-th
// appearing at k × interval; pool.slots = N. Everything runs through run_scene.
//
// Frame times: one run_scene call; its per-frame hook (RunOptions::on_frame) hands over each
// frame's wall time, DEM stage time and patch counts (filling / active / asleep), written per
// frame to OUT/stress.csv and summarised in OUT/stress.json (docs/stress.md). The earlier
// method (K runs of growing length, differenced) is gone: under machine load its windows came
// out negative; --windows is accepted and ignored.
#include <omp.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <vector>

#include "bench/bench.hpp"
#include "bench/bench_util.hpp"
#include "manager/run.hpp"
#include "manager/terrain.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;

namespace sandpatch {

namespace {

using ojson = nlohmann::ordered_json;

double bounding_radius(const BodyDef& b) {
  const api::ShapeDef& s = b.shape;
  switch (s.kind) {
    case ShapeKind::Sphere: return s.radius;
    case ShapeKind::Box: return std::sqrt(s.half_extents[0] * s.half_extents[0] + s.half_extents[1] * s.half_extents[1] +
                                          s.half_extents[2] * s.half_extents[2]);
    case ShapeKind::Cylinder: return std::hypot(s.radius, 0.5 * s.height);
    case ShapeKind::Capsule: return s.radius + 0.5 * s.height;
    case ShapeKind::Mesh: return std::max(0.5, body_extent_below(b));
  }
  return 1.0;
}

using bench::load_average;
using bench::write_text;


}  // namespace

std::string check_stress_args(const StressArgs& a) {
  if (a.scene.empty()) return "stress: SCENE: give a scene file (its terrain, material and first body are used)";
  if (a.sims < 1 || a.sims > 64) return "stress: --sims = " + std::to_string(a.sims) + ": must be in [1, 64]";
  if (a.frames < 1 || a.frames > 1000000)
    return "stress: --frames = " + std::to_string(a.frames) + ": must be in [1, 1000000]";
  if (!(a.interval >= 0) || a.interval > 1e4)
    return "stress: --interval = " + format_number(a.interval) + ": must be in [0, 10000] s";
  if (a.threads < 0) return "stress: --threads = " + std::to_string(a.threads) + ": must be >= 0 (0 = all cores)";
  return "";
}

Result<SceneDef> make_stress_scene(const SceneDef& base, int sims, double interval, long long frames) {
  const std::string where = base.source_path.empty() ? base.name : base.source_path;
  if (base.bodies.empty())
    return Error{where, "bodies", "[]", "at least one body: the stress runner copies the first body"};
  auto hf = load_scene_terrain(base);
  if (!hf) return hf.errors();
  const BodyDef& tpl = base.bodies.front();
  // Grid pitch: the body's patch (its footprint + a 1 m apron each side) plus 2 m between patches.
  const double pitch = 2.0 * bounding_radius(tpl) + 4.0;
  const int cols = int(std::ceil(std::sqrt(double(sims))));
  const int rows = (sims + cols - 1) / cols;
  const double cx = tpl.position[0], cz = tpl.position[2];
  const double ground0 = hf->origin_y() + hf->sample(float(cx - hf->origin_x()), float(cz - hf->origin_z()));
  nlohmann::json s = scene_to_json(base);
  s["name"] = base.name + "_stress_" + std::to_string(sims);
  s["description"] = "sandpatch stress: " + std::to_string(sims) + " copies of '" + tpl.name + "' from " + where +
                     ", one every " + format_number(interval) + " s";
  const nlohmann::json tj = s["bodies"][0];
  nlohmann::json bodies = nlohmann::json::array();
  const double margin = bounding_radius(tpl) + 1.0;
  for (int k = 0; k < sims; ++k) {
    const double x = cx + (k % cols - 0.5 * (cols - 1)) * pitch, z = cz + (k / cols - 0.5 * (rows - 1)) * pitch;
    if (x - margin < hf->origin_x() || x + margin > hf->origin_x() + hf->extent_x() || z - margin < hf->origin_z() ||
        z + margin > hf->origin_z() + hf->extent_z())
      return Error{"", "--sims", std::to_string(sims),
                   "as many bodies as fit on the terrain",
                   "body " + std::to_string(k) + " would be at (" + format_number(x) + ", " + format_number(z) +
                       ") m, off the terrain or within " + format_number(margin) + " m of its edge (grid pitch " +
                       format_number(pitch) + " m)"};
    const double ground = hf->origin_y() + hf->sample(float(x - hf->origin_x()), float(z - hf->origin_z()));
    nlohmann::json b = tj;
    b["name"] = tpl.name + "_" + std::to_string(k);
    b["pose"]["position"] = {x, tpl.position[1] + (ground - ground0), z};
    b["spawn_time"] = tpl.spawn_time + k * interval;
    bodies.push_back(b);
  }
  s["bodies"] = bodies;
  s["simulation"]["pool"]["slots"] = sims;
  s["simulation"]["duration"] = double(frames) * base.simulation.dt;
  s["outputs"] = {{"report", false}};
  return parse_scene(s.dump(), where + " (stress)", "");
}

namespace {

double median_of(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// Mean frame and DEM times of the frames `pick` selects.
ojson class_summary(const std::vector<FrameSample>& s, const std::function<bool(const FrameSample&)>& pick) {
  double frame = 0, dem = 0;
  long long n = 0;
  for (const auto& f : s)
    if (pick(f)) frame += f.frame_ms, dem += f.dem_ms, ++n;
  return {{"frames", n},
          {"frame_ms_mean", n > 0 ? ojson(frame / double(n)) : ojson()},
          {"dem_ms_mean", n > 0 ? ojson(dem / double(n)) : ojson()}};
}

}  // namespace

int run_stress(const StressArgs& a) {
  if (std::string e = check_stress_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  if (a.windows != 0)
    std::fprintf(stderr, "stress: --windows is deprecated and ignored: frame times are measured per frame now "
                         "(docs/stress.md)\n");
  auto base = load_scene_file(a.scene);
  if (!base) {
    std::fprintf(stderr, "stress: %s: invalid scene\n%s", a.scene.c_str(), base.message().c_str());
    return 2;
  }
  auto scene = make_stress_scene(*base, a.sims, a.interval, a.frames);
  if (!scene) {
    std::fprintf(stderr, "stress: %s", scene.message().c_str());
    return 2;
  }
  const fs::path out = a.out_dir.empty() ? fs::path("out") / scene->name : fs::path(a.out_dir);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    std::fprintf(stderr, "stress: --out = %s: cannot create the directory%s\n", out.string().c_str(),
                 ec ? (": " + ec.message()).c_str() : "");
    return 2;
  }
  const int threads = a.threads > 0 ? a.threads : omp_get_num_procs();
  const double dt = scene->simulation.dt;
  const double load_before = load_average();
  std::printf("stress: %d simulations ('%s' every %s s), %lld frames of %.4g s, per-frame timing, %d threads, load %.2f\n",
              a.sims, base->bodies.front().name.c_str(), format_number(a.interval).c_str(), a.frames, dt, threads,
              load_before);
  std::fflush(stdout);

  // One run; every frame's sample through the per-frame hook.
  std::vector<FrameSample> samples;
  samples.reserve(std::size_t(a.frames));
  RunOptions o;
  o.out_dir = (out / "run").string();
  o.frames = a.frames;
  o.threads = threads;
  o.progress = ProgressStyle::None;
  o.command_line = "sandpatch stress " + a.scene;
  o.on_frame = [&](const FrameSample& f) { samples.push_back(f); };
  const double c0 = bench::process_cpu_seconds();
  RunResult r = run_scene(*scene, o);
  const double cpu_s = bench::process_cpu_seconds() - c0;
  std::error_code ignore;
  fs::remove_all(out / "run", ignore);
  if (r.code != ExitCode::Ok) {
    std::fprintf(stderr, "stress: the run failed in stage '%s'\n%s", r.stage.c_str(), r.message.c_str());
    return int(r.code);
  }
  const ojson& rep = r.report;

  auto arrived_at = [&](double t) {  // bodies spawned by simulated time t (end of a frame)
    int n = 0;
    for (const auto& b : scene->bodies) n += b.spawn_time < t - 1e-9;
    return n;
  };
  std::string csv = "frame,time_s,frame_ms,dem_ms,filling,active,asleep,granules,queued,pool_bytes,arrived\n";
  std::vector<double> ms, dem;
  double sum_ms = 0, sum_dem = 0, sim_s_live = 0;
  int peak_live = 0;
  for (const auto& f : samples) {
    char line[256];
    std::snprintf(line, sizeof line, "%lld,%.6f,%.4f,%.4f,%d,%d,%d,%d,%d,%lld,%d\n", f.frame, f.time_s, f.frame_ms,
                  f.dem_ms, f.patches_filling, f.patches_active, f.patches_asleep, f.granules, f.queued_requests,
                  static_cast<long long>(f.pool_bytes), arrived_at(f.time_s));
    csv += line;
    ms.push_back(f.frame_ms);
    dem.push_back(f.dem_ms);
    sum_ms += f.frame_ms;
    sum_dem += f.dem_ms;
    sim_s_live += double(f.patches_active) * dt;
    peak_live = std::max(peak_live, f.patches_filling + f.patches_active + f.patches_asleep);
  }
  const double n = double(std::max<std::size_t>(1, samples.size()));
  const double med = median_of(ms), mx = ms.empty() ? 0 : *std::max_element(ms.begin(), ms.end());
  // "Sleeping costs nothing": frames with at least one patch simulating against frames whose
  // live patches are all asleep (none filling or active, at least one asleep).
  const ojson active = class_summary(samples, [](const FrameSample& f) { return f.patches_active >= 1; });
  const ojson asleep = class_summary(samples, [](const FrameSample& f) {
    return f.patches_asleep >= 1 && f.patches_active == 0 && f.patches_filling == 0;
  });
  const ojson none = class_summary(samples, [](const FrameSample& f) {
    return f.patches_asleep == 0 && f.patches_active == 0 && f.patches_filling == 0;
  });
  auto ratio = [](const ojson& x, const ojson& y, const char* key) {
    return x[key].is_number() && y[key].is_number() && y[key].get<double>() > 0
               ? ojson(x[key].get<double>() / y[key].get<double>())
               : ojson();
  };
  const ojson sleeping = {{"active_frames", active},
                          {"all_asleep_frames", asleep},
                          {"no_patch_frames", none},
                          {"asleep_over_active_frame_ms", ratio(asleep, active, "frame_ms_mean")},
                          {"asleep_over_active_dem_ms", ratio(asleep, active, "dem_ms_mean")}};
  const ojson rtf = {{"run", sum_ms > 0 ? ojson(double(samples.size()) * dt * 1000.0 / sum_ms) : ojson()},
                     {"median_frame", med > 0 ? ojson(dt * 1000.0 / med) : ojson()},
                     {"worst_frame", mx > 0 ? ojson(dt * 1000.0 / mx) : ojson()},
                     {"simulation_seconds_per_wall_second", sum_ms > 0 ? ojson(sim_s_live * 1000.0 / sum_ms) : ojson()}};
  const std::int64_t pool_bytes = samples.empty() ? 0 : samples.back().pool_bytes;
  const int at_rest = rep["counts"]["bodies_at_rest"].get<int>();
  const double load_after = load_average();
  ojson result = {{"scene", {{"name", scene->name}, {"base", a.scene}, {"hash", scene->hash}}},
                  {"sims", a.sims},
                  {"interval_s", a.interval},
                  {"frames", a.frames},
                  {"dt_s", dt},
                  {"threads", threads},
                  {"method", "per frame: one run_scene call, RunOptions::on_frame samples every frame's wall time "
                             "(frame_ms), DEM stage time (dem_ms) and patch counts; per-frame rows in csv"},
                  {"csv", "stress.csv"},
                  {"frame_ms", {{"median", med}, {"max", mx}, {"mean", sum_ms / n}}},
                  {"dem_ms", {{"median", median_of(dem)}, {"max", dem.empty() ? 0.0 : *std::max_element(dem.begin(), dem.end())},
                              {"mean", sum_dem / n}}},
                  {"real_time_factor", rtf},
                  {"sleeping", sleeping},
                  {"peak_live_patches", peak_live},
                  {"bodies_at_rest_at_end", at_rest},
                  {"pool", rep.contains("pool") ? rep["pool"] : ojson()},
                  {"pool_bytes", pool_bytes},
                  {"wall_s", rep["wall_s"]},
                  {"cpu_s", cpu_s},
                  {"conversions", rep.contains("conversions") ? rep["conversions"] : ojson::array()},
                  {"final_state_hash", rep["final_state_hash"]},
                  {"load_average", {load_before, load_after}}};
  if (!write_text(out / "stress.json", result.dump(2) + "\n") || !write_text(out / "stress.csv", csv)) {
    std::fprintf(stderr, "stress: cannot write %s/stress.json or stress.csv\n", out.string().c_str());
    return 1;
  }
  // Ten rows of the series (means over equal runs of frames) for the terminal; every frame is in the CSV.
  std::printf("t (s)            frame ms  (max)     dem ms  filling active asleep\n");
  const std::size_t rows = std::min<std::size_t>(10, samples.size());
  for (std::size_t k = 0; k < rows; ++k) {
    const std::size_t b = samples.size() * k / rows, e = samples.size() * (k + 1) / rows;
    double fm = 0, fx = 0, dm = 0;
    for (std::size_t i = b; i < e; ++i) fm += samples[i].frame_ms, fx = std::max(fx, samples[i].frame_ms), dm += samples[i].dem_ms;
    const double c = double(std::max<std::size_t>(1, e - b));
    const FrameSample& l = samples[e - 1];
    std::printf("%6.2f-%6.2f  %9.3f %8.2f  %9.3f  %6d %6d %6d\n", b * dt, e * dt, fm / c, fx, dm / c, l.patches_filling,
                l.patches_active, l.patches_asleep);
  }
  auto num = [](const ojson& v) { return v.is_number() ? v.get<double>() : std::nan(""); };
  std::printf("frame ms: median %.3f, max %.3f; real-time factor %.2f (run), %.2f (median frame)\n", med, mx,
              num(rtf["run"]), num(rtf["median_frame"]));
  std::printf("sleeping: %lld all-asleep frames %.3f ms (dem %.4f ms) vs %lld active frames %.3f ms (dem %.3f ms): "
              "ratio %.3f (dem %.4f)\n",
              asleep["frames"].get<long long>(), num(asleep["frame_ms_mean"]), num(asleep["dem_ms_mean"]),
              active["frames"].get<long long>(), num(active["frame_ms_mean"]), num(active["dem_ms_mean"]),
              num(sleeping["asleep_over_active_frame_ms"]), num(sleeping["asleep_over_active_dem_ms"]));
  std::printf("pool: %lld bytes fixed capacity; %d of %d bodies at rest at the end\n", static_cast<long long>(pool_bytes),
              at_rest, a.sims);
  std::printf("data: %s, %s\n", (out / "stress.json").string().c_str(), (out / "stress.csv").string().c_str());
  // Plots (python3 + matplotlib, scripts/plot_frames.py); the data stands without them.
  if (!a.plot_script.empty()) {
    std::fflush(stdout);  // the script's output after ours
    // Debian's python3 (where python3-matplotlib installs) before whatever python3 is first on PATH.
    const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    const std::string cmd = python + " '" + a.plot_script + "' '" + (out / "stress.json").string() + "' '" +
                            (out / "frame_time.png").string() + "' 2>&1";
    const int status = std::system(cmd.c_str());
    const int rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (rc == 0)
      std::printf("plot: %s\n", (out / "frame_time.png").string().c_str());
    else
      std::printf("plot: not made (%s %s exited with %d%s); the data above is written. Plots need python3 and "
                  "matplotlib: apt-get install python3-matplotlib (scripts/install-deps.sh)\n",
                  python.c_str(), a.plot_script.c_str(), rc,
                  rc == 3 ? ": matplotlib missing" : rc == 127 ? ": python3 missing" : "");
  }
  if (a.json) std::printf("%s\n", result.dump().c_str());
  return 0;
}

}  // namespace sandpatch
