// sandpatch stress: many granular simulations sharing the pool (Leach & Marais §6.3, figures
// 10, 12, 14: frame time against time while simulations come, run and fall asleep).
//
// The stress scene: the SCENE's terrain, materials and simulation settings with N copies of its
// first body on a grid around that body's position (same height above the ground), the k-th
// appearing at k × interval; pool.slots = N. Everything runs through run_scene.
//
// Frame times: run_scene reports whole runs only (no per-frame hook yet, see docs/stress.md), so
// the series is made of K windows: K runs of the same deterministic scene, the k-th stopping at
// k/K of the frames; window k's frame time is the difference of the k-th and (k−1)-th runs' wall
// time (and of each stage's) over the frames between them. Live simulations come from the
// longest run's promotions and demotions.
#include <omp.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "bench/bench.hpp"
#include "manager/run.hpp"
#include "manager/terrain.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;

namespace sandpatch {

namespace {

using ojson = nlohmann::ordered_json;

double bounding_radius(const BodyDef& b) {
  const ShapeDef& s = b.shape;
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

double load_average() {
  double l = 0;
  std::ifstream f("/proc/loadavg");
  f >> l;
  return l;
}

// CPU seconds (user + system, all threads) of this process so far.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

bool write_text(const fs::path& p, const std::string& text) {
  const fs::path tmp = p.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    if (!f.flush()) return false;
  }
  std::error_code ec;
  fs::rename(tmp, p, ec);
  return !ec;
}

}  // namespace

std::string check_stress_args(const StressArgs& a) {
  if (a.scene.empty()) return "stress: SCENE: give a scene file (its terrain, material and first body are used)";
  if (a.sims < 1 || a.sims > 64) return "stress: --sims = " + std::to_string(a.sims) + ": must be in [1, 64]";
  if (a.frames < 1 || a.frames > 1000000)
    return "stress: --frames = " + std::to_string(a.frames) + ": must be in [1, 1000000]";
  if (!(a.interval >= 0) || a.interval > 1e4)
    return "stress: --interval = " + format_number(a.interval) + ": must be in [0, 10000] s";
  if (a.windows < 1 || a.windows > 100) return "stress: --windows = " + std::to_string(a.windows) + ": must be in [1, 100]";
  if (a.windows > a.frames)
    return "stress: --windows = " + std::to_string(a.windows) + ": must be at most --frames (" + std::to_string(a.frames) + ")";
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
  const double cx = tpl.pose.position[0], cz = tpl.pose.position[2];
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
    b["pose"]["position"] = {x, tpl.pose.position[1] + (ground - ground0), z};
    b["spawn_time"] = tpl.spawn_time + k * interval;
    bodies.push_back(b);
  }
  s["bodies"] = bodies;
  s["simulation"]["pool"]["slots"] = sims;
  s["simulation"]["duration"] = double(frames) * base.simulation.dt;
  s["outputs"] = {{"report", false}};
  return parse_scene(s.dump(), where + " (stress)", "");
}

int run_stress(const StressArgs& a) {
  if (std::string e = check_stress_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
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
  std::printf("stress: %d simulations ('%s' every %s s), %lld frames of %.4g s, %d windows (%d runs), %d threads, load %.2f\n",
              a.sims, base->bodies.front().name.c_str(), format_number(a.interval).c_str(), a.frames, dt, a.windows,
              a.windows, threads, load_before);
  std::fflush(stdout);

  // A one-frame run first: the CPU time of the set-up (terrain, pool, pre-settled tile) and the
  // end, which every run spends and the first window must not count.
  double cpu_base = 0;
  {
    RunOptions o;
    o.out_dir = (out / "runs").string();
    o.frames = 1;
    o.threads = threads;
    o.progress = ProgressStyle::None;
    const double c0 = cpu_seconds();
    RunResult r = run_scene(*scene, o);
    cpu_base = cpu_seconds() - c0;
    if (r.code != ExitCode::Ok) {
      std::fprintf(stderr, "stress: the one-frame run failed in stage '%s'\n%s", r.stage.c_str(), r.message.c_str());
      return int(r.code);
    }
  }
  // K runs of growing length.
  std::vector<ojson> reports;
  std::vector<long long> ends;
  std::vector<double> cpu;  // CPU s of each whole run_scene call (set-up and end included: they cancel between runs)
  for (int k = 1; k <= a.windows; ++k) {
    const long long f = a.frames * k / a.windows;
    RunOptions o;
    o.out_dir = (out / "runs").string();
    o.frames = f;
    o.threads = threads;
    o.progress = ProgressStyle::None;
    o.command_line = "sandpatch stress " + a.scene + " (run " + std::to_string(k) + " of " + std::to_string(a.windows) + ")";
    const double c0 = cpu_seconds();
    RunResult r = run_scene(*scene, o);
    cpu.push_back(cpu_seconds() - c0);
    if (r.code != ExitCode::Ok) {
      std::fprintf(stderr, "stress: run %d of %d failed in stage '%s'\n%s", k, a.windows, r.stage.c_str(), r.message.c_str());
      return int(r.code);
    }
    reports.push_back(std::move(r.report));
    ends.push_back(f);
    std::printf("  run %d/%d: %lld frames in %.2f s wall (frame loop), %.2f s CPU (whole run)\n", k, a.windows, f,
                reports.back()["wall_s"].get<double>(), cpu.back());
    std::fflush(stdout);
  }
  std::error_code ignore;
  fs::remove_all(out / "runs", ignore);

  // Live simulations from the longest run's events (its end-of-run demotions excluded).
  const ojson& last = reports.back();
  const double t_end = double(a.frames) * dt;
  std::vector<double> ready_t, demoted_t;
  if (last.contains("conversions"))
    for (const auto& c : last["conversions"]) {
      if (c["kind"] == "ready") ready_t.push_back(c["time_s"].get<double>());
      if (c["kind"] == "demoted" && c["time_s"].get<double>() < t_end - 0.5 * dt) demoted_t.push_back(c["time_s"].get<double>());
    }
  auto live_at = [&](double t) {
    return int(std::count_if(ready_t.begin(), ready_t.end(), [&](double x) { return x <= t; })) -
           int(std::count_if(demoted_t.begin(), demoted_t.end(), [&](double x) { return x <= t; }));
  };
  auto arrived_at = [&](double t) {
    int n = 0;
    for (const auto& b : scene->bodies) n += b.spawn_time <= t + 1e-9;
    return n;
  };
  ojson windows = ojson::array();
  std::string csv = "t0_s,t1_s,frames,frame_ms_mean,frame_cpu_ms_mean,real_time_factor,bodies_arrived,simulations_live,dem_ms_per_frame,"
                    "activation_ms_per_frame,other_ms_per_frame\n";
  double prev_wall = 0;
  long long prev_f = 0;
  ojson prev_stages = ojson::object();
  for (std::size_t k = 0; k < reports.size(); ++k) {
    const ojson& rep = reports[k];
    const long long nf = ends[k] - prev_f;
    const double wall = rep["wall_s"].get<double>();
    const double ms = nf > 0 ? (wall - prev_wall) * 1000.0 / double(nf) : 0.0;
    // CPU time is less sensitive to other processes on a shared machine than wall time
    // (it still counts OpenMP threads waiting at barriers while spinning).
    const long long ncf = k > 0 ? nf : nf - 1;  // the baseline run did the first frame
    const double cpu_ms = ncf > 0 ? (cpu[k] - (k > 0 ? cpu[k - 1] : cpu_base)) * 1000.0 / double(ncf) : 0.0;
    const double t0 = double(prev_f) * dt, t1 = double(ends[k]) * dt;
    ojson st = ojson::object();
    for (const auto& [name, v] : rep["stages"].items()) {
      const double before = prev_stages.contains(name) ? prev_stages[name].get<double>() : 0.0;
      st[name] = nf > 0 ? (v["total_ms"].get<double>() - before) / double(nf) : 0.0;
    }
    // The demotion stage also holds each run's end-of-run demotion of every live patch (outside
    // the frame loop's wall time), so a window's demotion and outputs differences are not the
    // frames' own; "other" is the frame time minus dem and activation.
    const double dem = st.contains("dem") ? st["dem"].get<double>() : 0.0;
    const double act = st.contains("activation") ? st["activation"].get<double>() : 0.0;
    const double t_last = t1 - 0.5 * dt;  // the window's last frame (a body arriving at t1 belongs to the next)
    ojson w = {{"t0_s", t0},
               {"t1_s", t1},
               {"frames", nf},
               {"frame_ms_mean", ms},
               {"frame_cpu_ms_mean", cpu_ms},
               {"real_time_factor", ms > 0 ? dt * 1000.0 / ms : 0.0},
               {"bodies_arrived", arrived_at(t_last)},
               {"simulations_live", live_at(t_last)},
               {"simulations_asleep", nullptr},
               {"stage_ms_per_frame", st}};
    windows.push_back(w);
    char line[512];
    std::snprintf(line, sizeof line, "%.4f,%.4f,%lld,%.4f,%.4f,%.5f,%d,%d,%.4f,%.4f,%.4f\n", t0, t1, nf, ms, cpu_ms,
                  w["real_time_factor"].get<double>(), arrived_at(t_last), live_at(t_last), dem, act, std::max(0.0, ms - dem - act));
    csv += line;
    prev_wall = wall;
    prev_f = ends[k];
    for (const auto& [name, v] : rep["stages"].items()) prev_stages[name] = v["total_ms"].get<double>();
  }
  // Sleeping simulations: the last window (every body arrived long before) against the busiest.
  double busiest = 0, busiest_cpu = 0;
  for (const auto& w : windows) {
    busiest = std::max(busiest, w["frame_ms_mean"].get<double>());
    busiest_cpu = std::max(busiest_cpu, w["frame_cpu_ms_mean"].get<double>());
  }
  const double last_ms = windows.back()["frame_ms_mean"].get<double>();
  const double last_cpu = windows.back()["frame_cpu_ms_mean"].get<double>();
  const int at_rest = last["counts"]["bodies_at_rest"].get<int>();
  ojson sleep = {{"last_window_frame_ms", last_ms},
                 {"busiest_window_frame_ms", busiest},
                 {"last_over_busiest", busiest > 0 ? last_ms / busiest : 0.0},
                 {"last_window_cpu_ms", last_cpu},
                 {"busiest_window_cpu_ms", busiest_cpu},
                 {"bodies_at_rest_at_end", at_rest},
                 {"simulations_live_at_end", live_at(t_end)}};
  const double load_after = load_average();
  ojson result = {{"scene", {{"name", scene->name}, {"base", a.scene}, {"hash", scene->hash}}},
                  {"sims", a.sims},
                  {"interval_s", a.interval},
                  {"frames", a.frames},
                  {"dt_s", dt},
                  {"threads", threads},
                  {"method", "windows: " + std::to_string(a.windows) +
                                 " runs of the same deterministic scene, window k = run k minus run k-1 in frame-loop "
                                 "wall time and in process CPU time (a one-frame run takes the set-up off the first); "
                                 "run_scene has no per-frame hook; per-frame times, asleep counts and pool bytes need one"},
                  {"windows", windows},
                  {"sleeping", sleep},
                  {"pool", last.contains("pool") ? last["pool"] : ojson()},
                  {"pool_bytes", nullptr},
                  {"conversions", last.contains("conversions") ? last["conversions"] : ojson::array()},
                  {"final_state_hash", last["final_state_hash"]},
                  {"load_average", {load_before, load_after}}};
  if (!write_text(out / "stress.json", result.dump(2) + "\n") || !write_text(out / "stress.csv", csv)) {
    std::fprintf(stderr, "stress: cannot write %s/stress.json or stress.csv\n", out.string().c_str());
    return 1;
  }
  std::printf("window  t (s)          frame ms   CPU ms  live  arrived\n");
  for (const auto& w : windows)
    std::printf("        %6.2f-%6.2f  %9.3f  %7.2f  %4d  %4d\n", w["t0_s"].get<double>(), w["t1_s"].get<double>(),
                w["frame_ms_mean"].get<double>(), w["frame_cpu_ms_mean"].get<double>(), w["simulations_live"].get<int>(),
                w["bodies_arrived"].get<int>());
  std::printf("sleeping: last window %.3f ms per frame (%.2f ms CPU), busiest %.3f ms (%.2f ms CPU); %d of %d bodies at "
              "rest at the end\n",
              last_ms, last_cpu, busiest, busiest_cpu, at_rest, a.sims);
  std::printf("data: %s, %s\n", (out / "stress.json").string().c_str(), (out / "stress.csv").string().c_str());
  // Plots (python3 + matplotlib, scripts/plot_frames.py); the data stands without them.
  if (!a.plot_script.empty()) {
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
