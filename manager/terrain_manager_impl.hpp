// TerrainManager::Impl (internal to manager/): the manager's state and its stages, one source
// file per stage (docs/manager.md "Sources"):
//   terrain_manager.cpp  create, the frame's sequence (before_bodies, after_bodies), queries, report
//   planning.cpp         lod: requests, queue, merge, growth of a patch under a body; the
//                        planning geometry (planning.hpp: region, floor, soil volume)
//   filling.cpp          activation: tiles, promotion (heightfield -> granules), uploads
//   coupling.cpp         dem and sleep: carriers, shells, forces to and from Bullet
//   demotion.cpp         demotion: depth render, heightfield write, bodies set down
//   demotion_ledger.cpp  demotion: the volume ledger (mass conservation, the closed ledger)
//   budget.cpp           the frame budget: what patches cost, the scale and extent of a new one
// Each stage function runs inside its Profile timer (manager/profile.hpp), opened by the
// sequencer.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "gl/context.hpp"
#include "manager/depth_conversion.hpp"
#include "manager/patch.hpp"
#include "manager/planning.hpp"
#include "manager/terrain_manager.hpp"

namespace sandpatch {
namespace manager_detail {

using Clock = std::chrono::steady_clock;
inline double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

inline Vec3 v3(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }
inline Eigen::Vector3f eig(Vec3 v) { return {v.x, v.y, v.z}; }
inline Quat quat(const Eigen::Quaternionf& q) { return {q.x(), q.y(), q.z(), q.w()}; }

// Key of a body in the manager's maps: index << 32 | generation.
inline std::int64_t body_key(RigidBodyId b) { return (std::int64_t(b.index) << 32) | std::uint32_t(b.generation); }

}  // namespace manager_detail

struct TerrainManager::Impl {
  TerrainManagerDef def;
  Heightfield* hf = nullptr;
  BulletWorld* world = nullptr;

  // ---- tiles (filling.cpp) ----
  std::deque<TileSet> tile_sets;      // made at start-up, one per scale (references stay valid)
  double tiles_settled_ms = 0;
  std::string tile_cache;             // resolved directory ("" = no disk cache)
  std::string tile_fallback;          // read-only directory tried after it (the build's; tile_cache.hpp)
  std::vector<std::string> tile_cache_notes;  // why a stored tile was not used or not written
  int tiles_from[3] = {};             // tiles by TileCacheOutcome::Source: disk, memory, settled
  Eigen::Vector3d camera = Eigen::Vector3d::Zero();  // m, world: the scale bands' centre

  // ---- planning (planning.cpp) ----
  std::unordered_map<std::int64_t, int> still_frames;  // frames each body (body_key) has been at rest
  int lapsed_requests = 0;  // queued requests dropped because no body predicted contact there any more
  int extensions = 0;       // patches asked for ahead of a body heading past its patch's edge
  int travels = 0;          // of those, successors that took their patch's granules over (take_over)
  long long springs_handed_over = 0;  // contact springs those successors took with the granules (CPU backend)
  int urgent_fills = 0;     // fills finished at once because a body would reach them within two frames (activate)
  int released = 0;         // patches no body was over, demoted for a request waiting for a slot or to keep one ready
  int early_releases = 0;   // of which released with the pool full before a request needed the slot (demotion.cpp)

  // ---- the pool ----
  // The GL context (the GL backend's and the demotion's depth render's, made by create())
  // outlives the slots: declared first.
  std::unique_ptr<gl::Context> gl;
  std::vector<Slot> slots;            // what the frame touches
  std::vector<PatchRecord> records;   // records[k]: the patch in slots[k], for demotion and the report
  std::vector<PatchRequest> queue;
  std::vector<PatchEvent> events;
  int next_patch = 0;
  int peak_slots = 0;
  int peak_queue = 0;
  std::vector<nlohmann::ordered_json> ledgers;  // closed ledgers (demoted patches)
  std::vector<GridRegion> dirty;                // written by demotions, not yet taken
  std::vector<DemCost> earlier_costs;           // DEM costs of demoted patches whose slot took another
  TerrainManager::FrameWork work;               // this frame's work (reset by before_bodies)
  // Wall time of the conversion parts run one a frame, by kind (report: conversion_parts):
  // what a frame that runs one pays (docs/manager.md "No frame does a whole patch's work").
  enum class Part { Reset, Cut, Upload, Render, HatMeans, Write, Edges };
  static constexpr std::array<const char*, 7> kPartNames{"reset", "cut", "upload", "render", "hat_means", "write", "edges"};
  struct PartTime {
    long long count = 0;
    double total_ms = 0, max_ms = 0;
  };
  std::array<PartTime, kPartNames.size()> part_times{};
  void time_part(Part p, double ms) {
    PartTime& t = part_times[std::size_t(p)];
    ++t.count;
    t.total_ms += ms;
    t.max_ms = std::max(t.max_ms, ms);
  }

  // The demotion's GL depth render (create(): when use_gl and a context could be made; else
  // null, gl_note says why, and demotions render on the CPU).
  std::unique_ptr<ParticleDepthRenderer> depth;
  std::string gl_note;

  // ---- coupling (coupling.cpp) ----
  // One carrier per body. A body over two patches at once (resting across the seam of
  // adjacent patches) had a shell in both, and each DEM, supporting it on its granules and on
  // its terrain grid outside its region, gave Bullet the full support force: measured in
  // ExtremesManager.HundredBodiesAtOnceOnTwoSlots, 30.6 N + 18.3 N upwards on a 2 kg sphere
  // (weight 19.6 N), which bounced at 0.24-0.34 m/s and kept both patches awake. Now a
  // body is carried by the ready patch that holds most of its footprint (the one carrying it
  // keeps it while it holds at least half as much as another: no flip-flop), and only that
  // patch sets its heightfield collision. Key: body_key -> slot index.
  std::unordered_map<std::int64_t, int> carrier;
  // Bodies a demotion set down on the new heights, until this simulated time (s): their first
  // Bullet step on the changed heightfield falls g dt (0.16 m/s) before the contact holds them,
  // which asked for a new patch at once; promoted under bodies sunk into the old one's crater,
  // it threw them out of its fill at 1-3 m/s (measured in the hundred-bodies case). Until then
  // they ask for no patch and no patch takes them up.
  std::unordered_map<std::int64_t, double> set_down_until;
  double now = 0;  // s, simulated time of the frame being run
  // The soil's force on each carried body in the last dem stage (body_key -> N, N m about the
  // centre of mass, world): what couple_after or hold_resting_bodies handed Bullet. Cleared at
  // the start of every frame.
  struct SoilForce {
    Eigen::Vector3f force, torque;
  };
  std::unordered_map<std::int64_t, SoilForce> soil;
  // Kinematic and static bodies whose shell moved into a patch faster than its granules can
  // stop (body_key -> record): the report's tools_too_fast.
  struct FastTool {
    std::string name;
    double speed = 0, limit = 0;  // m/s, world: the fastest seen, and the limit then
    long long frames = 0;         // frames over the limit
    double last = -1;             // s, simulated time of the last frame over it (an event when it goes over again)
  };
  std::map<std::int64_t, FastTool> fast_tools;
  std::unordered_set<std::int64_t> shells_sampled;  // bodies whose shell was sampled ahead (body_key)

  // m (world): a body's shell joins a patch when the body's lowest point is within half of
  // this above the patch's highest surface point; the simulation's domain reaches this high.
  static constexpr double engage_height = 1.0;
  // m (world): a kinematic or static body whose shell a patch has enabled keeps it while its
  // lowest point is less than this above the patch's highest surface point: the top of the
  // simulation's domain, so a bucket lifting soil out of the patch carries it up to there
  // (docs/manager.md "Carrying soil up"); above it the shell is let go, the soil falls, and
  // the drop is reported (soil_dropped, PatchEventKind::SoilDropped).
  static constexpr double carry_height = engage_height;
  // The height (m above the patch's highest surface point) up to which a body engages slot s:
  // for a body whose shell s has enabled, carry_height if it is a tool, else engage_height / 2;
  // for the others join_height.
  double engage_limit(const Slot& s, RigidBodyId b) const;
  // s, how far ahead join_height looks at a body's approach.
  static constexpr double join_lookahead = 0.1;
  // The height (m above the patch's highest surface point) within which body b's lowest point
  // joins slot s: two sphere diameters at the patch's scale (a shell sphere is centred on the
  // body's surface, the top granules reach about a sphere radius above the cut surface; the rest
  // is margin), plus the distance the body can approach in join_lookahead (its downward speed
  // and its rotation's at its reach), at most engage_height / 2. Once joined, it is kept up to
  // engage_limit's larger heights. A body that only passes over the sand (a vehicle's chassis
  // above its wheels) stays out of the DEM and costs it nothing.
  double join_height(const Slot& s, RigidBodyId b) const;
  // Soil a tool took out of a patch (coupling.cpp couple_before): the report's soil_dropped.
  struct SoilDrop {
    std::string name;
    double time = 0;      // s, simulated
    int patch = -1;
    double height = 0;    // m, its lowest point above the patch's highest surface point
    int granules = 0;     // granules whose centres were within its bounds
    double volume = 0;    // m³, their bulk volume at the bed's packing
  };
  std::vector<SoilDrop> soil_drops;
  // Granules of slot s whose centres lie within the world box [lo, hi] (m) grown by a granule
  // radius, above lo.y: what a tool there holds.
  int granules_within(const Slot& s, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const;

  // ---- shared helpers ----
  // The GL backend's context must be current for any slot call (other GL users of the
  // thread, e.g. the image writer, make their own current in between). The CPU backend's
  // slots need none: there the manager's context (made at creation for the depth render) is
  // made current by the depth render alone, as before it was made at the first demotion, so
  // a caller's context current between frames stays current (manager/run.cpp's image writer
  // updates its terrain textures after after_bodies without making its own current: with
  // the manager's context made current every frame, those updates went to the wrong context
  // and the next GL depth render failed with GL_INVALID_OPERATION).
  void current() const {
    if (gl && def.backend == "gl") (void)gl->make_current();
  }
  PatchRecord& record(const Slot& s) { return records[std::size_t(&s - slots.data())]; }
  const PatchRecord& record(const Slot& s) const { return records[std::size_t(&s - slots.data())]; }
  // Books one DEM step call of slot s that took wall_ms (DemCost): the granules' spheres and
  // the enabled shells'. A new patch in the slot starts its record's cost afresh.
  void account_step(const Slot& s, double wall_ms, const StepStats* stats = nullptr, double share = 1) {
    DemCost& c = record(s).cost;
    if (c.patch != s.patch) {
      if (c.patch >= 0) earlier_costs.push_back(c);
      c = DemCost{};
      c.patch = s.patch;
    }
    c.granules = record(s).granules;
    int spheres = 4 * record(s).granules;
    for (const Carried& k : s.carried)
      if (k.enabled) spheres += s.sim->body_particle_count(k.shell);
    const StepStats& st = stats ? *stats : s.sim->last_step();
    c.add(wall_ms, st, spheres, share);
    c.last_frame = frame;
    ++work.patches_stepped;
    work.substeps += st.substeps;
    work.sphere_steps += std::int64_t(spheres) * st.substeps;
  }
  // Spheres a slot's DEM stepped awake at its last step (granules asleep in still regions cost
  // next to nothing: docs/dem.md "Sleeping regions").
  static int awake_spheres(const Slot& s) { return s.sim->particle_count() - 4 * s.sim->last_step().sleeping_granules; }
  float radius_world(double s) const { return float(def.material.radius * s); }
  float radius_world(const Slot& slot) const { return radius_world(slot.scale); }
  // m³ (world) of one granule's solid at particle scale s.
  double granule_volume(double s) const {
    return 4.0 * 4.0 / 3.0 * std::numbers::pi * std::pow(double(def.material.radius) * s, 3);
  }
  // The scales patches can take: the bands', or the one particle_scale.
  std::vector<double> scales() const {
    std::vector<double> v;
    for (const auto& b : def.scale_bands)
      if (std::find(v.begin(), v.end(), b.particle_scale) == v.end()) v.push_back(b.particle_scale);
    if (v.empty()) v.push_back(def.particle_scale);
    return v;
  }
  TileSet& set_for(double s) {
    for (TileSet& t : tile_sets)
      if (t.scale == s) return t;
    return tile_sets.front();  // not reached: every scale a request can take has a set from create()
  }
  const TileSet& set_for(double s) const { return const_cast<Impl*>(this)->set_for(s); }
  int max_cells() const {
    int c = 1;
    for (const TileSet& t : tile_sets) c = std::max(c, t.cells);
    return c;
  }
  bool settling(RigidBodyId b) const {
    const auto it = set_down_until.find(manager_detail::body_key(b));
    return it != set_down_until.end() && now < it->second;
  }
  // Whether slot `k` carries body b (see `carrier`).
  bool carries(int k, RigidBodyId b) const {
    const auto it = carrier.find(manager_detail::body_key(b));
    return it != carrier.end() && it->second == k;
  }
  bool carried_anywhere(RigidBodyId b) const { return carrier.count(manager_detail::body_key(b)) > 0; }
  // The world rectangle of a slot's region.
  PatchRequest rect(const Slot& s) const {
    const double sp = hf->spacing();
    PatchRequest p;
    p.x0 = hf->origin_x() + s.region.i0 * sp;
    p.x1 = p.x0 + (s.region.ni - 1) * sp;
    p.z0 = hf->origin_z() + s.region.j0 * sp;
    p.z1 = p.z0 + (s.region.nj - 1) * sp;
    return p;
  }

  // ---- the frame budget (budget.cpp) ----
  // The cost model (budget.cpp): ms of a frame = load × substeps × (a + b × spheres).
  double cost_a_ms = 0.02, cost_b_ms = 1e-4;  // ms per substep, and per substep and sphere
  double calibrated_a_ms = 0, calibrated_b_ms = 0;
  double load = 1;             // measured / predicted, followed frame by frame
  struct BudgetChoice {
    bool fits = true;          // within the budget (else: the coarsest rung, which did not fit)
    double requested_scale = 1, scale = 1;
    PatchRequest req;          // as promoted (apron trimmed)
    int granules = 0;          // predicted
    int rung = 0;              // 0 = as requested
    double predicted_ms = 0, available_ms = 0, budget_ms = 0;
    // The coarsest scale the bodies it is for allow (body_scale_cap; 0: no body), the body
    // that set it and its smallest dimension (m); and what the budget gave up instead of a
    // coarser scale the cap barred (e.g. "apron"), empty when it gave up nothing.
    double body_cap = 0;
    std::string capped_by;
    double capped_size_m = 0;
    bool cap_bound = false;    // the cap barred a rung the budget would have tried
    std::vector<std::string> traded;
    int steps_per_contact = 0;  // the DEM's N it runs at when it traded substeps (else 0)
  };
  // A successor's (planning.cpp ask_successor): its predecessor's scale (it takes their
  // granules over), its cost in place of its predecessor's; half the substeps when it does not
  // fit and its predecessor ran at the full N.
  BudgetChoice choose_successor(const PatchRequest& r, const Slot& pred, double dt, double live_ms) const;
  std::vector<nlohmann::ordered_json> budget_log;  // one entry per promotion (the report's budget.patches)
  std::vector<nlohmann::ordered_json> budget_log_lapsed;  // requests that waited for the budget and lapsed (at most 256)
  long long budget_waits = 0;      // request-frames a request waited in the queue because it did not fit
  // Bodies set on a patch's ground as they arrived on it (coupling.cpp couple_before): how
  // many times, and the largest rise (m, world). The report's arrivals.
  int lifts = 0;
  double lift_max = 0;
  int budget_overruns = 0;         // promotions that did not fit and went ahead (nothing else live)
  int budget_live_trades = 0;
  bool gl_profile = false;  // GL slots time their kernels (SANDPATCH_GL_PROFILE): the report's dem.total.gl_kernel_ms      // live patches whose substeps a later patch's overrun halved (trade_live_substeps)
  long long budget_held = 0;       // patch-frames a patch carrying no body was held (not stepped)
  long long budget_held_ahead = 0;  // of which a body was heading for the patch (further than two frames)
  int budget_longest_hold = 0;     // frames in a row, the longest hold
  // Which awake patches step this frame (budget.cpp): all of them without a budget; with one,
  // the wanted ones (a body on, over or heading for them), then the others, longest held
  // first, while they fit.
  bool wanted(const Slot& s) const;
  // Whether a body (world bounds lo..hi, velocity v) is over or heading for the rectangle r:
  // its bounds, grown by lod.margin (and `grow`, m) and swept along its horizontal velocity
  // over lod.horizon (or `horizon` s when >= 0).
  bool heading_for(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3f& v, const PatchRequest& r,
                   double grow = 0, double horizon = -1) const;
  // The coarsest particle scale the bodies a request is for allow (those over or heading for
  // it, within lod.apron: the request is their contact's footprint and apron): each body's
  // smallest dimension over kBodyGranules granule diameters at scale 1 (budget.cpp); 0 when
  // no body is.
  double body_scale_cap(const PatchRequest& r, std::string* by, double* size) const;
  std::vector<Slot*> stepping_order(const std::vector<Slot*>& awake, double dt);
  bool pinned() const { return def.budget_substep_ms > 0 && def.budget_sphere_ns > 0; }
  bool budget_on() const { return def.frame_budget_fraction > 0 || std::isfinite(def.frame_budget_ms); }
  double budget_ms(double dt) const;  // ms, infinity when off
  // DEM substeps of a frame of dt s at N = steps_per_contact (0: the manager's N).
  double substeps(double dt, int steps_per_contact = 0) const;
  // A patch's DEM ms per frame at N = steps_per_contact (0: the manager's).
  double predict_ms(double spheres, double dt, int steps_per_contact = 0) const;
  double live_cost_ms(double dt) const;  // predicted DEM ms of the awake and filling patches
  void observe_cost(const Slot& s, double wall_ms, double dt);
  Status calibrate();
  Status warm_slots();  // every slot run once at start-up (budget.cpp)
  // The scales tiles are made for: scales(), and with a budget each one's coarser rungs.
  std::vector<double> all_scales() const;
  int predict_granules(const PatchRequest& r, double s) const;
  BudgetChoice choose(const PatchRequest& r, double dt, double others_ms) const;

  // ---- creation (terrain_manager.cpp) ----
  // The demotion's GL depth render when def.use_gl: the context (the GL backend's, or a new
  // one) and the renderer; without them, gl_note says why and demotions render on the CPU.
  Status make_depth_renderer();

  // ---- planning (planning.cpp): Stage::Lod ----
  // Predicts contacts, merges them into requests, drops lapsed queued requests, queues new
  // ones (or grows a patch under a body heading past its edge) and orders the queue.
  Status plan(double time);
  // A body with a planned path (TerrainManager::set_planned_path): appends the request over the
  // stretch of its path that works the ground, when its first contact from now on is within
  // lod.horizon (planning.cpp). False when the path does not handle the body (no path, or a
  // stretch more than a slot holds: the body is predicted ballistically, and the report says so).
  bool plan_path(RigidBodyId b, double time, std::vector<PatchRequest>& out);
  // Planned paths (body_key -> bounds over time) and what planning made of them (the report's
  // planned_paths).
  std::unordered_map<std::int64_t, std::vector<TerrainManager::PathPose>> paths;
  // Bodies whose path is extrapolated from the game's motion, frame by frame (World
  // look_ahead), not keyframed: a stretch too big for a slot in one frame is followed
  // ballistically in that frame only (a keyframed path's is for the rest of the path).
  std::unordered_set<std::int64_t> extrapolated;
  struct PathLog {
    std::string name;
    bool extrapolated = false;    // the path is the game's motion held for lod.horizon
    long long asked_frames = 0;   // frames its stretch was not covered by a live patch (asked for)
    long long too_big_frames = 0;  // frames its stretch needed more granules than a slot holds
    PatchRequest last;            // the last stretch asked for (m, world, apron included)
    int granules = 0;             // predicted for it
    double from = 0, to = 0;      // s: the stretch's times
  };
  std::map<std::int64_t, PathLog> path_log;
  double scale_for(const PatchRequest& r) const;
  // Whether s is one of the coarser scales only a frame budget chooses (budget.cpp kLadder),
  // not one the terrain asked for (scales()).
  bool coarser_rung(double s) const {
    const std::vector<double> own = scales();
    return std::find(own.begin(), own.end(), s) == own.end();
  }
  // m: the granules under a patch's lowest surface point at particle scale s: patch_depth; at
  // the coarser scales a frame budget may choose, at least two granules (4 bounding radii,
  // 2.22 r each, world); at most soil_depth.
  double patch_depth_at(double s) const {
    const double two_granules = coarser_rung(s) ? 4.0 * 2.22 * double(def.material.radius) * s : 0.0;
    return std::min(def.soil_depth, std::max(def.patch_depth, two_granules));
  }
  // The floor of a patch over `region` at scale s (planning.hpp patch_floor, with def's depths).
  double floor_of(const GridRegion& region, double s, float* lo, float* hi) const {
    return patch_floor(*hf, region, patch_depth_at(s), def.soil_depth, def.bedrock_height, lo, hi);
  }
  double max_merged_side() const;
  bool has_soil(const PatchRequest& r) const;
  Result<GridRegion> region_for(const PatchRequest& r, double s) const;
  bool covered(const PatchRequest& r) const;
  bool overlaps_patch(const PatchRequest& r) const;
  // `ids`: the bodies of the requests' BodyMotion indices (PatchRequest::bodies).
  Result<bool> extend(const PatchRequest& r, double time, const std::vector<RigidBodyId>& ids);
  // A successor of slot s moved by whole tile periods toward `side` (0: -x, 1: +x, 2: -z,
  // 3: +z) over the request r; whether it was asked (or had been).
  bool ask_successor(Slot& s, const PatchRequest& r, int side, double time);
  // A successor's fill is in: it takes its predecessor's granules over where it covers them,
  // the bodies with them, and the predecessor is demoted (filling.cpp).
  Status take_over(Slot& successor);
  // The predecessor's demotion has written its heights: the successor's heights at promotion
  // over that apron, and its ledger's volume before, become those (demotion.cpp).
  void rebase(Slot& successor);
  Status trade_live_substeps(const Slot& to, double time);  // filling.cpp
  // A patch no body is over given up: held, demoted one part a frame (planning.cpp).
  Status release(Slot& s, double time);
  // `for_carried`: the request waiting for a slot is for a body a patch carries (its
  // successor, or the patch abutting ahead of it).
  Result<bool> release_idle(double time, bool for_carried);
  bool wanted_for_release(const Slot& s) const;
  bool body_coming(const Slot& s) const;

  // ---- filling (filling.cpp): Stage::Activation ----
  // Serves the queue while slots are free, then uploads a chunk of every filling patch.
  Status activate(double time, double dt);
  Status add_tile_set(double scale);
  bool derive_tile_set(double scale);  // false: no set it is a whole multiple (>= 2) of
  int tile_layers(const GranuleTileDef& td, double fill_depth) const;
  Result<const GranuleTile*> tile_for(TileSet& set, double fill_depth);
  SimulationDef sim_def(double scale) const;
  // A promotion's first part (the slot reset for the request's region), then its cut: at
  // most about `units` units of the fill's cut (FillCut::step) a call, the fill's render
  // baseline and ledger in the call that finishes it.
  Status promote(Slot& slot, const PatchRequest& req, double time);
  Status cut(Slot& slot, double time, std::size_t units);
  // Units of a fill's cut per frame (FillCut: a tile granule made a candidate is one, a
  // candidate cut four): 0.25 ms a part on a car's fill on average, 0.56 ms at most
  // (docs/manager.md "No frame does a whole patch's work").
  static constexpr std::size_t kCutUnitsPerFrame = 4096;
  static constexpr std::size_t kWhole = std::size_t(-1);
  Status clear_bodies(Slot& slot, const ParticleScale& sc, const GranuleShape& shape, double s);
  Status upload(Slot& slot, std::size_t budget, double time);

  // ---- coupling (coupling.cpp): Stage::Dem and Stage::Sleep ----
  // Chooses carriers, hands every ready patch its bodies, steps the awake ones and hands the
  // contact forces back to Bullet.
  Status step_patches(double time, double dt);
  // One patch's DEM step of a frame (coupling.cpp step_patch): its status, wall ms (its share
  // of the section's when patches stepped side by side, `share` the factor), whether a
  // substep ran, and for a prescribed shell's frame the summed stats.
  struct PatchStep {
    Status status = Ok{};
    double ms = 0, share = 1;
    bool prescribed = false, stepped = true;
    StepStats stats;
  };
  PatchStep step_patch(Slot& s, double dt);
  int concurrent_patches(const std::vector<Slot*>& order, double dt) const;
  std::int64_t side_by_side_frames = 0;  // frames whose patches stepped side by side
  std::int64_t frame = 0;  // step_patches calls so far (DemCost::last_frame)
  // After the Bullet step: patches whose DEM came to rest fall asleep (their bodies stop).
  void update_sleep(double time, double dt);
  // `above`: m over the patch's highest surface point the body's lowest point must be below.
  bool engages(const Slot& s, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, bool* inside,
               double above = 0.5 * engage_height) const;
  void choose_carriers();
  bool lying(RigidBodyId b, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const;
  Status couple_before(Slot& slot, double dt);
  void hold_resting_bodies(Slot& slot);
  // `stepped`: the DEM ran a substep this frame (else a kinematic shell's force stands).
  void couple_after(Slot& slot, double dt, bool stepped = true);
  Result<std::vector<Eigen::Vector3f>> shell_points(RigidBodyId b, double scale) const;
  Result<std::vector<Eigen::Vector3f>> shell_points(RigidShape shape, double scale) const;

  // ---- demotion (demotion.cpp): Stage::Demotion ----
  // Demotes the patches asleep for idle_timeout, one part of one patch a frame.
  Status demote_idle(double time);
  // The parts of a live patch's demotion that depend on its fill alone, done ahead (demotion.cpp).
  Status render_baselines(double time, bool whole);
  // Whether the slot's fill has a render baseline (its heights at promotion over the apron),
  // and whether that render's hat means are still to take (its render done, they not yet).
  bool has_baseline(const Slot& s) const {
    const PatchRecord& rec = record(s);
    return !rec.fill_spheres.empty() && rec.before_heights.size() == std::size_t(s.apron.ni) * s.apron.nj;
  }
  bool fill_hat_pending(const Slot& s) const {
    return s.demotion.stage == 1 && s.demotion.row == 0 && s.demotion.hat_was.empty() && has_baseline(s);
  }
  // Demotes every live patch (filling ones after uploading the rest).
  Status demote_every(double time);
  // `staged`: one part this call (a band of a render, an image's hat means, or the write), the
  // slot's Slot::demotion keeping the rest; otherwise all that is left of it now.
  Status demote(Slot& slot, double time, bool gl_ok = true, bool staged = false);
  void granule_spheres(const Slot& slot, std::vector<float>& xyzr) const;
  // The box a demotion renders: the slot's apron (m, heightfield-local), from the floor to
  // above the highest (grown) sphere.
  struct RenderBox {
    float x0 = 0, z0 = 0, x1 = 0, z1 = 0;
    float floor = 0, top = 0;
    float probe = 0;  // m, the spheres' growth
  };
  Result<HeightImage> render_surface(const Slot& slot, const RenderBox& box, const std::vector<float>& spheres, bool gl_ok,
                                     bool* on_gl) const;
  struct DepthSize {
    int width = 0, height = 0;  // texels along x, along z (rows)
  };
  DepthSize render_size(const Slot& slot, const RenderBox& box) const;
  void finish_surface_rows(const Slot& slot, const RenderBox& box, HeightImage& img, int v0, int v1) const;
  void set_bodies_down(const Slot& slot, double time);
  // The heights a demotion wrote, step by step, for the ledger's terms (close_ledger): over
  // `ring` (the apron grown by one sample, clipped to the grid: all the demotion may change),
  // ni × nj, i fastest, m, heightfield-local.
  struct DemotionSteps {
    GridRegion ring;
    std::vector<float> pre;        // before the write
    WriteStages write;             // write_to_heightfield's own steps (apron only)
    std::vector<float> written;    // after write_to_heightfield (its border band included)
    std::vector<float> edged;      // after the region's own edge band
    std::vector<float> set_down;   // after set_bodies_down
    std::vector<float> conserved;  // after conserve_volume: what the demotion leaves
  };
  // The volume ledger (demotion_ledger.cpp).
  double ring_change(const Slot& slot, const PatchRecord& rec, const DemotionSteps& steps, const std::vector<float>& ring_h) const;
  // (columns: count only spheres whose nearest apron sample is marked; null: all)
  long long spheres_above(const Slot& slot, const PatchRecord& rec, const std::vector<float>& xyzr, const RenderBox& box,
                          const std::vector<char>* columns = nullptr) const;
  static long long spheres_outside(const std::vector<float>& xyzr, const RenderBox& box);
  void conserve_volume(const Slot& slot, PatchRecord& rec, const DemotionSteps& steps, const std::vector<float>& granule_xyzr,
                       const RenderBox& box);
  void close_ledger(const Slot& slot, PatchRecord& rec, bool on_gl, const std::vector<float>& granule_xyzr,
                    const DemotionSteps& steps, const RenderBox& box);

  // ---- report (terrain_manager.cpp) ----
  nlohmann::ordered_json dem_report() const;  // the report's "dem" section
};

}  // namespace sandpatch
