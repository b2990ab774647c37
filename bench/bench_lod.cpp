// bench lod: the cost of a frame must not grow with the terrain (Leach & Marais §6).
//
// 1. sizes    the same three bodies dropped on the same spot of procedural hills whose grid
//             grows from 512² to 8192² cells (same 0.5 m cells, same origin). Every size is
//             set up first, in this one process, then all are advanced in turn, a short window
//             of simulated time each (round robin; the order rotates every round), until each
//             has simulated --seconds. So every size sees the same machine load, minute by
//             minute: on a shared machine, runs one after the other mostly measure the load's
//             drift. Per size: wall and CPU seconds per simulated second of the frame loop, per
//             stage, and, per window, the wall time over the smallest size's in the same round
//             (same simulated interval, seconds apart); set-up (terrain, Bullet, manager) and the
//             end-of-run demotion are timed apart.
// 2. lod off  the DEM's cost per granule-second measured on those patches (dem stage wall /
//             Σ granules × seconds simulated), times the granules the whole terrain would need
//             as particles: G = area × depth × φ / V_g (V_g = 16/3 π r³ the solid volume of a
//             4-sphere granule, φ the pre-settled tile's packing fraction, depth the manager's
//             patch depth); checked by running small terrains that one patch covers entirely
// 3. idle     the largest terrain with no bodies: heightfield, Bullet and manager bookkeeping
// 4. asleep   one body resting on the smallest terrain; its patch fills, settles and sleeps:
//             frames are advanced until every live patch is asleep, then one more simulated
//             second is timed.
//
// Each size is a World (manager/world.hpp) made from its scene as `sandpatch run` makes it,
// stepped by World::step (the frame of run_scene without outputs), so the stages timed are the
// same named stages (manager/profile.hpp); several are held open at once.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <memory>
#include <numbers>

#include "bench/bench.hpp"
#include "bench/bench_util.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/scene_world.hpp"
#include "manager/terrain.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/world.hpp"
#include "scene/scene.hpp"

namespace sandpatch {

namespace {

using ojson = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

constexpr double kSpacing = 0.5;      // m per cell
constexpr double kGranuleR = 0.05;    // m, sphere radius of a granule
constexpr double kSoilDepth = 1.0;    // m
constexpr double kHillsHeight = 0.0;  // m, base height
constexpr double kHillsAmplitude = 0.25;
constexpr double kDt = 1.0 / 120.0;
constexpr double kQuietUntil = 0.4;   // s: the drop's bodies land at ~0.45 s; before, the patches are quiet

using bench::load_average;
using bench::process_cpu_seconds;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Peak resident memory of this process (MB, /proc/self/status VmHWM); 0 where unreadable.
double peak_rss_mb() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// One scene held open: its World (terrain, Bullet world, manager, stage profile).
struct Lane {
  std::string name;
  int cells = 0;
  SceneDef scene;
  std::unique_ptr<World> world;
  TerrainManager* manager = nullptr;    // the world's
  long long frame = 0;
  double dt = kDt;
  // s: set-up, by part, and the end-of-run demotion
  double setup_terrain_s = 0, setup_bullet_s = 0, setup_manager_s = 0, end_s = 0;
  double wall_s = 0, cpu_s = 0;          // frame loop, all windows
  std::vector<double> window_wall_s, window_cpu_s, frame_ms;
  double dem_ms_quiet = -1;              // dem stage total when kQuietUntil was reached
  int peak_granules = 0;

  double simulated_s() const { return double(frame) * dt; }
  double dem_s() const { return world->profile().timer(Stage::Dem).total_ms / 1000.0; }
};

Result<std::unique_ptr<Lane>> make_lane(const nlohmann::json& scene_json, int cells, int threads) {
  auto lane = std::make_unique<Lane>();
  lane->name = scene_json["name"].get<std::string>();
  lane->cells = cells;
  auto scene = parse_scene(scene_json.dump(), "<bench lod: " + lane->name + ">", "");
  if (!scene) return scene.errors();
  lane->scene = std::move(*scene);
  const SceneDef& s = lane->scene;
  lane->dt = s.simulation.dt;
  auto t0 = Clock::now();
  auto hf = load_scene_terrain(s);
  if (!hf) return hf.errors();
  lane->setup_terrain_s = seconds_since(t0);
  const TerrainManagerDef md = manager_def(s, *hf, threads, "cpu");
  t0 = Clock::now();
  const Vec3d& g = s.terrain.gravity;
  auto world = World::create(std::move(*hf), Eigen::Vector3f(float(g[0]), float(g[1]), float(g[2])));
  if (!world) return world.errors();
  lane->world = std::move(*world);
  lane->setup_bullet_s = seconds_since(t0);
  t0 = Clock::now();
  if (Status st = lane->world->enable_patches(md); !st) return st.errors();
  lane->manager = lane->world->manager();
  lane->setup_manager_s = seconds_since(t0);
  for (std::size_t i = 0; i < s.bodies.size(); ++i) {
    auto d = to_rigid_body(s, i);
    if (!d) return d.errors();
    lane->world->schedule_body(*d, s.bodies[i].spawn_time);
  }
  return lane;
}

// Advances a lane by `frames` frames (the frame of run_scene, without outputs).
Status advance(Lane& l, long long frames) {
  const auto w0 = Clock::now();
  const double c0 = process_cpu_seconds();
  const long long quiet_frame = std::llround(kQuietUntil / l.dt);
  for (long long k = 0; k < frames; ++k, ++l.frame) {
    const auto f0 = Clock::now();
    if (Status st = l.world->step(l.dt, l.scene.simulation.substeps); !st) return st;
    l.peak_granules = std::max(l.peak_granules, l.manager->granules());
    {
      auto timer = l.world->profile().time(Stage::Outputs);
      (void)l.world->take_dirty_regions();  // what a renderer would take
    }
    l.frame_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - f0).count());
    if (l.frame + 1 == quiet_frame) l.dem_ms_quiet = l.world->profile().timer(Stage::Dem).total_ms;
  }
  const double wall = seconds_since(w0), cpu = process_cpu_seconds() - c0;
  l.wall_s += wall;
  l.cpu_s += cpu;
  l.window_wall_s.push_back(wall);
  l.window_cpu_s.push_back(cpu);
  return Ok{};
}

// Granule-seconds: each patch from "ready" (simulating) to its demotion (or `until`).
double granule_seconds(const Lane& l, double until) {
  std::map<int, std::pair<double, int>> ready;  // patch -> (time, granules)
  double gs = 0;
  for (const auto& e : l.manager->events()) {
    if (e.kind == PatchEventKind::Ready) ready[e.patch] = {e.time, e.granules};
    if (e.kind == PatchEventKind::Demoted && ready.count(e.patch)) {
      const auto [t0, g] = ready[e.patch];
      gs += double(g) * std::max(0.0, std::min(e.time, until) - t0);
      ready.erase(e.patch);
    }
  }
  for (const auto& [p, tg] : ready) gs += double(tg.second) * std::max(0.0, until - tg.first);
  return gs;
}

ojson stages_per_sim_s(const Lane& l) {
  ojson j = ojson::object();
  const double sim = l.simulated_s();
  const ojson profile = l.world->profile().to_json();
  for (const auto& [name, t] : profile.items()) j[name] = t["total_ms"].get<double>() / sim;
  return j;
}

ojson bullet_stats(const BulletWorld& w) {
  const BulletWorld::Stats s = w.stats();
  return {{"tiles", s.tiles},
          {"aabb_updates_per_step", s.aabb_updates_per_step},
          {"dynamic_proxies", s.dynamic_proxies},
          {"fixed_proxies", s.fixed_proxies},
          {"pairs", s.pairs},
          {"edge_maps", s.edge_maps}};
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

// A lane run alone for `seconds` (the checks, idle): its frame loop and stages.
Result<std::unique_ptr<Lane>> run_alone(const nlohmann::json& scene_json, int cells, int threads, double seconds) {
  auto lane = make_lane(scene_json, cells, threads);
  if (!lane) return lane.errors();
  if (Status st = advance(**lane, std::max(1LL, std::llround(seconds / (*lane)->dt))); !st) return st.errors();
  return lane;
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
  for (auto& b : bodies) b["restitution"] = 0.2;  // against the heightfield, as every result here was measured
  s["bodies"] = bodies;
  const bool loose = kind == LodBenchScene::Asleep;
  s["simulation"] = {{"dt", kDt},
                     {"substeps", 1},
                     {"duration", 1.0},
                     {"threads", threads},
                     {"pool", {{"slots", 3}, {"granules_per_slot", 16384}}},
                     {"sleep", {{"speed_threshold", loose ? 0.1 : 0.02}, {"hold_time", loose ? 0.2 : 0.25}}},
                     {"idle_timeout", 1000.0},
                     // The same patches at every size (the bench compares their DEM state):
                     // no frame budget, whose choices follow the clock.
                     {"frame_budget_ms", "off"}};
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
  if (!(a.window >= kDt - 1e-12) || a.window > a.seconds + 1e-12)
    return "bench lod: --window = " + format_number(a.window) + ": must be in [" + format_number(kDt) +
           ", --seconds] simulated seconds (one frame at least)";
  if (a.threads < 0) return "bench lod: --threads = " + std::to_string(a.threads) + ": must be >= 0 (0 = all cores)";
  return "";
}

int run_bench_lod(const BenchLodArgs& a) {
  if (std::string e = check_bench_lod_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  const auto t_start = Clock::now();
  const int threads = a.threads > 0 ? a.threads : omp_get_num_procs();
  omp_set_num_threads(threads);
  const double load_before = load_average();
  auto fail = [](const std::string& what, const std::string& msg) {
    std::fprintf(stderr, "bench lod: %s: %s", what.c_str(), msg.c_str());
    return 1;
  };
  const long long total_frames = std::max(1LL, std::llround(a.seconds / kDt));
  const long long window_frames = std::max(1LL, std::llround(a.window / kDt));
  const long long rounds = (total_frames + window_frames - 1) / window_frames;
  std::printf("bench lod: 3 bodies dropped on hills, %.2f m cells, granule r %.3f m, %.3f s simulated per size in %lld "
              "windows of %lld frames (round robin over the sizes, all set up first), %d threads, load %.2f%s\n",
              kSpacing, kGranuleR, double(total_frames) * kDt, rounds, window_frames, threads, load_before,
              a.quick ? " (--quick: no full-terrain checks, no sleeping patch)" : "");
  std::fflush(stdout);

  // 1. the same bodies on growing terrains: set up every size, then advance them in turn.
  std::vector<std::unique_ptr<Lane>> lanes;
  for (int n : a.sizes) {
    auto lane = make_lane(lod_bench_scene(LodBenchScene::Drop, n, threads), n, threads);
    if (!lane) return fail("set-up " + std::to_string(n), lane.message());
    const Lane& l = **lane;
    std::printf("  set up %5d² cells: terrain %.2f s, Bullet %.2f s (%d tiles), manager %.2f s; peak RSS %.0f MB\n", n,
                l.setup_terrain_s, l.setup_bullet_s, l.world->bullet().terrain_tile_count(), l.setup_manager_s, peak_rss_mb());
    std::fflush(stdout);
    lanes.push_back(std::move(*lane));
  }
  const std::size_t nl = lanes.size();
  double load_min = load_before, load_max = load_before;
  for (long long r = 0; r < rounds; ++r) {
    const long long frames = std::min(window_frames, total_frames - r * window_frames);
    for (std::size_t k = 0; k < nl; ++k) {
      Lane& l = *lanes[(std::size_t(r) + k) % nl];  // rotate the order each round
      if (Status st = advance(l, frames); !st) return fail(l.name, st.message());
    }
    const double load = load_average();
    load_min = std::min(load_min, load);
    load_max = std::max(load_max, load);
    if (!a.json && (r + 1) % std::max(1LL, rounds / 10) == 0)
      std::fprintf(stderr, "bench lod: round %lld / %lld, %.0f s, load %.2f\n", r + 1, rounds, seconds_since(t_start), load);
  }
  ojson results = ojson::array();
  double c_dem_s = 0, c_granule_s = 0, q_dem_s = 0, q_granule_s = 0;
  double packing = 0.6;
  const Lane& small = *lanes.front();
  for (const auto& lp : lanes) {
    Lane& l = *lp;
    const double sim = l.simulated_s();
    const double gs = granule_seconds(l, sim);
    c_dem_s += l.dem_s();
    c_granule_s += gs;
    if (l.dem_ms_quiet >= 0) {
      q_dem_s += l.dem_ms_quiet / 1000.0;
      q_granule_s += granule_seconds(l, kQuietUntil);
    }
    const ojson rep = l.manager->report();
    if (rep.contains("tile") && rep["tile"].contains("packing_fraction")) packing = rep["tile"]["packing_fraction"].get<double>();
    std::vector<double> ratio;  // this size's window wall over the smallest's, same round
    for (std::size_t r = 0; r < l.window_wall_s.size(); ++r)
      if (small.window_wall_s[r] > 0) ratio.push_back(l.window_wall_s[r] / small.window_wall_s[r]);
    const ojson stages = stages_per_sim_s(l);
    const ojson bullet = bullet_stats(l.world->bullet());
    const std::uint64_t dem_hash = l.manager->state_hash();
    const auto end0 = Clock::now();
    if (Status st = l.world->demote_all(); !st) return fail(l.name, st.message());
    l.end_s = seconds_since(end0);
    char hex[24];
    std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(dem_hash));
    results.push_back({{"terrain", l.cells},
                       {"samples", std::int64_t(l.cells + 1) * (l.cells + 1)},
                       {"wall_s_per_sim_s", l.wall_s / sim},
                       {"cpu_s_per_sim_s", l.cpu_s / sim},
                       {"non_dem_s_per_sim_s", (l.wall_s - l.dem_s()) / sim},
                       {"window_wall_over_smallest", {{"median", median(ratio)},
                                                      {"min", ratio.empty() ? 0 : *std::min_element(ratio.begin(), ratio.end())},
                                                      {"max", ratio.empty() ? 0 : *std::max_element(ratio.begin(), ratio.end())},
                                                      {"windows", ratio.size()}}},
                       {"setup_s", {{"terrain", l.setup_terrain_s}, {"bullet", l.setup_bullet_s}, {"manager", l.setup_manager_s},
                                    {"total", l.setup_terrain_s + l.setup_bullet_s + l.setup_manager_s}}},
                       {"end_demotion_s", l.end_s},
                       {"simulated_s", sim},
                       {"peak_granules", l.peak_granules},
                       {"terrain_tiles", l.world->bullet().terrain_tile_count()},
                       {"bullet", bullet},
                       {"dem_state_hash", hex},
                       {"frame_median_ms", median(l.frame_ms)},
                       {"frame_max_ms", l.frame_ms.empty() ? 0 : *std::max_element(l.frame_ms.begin(), l.frame_ms.end())},
                       {"stage_ms_per_sim_s", stages}});
    const ojson& res = results.back();
    std::printf("  %5d² cells: %.3f s wall (%.3f s CPU) per simulated s, %.4f outside dem; window / smallest's: median %.3f "
                "[%.3f, %.3f]; %d granules at peak; set-up %.2f s, end %.2f s; Bullet: %d tiles, %d bounds updated a step, "
                "%d edge maps; stages (ms per simulated s):%s\n",
                l.cells, res["wall_s_per_sim_s"].get<double>(), res["cpu_s_per_sim_s"].get<double>(),
                res["non_dem_s_per_sim_s"].get<double>(), res["window_wall_over_smallest"]["median"].get<double>(),
                res["window_wall_over_smallest"]["min"].get<double>(), res["window_wall_over_smallest"]["max"].get<double>(),
                l.peak_granules, res["setup_s"]["total"].get<double>(), l.end_s, bullet["tiles"].get<int>(),
                bullet["aabb_updates_per_step"].get<int>(), bullet["edge_maps"].get<int>(), join_stages(stages).c_str());
    std::fflush(stdout);
  }
  bool same_dem = true;
  for (const auto& r : results) same_dem = same_dem && r["dem_state_hash"] == results.front()["dem_state_hash"];
  const double peak_rss_sizes = peak_rss_mb();
  lanes.clear();

  auto ratio_of = [&](const char* key) {
    const double v0 = results.front()[key].get<double>(), v1 = results.back()[key].get<double>();
    return v0 > 0 ? v1 / v0 : 0.0;
  };
  const double ratio = ratio_of("wall_s_per_sim_s");
  const double ratio_cpu = ratio_of("cpu_s_per_sim_s");
  const double ratio_non_dem = ratio_of("non_dem_s_per_sim_s");
  const double ratio_window = results.back()["window_wall_over_smallest"]["median"].get<double>();
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
  const double c = c_granule_s > 0 ? c_dem_s / c_granule_s : 0;            // wall s per granule-second
  const double c_quiet = q_granule_s > 0 ? q_dem_s / q_granule_s : 0;      // the same before the bodies land
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
  for (const auto& r : results) {
    const int n = r["terrain"].get<int>();
    const double g = granules_for(n), lod = r["wall_s_per_sim_s"].get<double>();
    extrap.push_back({{"terrain", n},
                      {"granules", g},
                      {"wall_s_per_sim_s", c * g},
                      {"wall_s_per_sim_s_quiet", c_quiet * g},
                      {"over_lod_on", lod > 0 ? c * g / lod : 0.0}});
  }
  lod_off["estimates"] = extrap;
  std::printf("LOD off (all terrain as particles): c = %.3g wall s per granule-second (dem stage / granule-seconds of the "
              "runs above), %.3g on quiet patches (their first %.1f s, before the bodies land); G = (N x %.2f m)^2 x %.2f m "
              "x phi %.3f / (16/3 pi r^3)\n",
              c, c_quiet, kQuietUntil, kSpacing, depth, packing);
  for (const auto& e : extrap)
    std::printf("  %5d² cells: %.3g granules -> %.3g s wall per simulated s (%.3g quiet; %.3g x LOD on)\n",
                e["terrain"].get<int>(), e["granules"].get<double>(), e["wall_s_per_sim_s"].get<double>(),
                e["wall_s_per_sim_s_quiet"].get<double>(), e["over_lod_on"].get<double>());
  std::fflush(stdout);
  // Check: small terrains fully as particles (one patch covers each): the drop's ball on a
  // terrain its patch covers, and a slab that loads the whole patch.
  ojson checks = ojson::array();
  if (!a.quick) {
    const std::pair<LodBenchScene, int> cases[] = {{LodBenchScene::Full, 4}, {LodBenchScene::FullSlab, 8}};
    for (const auto& [kind, n] : cases) {
      auto r = run_alone(lod_bench_scene(kind, n, threads), n, threads, a.seconds);
      if (!r) return fail("check " + std::to_string(n), r.message());
      const Lane& l = **r;
      const double sim = l.simulated_s();
      const double g_pred = granules_for(n), g = l.peak_granules;
      const double measured_dem = l.dem_s() / sim;
      const double ready_fraction = g > 0 ? granule_seconds(l, sim) / (g * sim) : 0;
      const char* what = kind == LodBenchScene::Full ? "ball" : "slab";
      checks.push_back({{"terrain", n},
                        {"body", what},
                        {"granules_predicted", g_pred},
                        {"granules_measured", g},
                        {"dem_s_per_sim_s_predicted", c * g * ready_fraction},
                        {"dem_s_per_sim_s_measured", measured_dem},
                        {"wall_s_per_sim_s_measured", l.wall_s / sim},
                        {"simulated_s", sim}});
      std::printf("  check, %d² cells (%.1f m square) all particles under a %s: %.0f granules predicted, %.0f measured; "
                  "dem %.3g s per simulated s predicted (c x granules x %.2f of the run simulating), %.3g measured\n",
                  n, n * kSpacing, what, g_pred, g, c * g * ready_fraction, ready_fraction, measured_dem);
      std::fflush(stdout);
    }
  }
  lod_off["check_full_terrain"] = checks;

  // 3. idle terrain: the largest size, nothing touching it.
  ojson idle;
  {
    const int n = a.sizes.back();
    auto r = run_alone(lod_bench_scene(LodBenchScene::Idle, n, threads), n, threads, a.quick ? a.seconds : std::max(1.0, a.seconds));
    if (!r) return fail("idle", r.message());
    const Lane& l = **r;
    idle = {{"terrain", n},
            {"wall_s_per_sim_s", l.wall_s / l.simulated_s()},
            {"frame_median_ms", median(l.frame_ms)},
            {"setup_s", l.setup_terrain_s + l.setup_bullet_s + l.setup_manager_s},
            {"bullet", bullet_stats(l.world->bullet())},
            {"stage_ms_per_sim_s", stages_per_sim_s(l)}};
    std::printf("idle: %d² cells, no bodies: %.4f s wall per simulated s, frame median %.4f ms, Bullet updates %d bounds a "
                "step (%d tiles), stages (ms per simulated s):%s\n",
                n, idle["wall_s_per_sim_s"].get<double>(), idle["frame_median_ms"].get<double>(),
                idle["bullet"]["aabb_updates_per_step"].get<int>(), idle["bullet"]["tiles"].get<int>(),
                join_stages(idle["stage_ms_per_sim_s"]).c_str());
    std::fflush(stdout);
  }

  // 4. a sleeping patch: frames until every live patch is asleep, then one simulated second.
  ojson asleep = ojson::object();
  if (!a.quick) {
    const int n = a.sizes.front();
    auto lane = make_lane(lod_bench_scene(LodBenchScene::Asleep, n, threads), n, threads);
    if (!lane) return fail("asleep", lane.message());
    Lane& l = **lane;
    const double give_up = 8.0;  // s simulated
    auto all_asleep = [&] { return l.manager->ready_patches() > 0 && l.manager->asleep_patches() == l.manager->ready_patches(); };
    while (!all_asleep() && l.simulated_s() < give_up)
      if (Status st = advance(l, 1); !st) return fail("asleep", st.message());
    const double t_asleep = l.simulated_s(), wall_awake = l.wall_s, dem_awake = l.dem_s();
    const bool fell_asleep = all_asleep();
    const long long frames = std::llround(1.0 / l.dt);
    if (Status st = advance(l, frames); !st) return fail("asleep", st.message());
    const double window = double(frames) * l.dt;
    const bool stayed = all_asleep();
    asleep = {{"terrain", n},
              {"granules", l.peak_granules},
              {"asleep_at_s", fell_asleep ? t_asleep : -1.0},
              {"wall_s_per_sim_s_awake", wall_awake / t_asleep},
              {"wall_s_per_sim_s_asleep", (l.wall_s - wall_awake) / window},
              {"dem_s_per_sim_s_asleep", (l.dem_s() - dem_awake) / window},
              {"asleep_whole_window", fell_asleep && stayed}};
    std::printf("asleep: one body resting on %d² cells, a patch of %d granules: %s; %.4f s wall per simulated s until "
                "then (fill, settle), %.6f s over the next %.1f s asleep (dem %.6f)%s\n",
                n, l.peak_granules,
                fell_asleep ? ("asleep at " + format_number(t_asleep) + " s").c_str() : "not asleep by 8 s",
                asleep["wall_s_per_sim_s_awake"].get<double>(), asleep["wall_s_per_sim_s_asleep"].get<double>(), window,
                asleep["dem_s_per_sim_s_asleep"].get<double>(), stayed ? "" : " (it woke during the window)");
    std::fflush(stdout);
  }

  const double load_after = load_average();
  const bool within = std::abs(ratio - 1) <= 0.10;
  std::printf("wall per simulated s, largest / smallest terrain: %.3f (%d² / %d²): %s; median of the per-window ratios "
              "%.3f; CPU s per simulated s %.3f; outside the dem stage %.3f; stage that grew most outside dem: %s (%+.2f ms "
              "per simulated s); dem state %s at every size\n",
              ratio, a.sizes.back(), a.sizes.front(), within ? "within 10 %" : "NOT within 10 %", ratio_window, ratio_cpu,
              ratio_non_dem, grew.c_str(), grew_by, same_dem ? "the same" : "NOT the same");
  std::printf("load average %.2f -> %.2f (%.2f-%.2f between rounds); %.0f s in all; peak RSS %.0f MB with every size set up\n",
              load_before, load_after, load_min, load_max, seconds_since(t_start), peak_rss_sizes);
  ojson out = {{"results", results},
               {"lod_off", lod_off},
               {"ratio_largest_over_smallest", ratio},
               {"within_10_pct", within},
               {"median_window_ratio_largest_over_smallest", ratio_window},
               {"cpu_ratio_largest_over_smallest", ratio_cpu},
               {"ratio_outside_dem", ratio_non_dem},
               {"stage_grown_most", {{"stage", grew}, {"ms_per_sim_s", grew_by}}},
               {"same_dem_state_every_size", same_dem},
               {"idle", idle},
               {"asleep", asleep},
               {"method", {{"interleaved", true}, {"window_s", double(window_frames) * kDt}, {"rounds", rounds},
                           {"order", "round robin, rotated each round"}}},
               {"threads", threads},
               {"seconds", double(total_frames) * kDt},
               {"quick", a.quick},
               {"wall_s_total", seconds_since(t_start)},
               {"peak_rss_mb", peak_rss_sizes},
               {"load_average", {load_before, load_after}},
               {"load_average_between_rounds", {load_min, load_max}}};
  if (a.json) std::printf("%s\n", out.dump().c_str());
  return 0;
}

}  // namespace sandpatch
