// bench lod: the cost of a frame must not grow with the terrain (Leach & Marais §6; issue 7).
//
// 1. sizes    the same three bodies dropped on the same spot of procedural hills whose grid
//             grows from 512² to 8192² cells (same 0.5 m cells, same origin): wall seconds per
//             simulated second of each run (run_scene, the frame loop only) and per stage
// 2. lod off  the DEM's cost per granule-second measured on those patches (dem stage wall /
//             Σ granules × seconds simulated), times the granules the whole terrain would need
//             as particles: G = area × depth × φ / V_g (V_g = 16/3 π r³ the solid volume of a
//             4-sphere granule, φ the pre-settled tile's packing fraction, depth the manager's
//             patch depth); checked by running small terrains that one patch covers entirely
// 3. idle     the largest terrain with no bodies: heightfield, Bullet and manager bookkeeping
// 4. asleep   one body resting on the smallest terrain; its patch goes to sleep (loosely): the
//             cost of the frames after it is asleep = wall(T2) − wall(T1) over T2 − T1 (two runs of the
//             same deterministic scene; run_scene has no per-frame hook)
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>

#include "bench/bench.hpp"
#include "bench/bench_util.hpp"
#include "manager/run.hpp"
#include "manager/terrain_manager.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;

namespace sandpatch {

namespace {

using ojson = nlohmann::ordered_json;

constexpr double kSpacing = 0.5;      // m per cell
constexpr double kGranuleR = 0.05;    // m, sphere radius of a granule
constexpr double kSoilDepth = 1.0;    // m
constexpr double kHillsHeight = 0.0;  // m, base height
constexpr double kHillsAmplitude = 0.25;
constexpr double kDt = 1.0 / 120.0;

using bench::load_average;

struct Run {
  ojson report;
  double wall_per_sim = 0;       // wall s per simulated s (frame loop)
  double granule_seconds = 0;    // Σ patches granules × s simulated while ready
  double dem_s = 0;              // dem stage wall s
  double outside_loop_s = 0;     // s of run_scene outside the frame loop: terrain, Bullet, pool, tile; the end
};

double stage_ms(const ojson& rep, const char* name) {
  const auto& st = rep["stages"];
  return st.contains(name) ? st[name]["total_ms"].get<double>() : 0.0;
}

Result<Run> run_one(const nlohmann::json& scene_json, double seconds, int threads) {
  const std::string name = scene_json["name"].get<std::string>();
  auto scene = parse_scene(scene_json.dump(), "<bench lod: " + name + ">", "");
  if (!scene) return scene.errors();
  RunOptions o;
  o.out_dir = (fs::temp_directory_path() / "sandpatch_bench_lod" / name).string();
  o.seconds = seconds;
  o.threads = threads;
  o.progress = ProgressStyle::None;
  o.command_line = "sandpatch bench lod (" + name + ")";
  const auto start = std::chrono::steady_clock::now();
  RunResult r = run_scene(*scene, o);
  const double call_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (r.code != ExitCode::Ok) return Error{"<bench lod: " + name + ">", r.stage, "", "run failed", r.message};
  Run out;
  out.report = std::move(r.report);
  const ojson& rep = out.report;
  const double sim = rep["simulated_s"].get<double>();
  out.wall_per_sim = rep["wall_s"].get<double>() / sim;
  out.outside_loop_s = call_s - rep["wall_s"].get<double>();
  out.dem_s = stage_ms(rep, "dem") / 1000.0;
  // Granule-seconds: each patch from "ready" (simulating) to its demotion (the run's end at the latest).
  if (rep.contains("conversions")) {
    std::map<int, std::pair<double, int>> ready;  // patch -> (time, granules)
    for (const auto& c : rep["conversions"]) {
      const int p = c["patch"].get<int>();
      if (c["kind"] == "ready") ready[p] = {c["time_s"].get<double>(), c["granules"].get<int>()};
      if (c["kind"] == "demoted" && ready.count(p)) {
        const auto [t0, g] = ready[p];
        out.granule_seconds += double(g) * std::max(0.0, std::min(c["time_s"].get<double>(), sim) - t0);
        ready.erase(p);
      }
    }
    for (const auto& [p, tg] : ready) out.granule_seconds += double(tg.second) * std::max(0.0, sim - tg.first);
  }
  return out;
}

ojson per_stage_ms_per_sim_s(const ojson& rep) {
  ojson j = ojson::object();
  const double sim = rep["simulated_s"].get<double>();
  for (const auto& [name, t] : rep["stages"].items()) j[name] = t["total_ms"].get<double>() / sim;
  return j;
}

std::string join_stages(const ojson& per_stage) {
  std::string s;
  char buf[64];
  for (const auto& [name, v] : per_stage.items()) {
    std::snprintf(buf, sizeof buf, " %s %.1f", name.c_str(), v.get<double>());
    s += buf;
  }
  return s;
}

}  // namespace

nlohmann::json lod_bench_scene(LodBenchScene kind, int cells, int threads) {
  using json = nlohmann::json;
  const char* names[] = {"drop", "idle", "asleep", "full", "full_slab"};
  json s;
  s["version"] = 1;
  s["name"] = std::string("bench_lod_") + names[int(kind)] + "_" + std::to_string(cells);
  s["description"] = "sandpatch bench lod (bench/bench_lod.cpp): generated";
  json src = {{"type", "procedural"}, {"kind", "hills"}, {"height", kHillsHeight}, {"amplitude", kHillsAmplitude},
              {"wavelength", 16.0}, {"samples_x", cells + 1}, {"samples_z", cells + 1}};
  if (kind == LodBenchScene::Full || kind == LodBenchScene::FullSlab) src = {{"type", "procedural"}, {"kind", "flat"}, {"height", kHillsHeight},
                                          {"samples_x", cells + 1}, {"samples_z", cells + 1}};
  s["terrain"] = {{"source", src}, {"spacing", kSpacing}, {"origin", {0.0, 0.0, 0.0}}, {"soil_depth", kSoilDepth},
                  {"material", "sand"}};
  s["materials"] = json::array({{{"name", "sand"}, {"density", 2650.0}, {"friction", 0.5}, {"restitution", 0.3},
                                 {"stiffness", 5.0e4}, {"granule_radius", kGranuleR}, {"packing_fraction", 0.6}}});
  // World positions (m) fixed for every terrain size: the terrain grows away from them.
  const double top = kHillsHeight + kHillsAmplitude;
  json bodies = json::array();
  switch (kind) {
    case LodBenchScene::Drop:
      bodies.push_back({{"name", "ball"}, {"shape", {{"type", "sphere"}, {"radius", 0.25}}}, {"density", 1000.0},
                        {"pose", {{"position", {20.0, top + 1.0, 20.0}}}}});
      bodies.push_back({{"name", "crate"}, {"shape", {{"type", "box"}, {"half_extents", {0.2, 0.2, 0.2}}}},
                        {"mass", 30.0}, {"pose", {{"position", {26.0, top + 1.0, 20.0}}, {"euler_deg", {0.0, 30.0, 15.0}}}}});
      bodies.push_back({{"name", "drum"}, {"shape", {{"type", "cylinder"}, {"radius", 0.2}, {"height", 0.4}}},
                        {"mass", 30.0}, {"pose", {{"position", {20.0, top + 1.0, 26.0}}}}});
      break;
    case LodBenchScene::Idle: break;
    case LodBenchScene::Asleep:
      // A light ball set down just above the ground: its patch fills, settles and sleeps
      // (a loose sleep threshold, 0.1 m/s held 0.2 s, so that it sleeps within a second or two).
      bodies.push_back({{"name", "ball"}, {"shape", {{"type", "sphere"}, {"radius", 0.25}}}, {"density", 500.0},
                        {"pose", {{"position", {20.0, top + 0.27, 20.0}}}}});
      break;
    case LodBenchScene::Full:
      // The drop's ball over a terrain so small that its patch (footprint + 1 m apron,
      // clipped to the terrain) is the whole terrain.
      bodies.push_back({{"name", "ball"}, {"shape", {{"type", "sphere"}, {"radius", 0.25}}}, {"density", 1000.0},
                        {"pose", {{"position", {0.5 * cells * kSpacing, kHillsHeight + 1.0, 0.5 * cells * kSpacing}}}}});
      break;
    case LodBenchScene::FullSlab: {
      // A slab whose patch is the whole terrain: the granules carry a body everywhere.
      const double half = std::max(0.25, 0.5 * cells * kSpacing - 1.0);
      bodies.push_back({{"name", "slab"}, {"shape", {{"type", "box"}, {"half_extents", {half, 0.1, half}}}},
                        {"mass", 50.0}, {"pose", {{"position", {0.5 * cells * kSpacing, kHillsHeight + 0.3, 0.5 * cells * kSpacing}}}}});
      break;
    }
  }
  s["bodies"] = bodies;
  const bool loose = kind == LodBenchScene::Asleep;
  s["simulation"] = {{"dt", kDt},
                     {"substeps", 1},
                     {"duration", 1.0},
                     {"threads", threads},
                     {"pool", {{"slots", 3}, {"granules_per_slot", 16384}}},
                     {"sleep", {{"speed_threshold", loose ? 0.1 : 0.02}, {"hold_time", loose ? 0.2 : 0.25}}},
                     {"idle_timeout", 1000.0}};
  s["outputs"] = {{"report", false}};
  return s;
}

std::string check_bench_lod_args(const BenchLodArgs& a) {
  if (a.sizes.empty()) return "bench lod: --sizes: give at least one terrain size";
  for (int n : a.sizes)
    if (n < 64 || n > 16384)
      return "bench lod: --sizes = " + std::to_string(n) + ": each size must be a cell count in [64, 16384]";
  for (std::size_t k = 1; k < a.sizes.size(); ++k)
    if (a.sizes[k] <= a.sizes[k - 1])
      return "bench lod: --sizes = " + std::to_string(a.sizes[k]) + " after " + std::to_string(a.sizes[k - 1]) +
             ": sizes must be strictly ascending";
  if (!(a.seconds > 0) || a.seconds > 60)
    return "bench lod: --seconds = " + format_number(a.seconds) + ": must be in (0, 60] simulated seconds";
  if (a.threads < 0) return "bench lod: --threads = " + std::to_string(a.threads) + ": must be >= 0 (0 = all cores)";
  return "";
}

int run_bench_lod(const BenchLodArgs& a) {
  if (std::string e = check_bench_lod_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  const int threads = a.threads > 0 ? a.threads : omp_get_num_procs();
  const double load_before = load_average();
  auto fail = [](const Result<Run>& r) {
    std::fprintf(stderr, "bench lod: %s", r.message().c_str());
    return 1;
  };
    std::printf("bench lod: 3 bodies dropped on hills, %.2f m cells, granule r %.3f m, %.2f s simulated per size, "
                "%d threads, load %.2f\n",
                kSpacing, kGranuleR, a.seconds, threads, load_before);

  // 1. the same bodies on growing terrains
  ojson results = ojson::array();
  double c_dem_s = 0, c_granule_s = 0;  // for the cost per granule-second
  double packing = 0.6;
  for (int n : a.sizes) {
    auto r = run_one(lod_bench_scene(LodBenchScene::Drop, n, threads), a.seconds, threads);
    if (!r) return fail(r);
    const ojson& rep = r->report;
    c_dem_s += r->dem_s;
    c_granule_s += r->granule_seconds;
    if (rep.contains("tile")) packing = rep["tile"]["packing_fraction"].get<double>();
    const ojson stages = per_stage_ms_per_sim_s(rep);
    results.push_back({{"terrain", n},
                       {"samples", std::int64_t(n + 1) * (n + 1)},
                       {"wall_s_per_sim_s", r->wall_per_sim},
                       {"non_dem_s_per_sim_s", r->wall_per_sim - r->dem_s / rep["simulated_s"].get<double>()},
                       {"setup_and_end_s", r->outside_loop_s},
                       {"peak_granules", rep["counts"]["peak_granules"]},
                       {"terrain_tiles", rep["counts"]["terrain_tiles"]},
                       {"frame_median_ms", rep["frames"]["median_ms"]},
                       {"frame_max_ms", rep["frames"]["max_ms"]},
                       {"stage_ms_per_sim_s", stages}});
      std::printf("  %5d² cells: %.3f s wall per simulated s (%.4f outside dem), %d granules at peak, %.1f s outside the "
                  "frame loop (terrain, Bullet, pool; end), stages (ms per simulated s):%s\n",
                  n, r->wall_per_sim, results.back()["non_dem_s_per_sim_s"].get<double>(),
                  rep["counts"]["peak_granules"].get<int>(), r->outside_loop_s, join_stages(stages).c_str());
    std::fflush(stdout);
  }
  const double w0 = results.front()["wall_s_per_sim_s"].get<double>();
  const double w1 = results.back()["wall_s_per_sim_s"].get<double>();
  const double ratio = w0 > 0 ? w1 / w0 : 0;
  // The same outside the dem stage: the DEM's work is the same at every size (same patches, same
  // granules), so its wall time only follows the machine's load; the rest is what could grow.
  const double n0 = results.front()["non_dem_s_per_sim_s"].get<double>();
  const double n1 = results.back()["non_dem_s_per_sim_s"].get<double>();
  const double ratio_non_dem = n0 > 0 ? n1 / n0 : 0;
  // The stage that grew most (ms per simulated s) from the smallest to the largest terrain,
  // leaving out dem (same work at every size: its changes are the machine's load).
  std::string grew;
  double grew_by = -1e300;
  for (const auto& [name, v] : results.back()["stage_ms_per_sim_s"].items()) {
    if (name == "dem") continue;
    const auto& s0 = results.front()["stage_ms_per_sim_s"];
    const double d = v.get<double>() - (s0.contains(name) ? s0[name].get<double>() : 0.0);
    if (d > grew_by) {
      grew_by = d;
      grew = name;
    }
  }

  // 2. LOD off: the whole terrain as particles, extrapolated from the cost per granule-second.
  const double c = c_granule_s > 0 ? c_dem_s / c_granule_s : 0;  // wall s per granule-second
  // The same on quiet patches: the drop stopped before the bodies land (~0.45 s), so the
  // patches only hold still granules (a terrain with nothing on it would be like this).
  double c_quiet = 0;
  {
    auto r = run_one(lod_bench_scene(LodBenchScene::Drop, a.sizes.front(), threads), 0.4, threads);
    if (!r) return fail(r);
    c_quiet = r->granule_seconds > 0 ? r->dem_s / r->granule_seconds : 0;
  }
  const double depth = std::min(TerrainManagerDef{}.patch_depth, kSoilDepth);
  const double vg = 16.0 / 3.0 * std::numbers::pi * std::pow(kGranuleR, 3);
  auto granules_for = [&](int n) { return std::pow(n * kSpacing, 2) * depth * packing / vg; };
  ojson lod_off = {{"formula", "wall_s_per_sim_s = c * G, G = (N * spacing)^2 * depth * phi / (16/3 pi r^3)"},
                   {"c_wall_s_per_granule_s", c},
                   {"c_quiet_wall_s_per_granule_s", c_quiet},
                   {"spacing_m", kSpacing},
                   {"depth_m", depth},
                   {"phi", packing},
                   {"granule_radius_m", kGranuleR}};
  ojson extrap = ojson::array();
  for (int n : a.sizes) {
    const double g = granules_for(n);
    const double lod = std::find_if(results.begin(), results.end(), [&](const ojson& r) { return r["terrain"] == n; })
                           ->at("wall_s_per_sim_s")
                           .get<double>();
    extrap.push_back({{"terrain", n},
                      {"granules", g},
                      {"wall_s_per_sim_s", c * g},
                      {"wall_s_per_sim_s_quiet", c_quiet * g},
                      {"over_lod_on", lod > 0 ? c * g / lod : 0.0}});
  }
  lod_off["estimates"] = extrap;
  {
    std::printf("LOD off (all terrain as particles): c = %.3g wall s per granule-second (dem stage / granule-seconds "
                "of the runs above), %.3g on quiet patches (the smallest run stopped at 0.4 s, before the bodies "
                "land); G = (N x %.2f m)^2 x %.2f m x phi %.3f / (16/3 pi r^3)\n",
                c, c_quiet, kSpacing, depth, packing);
    for (const auto& e : extrap)
      std::printf("  %5d² cells: %.3g granules -> %.3g s wall per simulated s (%.3g quiet; %.3g x LOD on)\n",
                  e["terrain"].get<int>(), e["granules"].get<double>(), e["wall_s_per_sim_s"].get<double>(),
                  e["wall_s_per_sim_s_quiet"].get<double>(), e["over_lod_on"].get<double>());
    std::fflush(stdout);
  }
  // Check: small terrains fully as particles (one patch covers each): the drop's ball on a
  // terrain its patch covers, and a slab that loads the whole patch.
  {
    ojson checks = ojson::array();
    const std::pair<LodBenchScene, int> cases[] = {{LodBenchScene::Full, 4}, {LodBenchScene::FullSlab, 8}};
    for (const auto& [kind, n] : cases) {
      const double secs = a.seconds;  // as long as the drops: the ball lands at ~0.45 s in both
      auto r = run_one(lod_bench_scene(kind, n, threads), secs, threads);
      if (!r) return fail(r);
      const double g_pred = granules_for(n);
      const double g = r->report["counts"]["peak_granules"].get<double>();
      const double sim = r->report["simulated_s"].get<double>();
      const double measured_dem = r->dem_s / sim;
      const double ready_fraction = g > 0 ? r->granule_seconds / (g * sim) : 0;
      const char* what = kind == LodBenchScene::Full ? "ball" : "slab";
      checks.push_back({{"terrain", n},
                        {"body", what},
                        {"granules_predicted", g_pred},
                        {"granules_measured", g},
                        {"dem_s_per_sim_s_predicted", c * g * ready_fraction},
                        {"dem_s_per_sim_s_measured", measured_dem},
                        {"wall_s_per_sim_s_measured", r->wall_per_sim},
                        {"simulated_s", sim}});
        std::printf("  check, %d² cells (%.1f m square) all particles under a %s: %.0f granules predicted, %.0f "
                    "measured; dem %.3g s per simulated s predicted (c x granules x %.2f of the run simulating), %.3g "
                    "measured\n",
                    n, n * kSpacing, what, g_pred, g, c * g * ready_fraction, ready_fraction, measured_dem);
      std::fflush(stdout);
    }
    lod_off["check_full_terrain"] = checks;
  }

  // 3. idle terrain: the largest size, nothing touching it.
  ojson idle;
  {
    const int n = a.sizes.back();
    auto r = run_one(lod_bench_scene(LodBenchScene::Idle, n, threads), std::max(1.0, a.seconds), threads);
    if (!r) return fail(r);
    idle = {{"terrain", n}, {"wall_s_per_sim_s", r->wall_per_sim}, {"frame_median_ms", r->report["frames"]["median_ms"]},
            {"stage_ms_per_sim_s", per_stage_ms_per_sim_s(r->report)}};
      std::printf("idle: %d² cells, no bodies: %.4f s wall per simulated s, frame median %.3f ms, stages:%s\n", n,
                  r->wall_per_sim, r->report["frames"]["median_ms"].get<double>(),
                  join_stages(idle["stage_ms_per_sim_s"]).c_str());
  }

  // 4. a sleeping patch: frames after it fell asleep, by difference of two runs.
  ojson asleep;
  {
    const int n = a.sizes.front();
    const double t1 = 3.0, t2 = 5.0;
    auto r1 = run_one(lod_bench_scene(LodBenchScene::Asleep, n, threads), t1, threads);
    if (!r1) return fail(r1);
    auto r2 = run_one(lod_bench_scene(LodBenchScene::Asleep, n, threads), t2, threads);
    if (!r2) return fail(r2);
    const double window = (r2->report["wall_s"].get<double>() - r1->report["wall_s"].get<double>()) / (t2 - t1);
    const double dem_window = (r2->dem_s - r1->dem_s) / (t2 - t1);
    asleep = {{"terrain", n},
              {"granules", r2->report["counts"]["peak_granules"]},
              {"first_s", t1},
              {"wall_s_per_sim_s_first", r1->wall_per_sim},
              {"wall_s_per_sim_s_after", window},
              {"dem_s_per_sim_s_after", dem_window},
              {"asleep_in_window", window < 0.1 * r1->wall_per_sim}};
      std::printf("asleep: one body resting on %d² cells, a patch of %d granules: %.4f s wall per simulated s over the "
                  "first %.1f s (fill, settle), %.4f s over [%.1f, %.1f] s (dem %.4f)\n",
                  n, r2->report["counts"]["peak_granules"].get<int>(), r1->wall_per_sim, t1, window, t1, t2, dem_window);
    if (!asleep["asleep_in_window"].get<bool>())
      std::printf("asleep: the window costs more than 10 %% of the first %.1f s: the patch was not asleep all of it\n", t1);
  }

  const double load_after = load_average();
  {
    std::printf("wall per simulated s, largest / smallest terrain: %.3f (%d² / %d²): %s; stage that grew most "
                "outside dem: %s (%+.1f ms per simulated s)\n",
                ratio, a.sizes.back(), a.sizes.front(), std::abs(ratio - 1) <= 0.10 ? "within 10 %" : "NOT within 10 %",
                grew.c_str(), grew_by);
    std::printf("outside the dem stage, largest / smallest: %.3f (%.4f / %.4f s per simulated s)\n", ratio_non_dem, n1, n0);
    std::printf("load average %.2f -> %.2f\n", load_before, load_after);
  }
  ojson out = {{"results", results},
               {"lod_off", lod_off},
               {"ratio_largest_over_smallest", ratio},
               {"within_10_pct", std::abs(ratio - 1) <= 0.10},
               {"ratio_outside_dem", ratio_non_dem},
               {"stage_grown_most", {{"stage", grew}, {"ms_per_sim_s", grew_by}}},
               {"idle", idle},
               {"asleep", asleep},
               {"threads", threads},
               {"seconds", a.seconds},
               {"load_average", {load_before, load_after}}};
  if (a.json) std::printf("%s\n", out.dump().c_str());
  return 0;
}

}  // namespace sandpatch
