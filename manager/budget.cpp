// The terrain manager's frame budget (docs/manager.md "Frame budget"): what a patch costs, and
// the particle scale and extent a new patch is promoted at so that the frame's DEM stays
// within TerrainManagerDef::frame_budget_ms. See terrain_manager_impl.hpp.
//
// The cost model. A patch's DEM costs, per frame of dt seconds,
//   ms = load × n_sub(dt) × (a + b × spheres)
// n_sub the substeps the frame takes (dt_sub <= t_c / N, the same for every patch of one
// material), a the fixed cost of a substep (the parallel stages' start-up, the grid) and b
// its cost per sphere (the contact search and the forces are linear in the spheres at a
// fixed packing). a and b are measured at creation (`calibrate`: a pre-settled tile stepped
// in slot 0 at two sizes); `load` (1 at creation) then follows every patch's measured steps
// (an exponential average of measured / predicted), so the model tracks the machine's load,
// the thread count and the backend. A new patch's spheres are predicted from the soil volume
// of its region: 4 × volume × φ / v_granule at its scale (φ the tile's packing fraction).
#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "particles/granule.hpp"

#include "manager/terrain_manager_impl.hpp"

namespace sandpatch {

using manager_detail::Clock;
using manager_detail::ms_since;

double TerrainManager::Impl::budget_ms(double dt) const {
  if (def.frame_budget_fraction > 0) return def.frame_budget_fraction * dt * 1e3;
  return def.frame_budget_ms;
}

// Spheres a live slot steps per frame: its granules' (uploaded and pending) and its shells'.
static int slot_spheres(const Slot& s, int granules) {
  if (s.state == SlotState::Filling && !s.cut) return 4 * s.predicted_granules;  // not cut yet: the prediction
  const int all = std::max(s.sim->particle_count(), 4 * (granules + int(s.pending.size()) - int(s.uploaded)));
  // (less the granules asleep in still regions at its last step: they cost next to nothing)
  return s.state == SlotState::Active ? all - 4 * s.sim->last_step().sleeping_granules : all;
}

// (slot 0's substeps at its own N, scaled to N: n_sub = ceil(dt N / t_c))
double TerrainManager::Impl::substeps(double dt, int steps_per_contact) const {
  if (slots.empty()) return 1;
  const Slot& s = slots.front();
  auto n = s.sim->substeps_for(dt);
  const double base = n ? double(*n) : 1.0;
  const int own = s.steps_per_contact > 0 ? s.steps_per_contact : def.steps_per_contact;
  const int want = steps_per_contact > 0 ? steps_per_contact : def.steps_per_contact;
  if (own == want || own <= 0) return base;
  return std::max(1.0, std::ceil(base * want / own - 1e-9));
}

double TerrainManager::Impl::predict_ms(double spheres, double dt, int steps_per_contact) const {
  return load * substeps(dt, steps_per_contact) * (cost_a_ms + cost_b_ms * spheres);
}

// (a patch the budget may hold, one no body wants, leaves its room to a new one)
double TerrainManager::Impl::live_cost_ms(double dt) const {
  double ms = 0;
  for (const Slot& s : slots)
    if (s.state == SlotState::Filling || (s.state == SlotState::Active && (!budget_on() || wanted(s))))
      ms += predict_ms(slot_spheres(s, record(s).granules), dt, s.steps_per_contact);
  return ms;
}

// Whether a patch is wanted this frame: it carries a body, or a body is over or heading for
// its region (heading_for). A patch not wanted (its body left, or was removed) may be held by
// the budget and does not count against a new patch's room.
bool TerrainManager::Impl::wanted(const Slot& s) const {
  for (const Carried& c : s.carried)
    if (c.enabled) return true;
  const PatchRequest r = rect(s);
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    if (heading_for(lo, hi, world->state(b).linear_velocity, r)) return true;
  }
  return false;
}

// The body's bounds grown by lod.margin, swept along its horizontal velocity over lod.horizon
// (ahead of it only: a patch a body drove off is behind it, and no longer wanted by it).
bool TerrainManager::Impl::heading_for(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3f& v,
                                       const PatchRequest& r, double grow, double horizon) const {
  const double h = horizon >= 0 ? horizon : def.lod.horizon;
  const double m = def.lod.margin + grow, dx = double(v.x()) * h, dz = double(v.z()) * h;
  const double x0 = lo.x() + std::min(0.0, dx) - m, x1 = hi.x() + std::max(0.0, dx) + m;
  const double z0 = lo.z() + std::min(0.0, dz) - m, z1 = hi.z() + std::max(0.0, dz) + m;
  return x0 < r.x1 && x1 > r.x0 && z0 < r.z1 && z1 > r.z0;
}

// m: a body's smallest dimension (sphere and capsule: the diameter; box: its thinnest side;
// cylinder: the smaller of its diameter and length; mesh: the thinnest side of its vertices'
// box in its own frame).
static double smallest_dimension(const RigidShape& sh) {
  switch (sh.kind) {
    case RigidShapeKind::Sphere:
    case RigidShapeKind::Capsule: return 2.0 * double(sh.radius);
    case RigidShapeKind::Box: return 2.0 * double(sh.half_extents.minCoeff());
    case RigidShapeKind::Cylinder: return std::min(2.0 * double(sh.radius), double(sh.height));
    case RigidShapeKind::Mesh: {
      if (sh.vertices.empty()) return 0;
      Eigen::Vector3f lo = sh.vertices.front(), hi = lo;
      for (const Eigen::Vector3f& p : sh.vertices) lo = lo.cwiseMin(p), hi = hi.cwiseMax(p);
      return double((hi - lo).minCoeff());
    }
  }
  return 0;
}

// The particle-scale cap (docs/manager.md "Frame budget"): a body carried by a patch whose
// granules are as wide as the body sinks into them and stalls. Measured with the vehicle of
// scenes/vehicle_drive.json (0.3 m wide wheels) under a budget nothing fits (every patch at
// scale 2), started from six places 0.4 m apart (scripts/vehicle_starts.py; docs/BENCHMARKS.md
// "The particle-scale cap from six starts"): on r = 4 cm granules (wheel width 0.84 granule
// diameters) it dug itself in from three starts of six (0.5-1.0 m driven in 12 s; 18.9-24.6 m
// from the others); on r = 3.59 cm (0.94 diameters) it drove from all six (17.6-32.9 m), at
// scale 1.5 (1.12) and at scale 1 (1.69) too (29.6-34.9 m). (Without a budget, one start each:
// scale 3, 0.56 diameters, its wheels sank 0.27 m at the start and it did not move.)
// So a body keeps at least kBodyGranules granule diameters (the granule's bounding diameter,
// 2 (1 + sqrt(3/2)) r s = 4.45 r s) across its smallest dimension.
constexpr double kBodyGranules = 0.9;

double TerrainManager::Impl::body_scale_cap(const PatchRequest& r, std::string* by, double* size) const {
  const GranuleShape g = make_granule_shape(def.material.radius, 1.0f, def.material.density);
  const double diameter1 = 2.0 * double(g.centre_distance + g.radius);  // m, at scale 1
  double cap = 0;
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    if (!heading_for(lo, hi, world->state(b).linear_velocity, r, def.lod.apron)) continue;
    const double d = smallest_dimension(world->definition(b).shape);
    if (!(d > 0)) continue;
    const double c = d / (kBodyGranules * diameter1);
    if (cap == 0 || c < cap) {
      cap = c;
      if (by) *by = world->definition(b).name;
      if (size) *size = d;
    }
  }
  return cap;
}

// Which awake patches step this frame. A patch that carries a body, or that a body reaches
// within two frames, always steps. The others (one a body is heading for, further ahead; then
// those settling after their body left) step, the longest held first, while the predicted DEM
// of everything stepped so far fits 80 % of the budget (the share `choose` gives the DEM); one
// that does not fit is held this frame: not stepped, its granules where they are, its time
// behind the frame's (nothing outside the patch reads it). A patch no body wants is held at
// most kMaxHeldFrames in a row, so it still settles and sleeps, at a fraction of the rate; one
// a body is heading for waits for the body (stepped every kMaxHeldFrames beside the patches
// its body was on, it made frames of three patches' work). Without a budget every awake patch
// steps, in slot order.
std::vector<Slot*> TerrainManager::Impl::stepping_order(const std::vector<Slot*>& awake, double dt) {
  if (!budget_on()) return awake;
  constexpr int kMaxHeldFrames = 30;
  // Tiers: 2, a patch that carries a body or that a body reaches within two frames (it must
  // step); 1, one a body is heading for, further ahead (it may wait until the body comes:
  // nothing is on it yet); 0, one no body wants.
  auto tier = [&](const Slot& s) {
    for (const Carried& c : s.carried)
      if (c.enabled) return 2;
    if (!wanted(s)) return 0;
    const PatchRequest r = rect(s);
    for (RigidBodyId b : world->bodies()) {
      Eigen::Vector3d lo, hi;
      world->bounds(b, &lo, &hi);
      if (heading_for(lo, hi, world->state(b).linear_velocity, r, 0, 2 * dt)) return 2;
    }
    return 1;
  };
  std::vector<std::pair<Slot*, int>> order;
  for (Slot* s : awake) order.push_back({s, tier(*s)});
  std::stable_sort(order.begin(), order.end(), [&](const auto& a, const auto& b) {
    if (a.second != b.second) return a.second > b.second;
    return a.first->held > b.first->held;
  });
  const double avail = 0.8 * budget_ms(dt);
  double used = 0;
  std::vector<Slot*> step;
  for (auto [s, t] : order) {
    const double ms = predict_ms(s->sim->particle_count(), dt, s->steps_per_contact);
    if (t < 2 && used + ms > avail && (t == 1 || s->held < kMaxHeldFrames)) {
      ++s->held;
      ++budget_held;
      budget_held_ahead += t == 1;
      budget_longest_hold = std::max(budget_longest_hold, s->held);
      continue;
    }
    s->held = 0;
    used += ms;
    step.push_back(s);
  }
  return step;
}

// A patch's measured step: the load factor follows it (weight 0.2: a few frames to settle,
// and one slow frame, e.g. the machine busy elsewhere for a moment, does not throw it).
void TerrainManager::Impl::observe_cost(const Slot& s, double wall_ms, double dt) {
  if (pinned()) return;
  const double pred = predict_ms(awake_spheres(s), dt, s.steps_per_contact) / load;
  if (!(pred > 0) || !(wall_ms > 0)) return;
  load += 0.2 * (std::clamp(wall_ms / pred, 0.1, 100.0) - load);
}

// a and b from the first tile of the finest scale stepped in slot 0 at two sizes (a quarter
// and all of the tile's area), cut at a patch's depth as a fill is: five frames of 1/60 s each after four untimed ones (they build the grid and let the
// cut tile's first moves settle); the fastest frame of each counts (a frame slowed by
// something else running is not the DEM's cost). The slot is reset: nothing of it stays.
Status TerrainManager::Impl::calibrate() {
  if (pinned()) {
    cost_a_ms = def.budget_substep_ms, cost_b_ms = def.budget_sphere_ns * 1e-6;
    return Ok{};
  }
  const double s = all_scales().front();
  TileSet& set = set_for(s);
  if (set.tiles.empty() || slots.empty()) return Ok{};
  const GranuleTile& tile = set.tiles.front();
  const float side = set.def.box_side;
  const float top = std::min(tile.period_y + tile.surface_offset, float(patch_depth_at(s) / s));
  SimulationDef sd = sim_def(s);  // (a patch's: its skin too)
  Slot& slot = slots.front();
  // Frames of 1/60 s, or shorter where a stiff material would need more substeps than allowed.
  double dt = 1.0 / 60.0;
  for (int k = 0; k < 12 && !slot.sim->substeps_for(dt); ++k) dt *= 0.5;
  double per_sub[2] = {}, spheres[2] = {};
  for (int k = 0; k < 2; ++k) {
    const float w = k == 0 ? 0.5f * side : side;
    sd.bounds_min = {0, 0, 0};
    sd.bounds_max = {w, top + 4.0f * def.material.radius, w};
    sd.floor_height = 0;
    if (Status st = slot.sim->reset(sd); !st) return st;
    for (const PlacedGranule& g : fill_from_tile(tile, w, w, [&](float, float) { return top; }))
      if (auto id = slot.sim->add_granule(g.position, g.orientation); !id) return id.errors();
    auto n = slot.sim->substeps_for(dt);
    if (!n) return n.errors();
    for (int f = 0; f < 4; ++f)
      if (Status st = slot.sim->step(dt); !st) return st;
    double best = 1e300;
    for (int f = 0; f < 5; ++f) {
      const auto t0 = Clock::now();
      if (Status st = slot.sim->step(dt); !st) return st;
      best = std::min(best, ms_since(t0));
    }
    per_sub[k] = best / *n;
    spheres[k] = slot.sim->particle_count();
  }
  if (spheres[1] > spheres[0] && per_sub[1] > per_sub[0]) {
    cost_b_ms = (per_sub[1] - per_sub[0]) / (spheres[1] - spheres[0]);
    cost_a_ms = std::max(0.0, per_sub[0] - cost_b_ms * spheres[0]);
  } else if (spheres[1] > 0) {
    cost_b_ms = per_sub[1] / spheres[1];
    cost_a_ms = 0;
  }
  calibrated_a_ms = cost_a_ms, calibrated_b_ms = cost_b_ms;
  return slot.sim->reset(sd);
}

// Every slot run once at start-up (a small patch of the first tile filled and stepped two
// frames, then the slot reset): the slot's memory is touched, and the DEM's buffers that
// grow on a first step are grown, before any frame. Without it the first promotion into a
// slot paid them in its frame (measured on the default scene: the second slot's reset took
// 12.7 ms of a frame against 0.7 ms for the first, which calibrate had run).
Status TerrainManager::Impl::warm_slots() {
  const double s = all_scales().front();
  TileSet& set = set_for(s);
  if (set.tiles.empty()) return Ok{};
  const GranuleTile& tile = set.tiles.front();
  const float side = set.def.box_side;
  const float top = std::min(tile.period_y + tile.surface_offset, float(patch_depth_at(s) / s));
  SimulationDef sd = sim_def(s);
  sd.bounds_min = {0, 0, 0};
  sd.bounds_max = {side, top + 4.0f * def.material.radius, side};
  sd.floor_height = 0;
  const std::vector<PlacedGranule> fill = fill_from_tile(tile, side, side, [&](float, float) { return top; });
  for (Slot& slot : slots) {
    if (Status st = slot.sim->reset(sd); !st) return st;
    const std::size_t n = std::min(fill.size(), std::size_t(def.granules_per_slot));
    for (std::size_t k = 0; k < n; ++k)
      if (auto id = slot.sim->add_granule(fill[k].position, fill[k].orientation); !id) return id.errors();
    double dt = 1.0 / 60.0;
    for (int k = 0; k < 12 && !slot.sim->substeps_for(dt); ++k) dt *= 0.5;
    for (int f = 0; f < 2; ++f)
      if (Status st = slot.sim->step(dt); !st) return st;
    if (Status st = slot.sim->reset(sd); !st) return st;
  }
  return Ok{};
}

// The ladder of (particle scale ×, apron ×) a new patch steps down until it fits, each rung
// a half or less of the one before (cost ∝ area / scale³).
namespace {
struct Rung {
  double scale, apron;
};
// The whole multiples take their base scale's tiles (derive_tile_set); ×1.5 settles its own
// at creation. (×1.5, 1.5³ = 3.4 times fewer granules than scale 1, sits where the cap often
// binds: a car's 0.3 m wide wheels on 4 cm granules allow at most 1.87, and the car then runs
// at about 0.7 times real time on two cores against 0.3 at scale 1; docs/BENCHMARKS.md "A rung
// at particle scale 1.5".)
constexpr Rung kLadder[] = {{1, 1}, {1, 0.5}, {1.5, 0.5}, {2, 0.5}, {3, 0.5}};
// The rung the budget takes when a body's size barred the coarser scales: the coarsest scale
// the cap allows, without the apron (body_scale_cap).
constexpr int kTradeApronRung = 5;
// Then half the substeps (dt_sub <= t_c / N with N halved, at least kMinStepsPerContact).
// Measured on scenes/vehicle_drive.json at scale 2 without a budget (docs/BENCHMARKS.md
// "Wheels and the particle-scale cap"): N = 10 against 20 steps 0.44 times the sphere-steps
// and the car drives as far in three pairs of runs of four (10.7 / 12.9, 20.7 / 18.9,
// 18.1 / 18.8 m in 8 s; 8.7 / 8.5 m in 4 s), deepest wheel sinkage 0.12-0.20 m either way.
constexpr int kTradeSubstepsRung = 6;
constexpr int kMinStepsPerContact = 10;
}  // namespace

std::vector<double> TerrainManager::Impl::all_scales() const {
  std::vector<double> v;
  for (double base : scales()) {
    if (!budget_on()) {
      v.push_back(base);
      continue;
    }
    for (const Rung& r : kLadder)
      if (std::find(v.begin(), v.end(), base * r.scale) == v.end()) v.push_back(base * r.scale);
  }
  std::sort(v.begin(), v.end());
  return v;
}

// Granules a request would fill at scale s: its region's soil volume at the tile's packing.
int TerrainManager::Impl::predict_granules(const PatchRequest& r, double s) const {
  const TileSet& set = set_for(s);
  auto reg = region_for(r, s);
  if (!reg) return 0;
  float lo = 0, hi = 0;
  const double floor_local = floor_of(*reg, s, &lo, &hi);
  const double pf = set.tiles.empty() ? 0.6 : set.tiles.front().packing_fraction;
  const double v = soil_volume(*hf, *reg, floor_local) * pf / granule_volume(s);
  return int(std::clamp(v, 0.0, 1e9));
}

TerrainManager::Impl::BudgetChoice TerrainManager::Impl::choose(const PatchRequest& r, double dt, double others_ms) const {
  BudgetChoice c;
  c.requested_scale = r.particle_scale > 0 ? r.particle_scale : scale_for(r);
  c.scale = c.requested_scale;
  c.req = r;
  c.budget_ms = budget_ms(dt);
  // What the rest of the frame (Bullet, planning) takes is kept out of the DEM's share.
  c.available_ms = 0.8 * c.budget_ms - others_ms;
  if (!budget_on()) {
    c.granules = predict_granules(r, c.scale);
    c.predicted_ms = predict_ms(4.0 * c.granules, dt);
    return c;
  }
  c.fits = false;
  // The bodies it is for cap the scale (never below the requested one: the cap stops the
  // budget coarsening, it does not refine).
  c.body_cap = body_scale_cap(r, &c.capped_by, &c.capped_size_m);
  const double cap = c.body_cap > 0 ? std::max(c.body_cap, c.requested_scale) : std::numeric_limits<double>::infinity();
  // The rungs a request may take: those of the scales made at creation (a patch asked for
  // ahead of a body starts from its own requested scale) that the cap allows.
  const std::vector<double> made = all_scales();
  auto attempt = [&](double s, double apron, int rung, int steps_per_contact = 0) {
    PatchRequest q = r;
    const double trim = r.apron * (1.0 - apron);
    // (a patch asked for ahead of another is trimmed across the way it extends only)
    const bool along_x = r.abuts < 0 || r.abuts >= 2, along_z = r.abuts < 2;
    if (trim > 0 && along_x && q.x1 - q.x0 > 2 * trim) q.x0 += trim, q.x1 -= trim;
    if (trim > 0 && along_z && q.z1 - q.z0 > 2 * trim) q.z0 += trim, q.z1 -= trim;
    const int n = predict_granules(q, s);
    const double ms = predict_ms(4.0 * n, dt, steps_per_contact);
    c.scale = s, c.req = q, c.granules = n, c.predicted_ms = ms, c.rung = rung;
    c.req.particle_scale = s;
    c.req.steps_per_contact = c.steps_per_contact = steps_per_contact;
    c.fits = n <= def.granules_per_slot && ms <= c.available_ms;
    return c.fits;
  };
  double coarsest = 0;  // the coarsest scale tried, and its apron
  double coarsest_apron = 1;
  for (const Rung& g : kLadder) {
    const double s = c.requested_scale * g.scale;
    if (std::find(made.begin(), made.end(), s) == made.end()) continue;
    if (s > cap * (1 + 1e-9)) {
      c.cap_bound = true;
      continue;
    }
    coarsest = s, coarsest_apron = g.apron;
    if (attempt(s, g.apron, int(&g - kLadder))) return c;
  }
  // The cap barred the coarser scales: at the coarsest scale the cap allows, the budget gives
  // up the apron (the patch covers the bodies' predicted footprint and 4 r s only), then half
  // of the DEM's substeps (N = steps_per_contact halved, not below kMinStepsPerContact).
  if (!c.cap_bound || coarsest <= 0) return c;
  // (the apron kept: two sphere diameters at that scale, 4 r s, the margin at which a body
  // nearing a patch's edge has a patch asked for beyond it (planning.cpp extend): less, and
  // the patch would at once ask for one beside it)
  double apron = coarsest_apron;
  const double keep = r.apron > 0 ? std::min(1.0, 4.0 * radius_world(coarsest) / r.apron) : 1.0;
  if (r.apron > 0 && apron > keep) {
    c.traded.push_back("apron");
    apron = keep;
    if (attempt(coarsest, apron, kTradeApronRung)) return c;
  }
  const int n_half = std::max(kMinStepsPerContact, def.steps_per_contact / 2);
  if (n_half < def.steps_per_contact) {
    c.traded.push_back("substeps");
    attempt(coarsest, apron, kTradeSubstepsRung, n_half);
  }
  return c;
}

TerrainManager::Impl::BudgetChoice TerrainManager::Impl::choose_successor(const PatchRequest& r, const Slot& pred, double dt,
                                                                          double live_ms) const {
  BudgetChoice c;
  c.requested_scale = c.scale = pred.scale;
  c.req = r;
  c.req.particle_scale = pred.scale;
  c.granules = predict_granules(r, pred.scale);
  c.budget_ms = budget_ms(dt);
  const int own = pred.steps_per_contact > 0 ? pred.steps_per_contact : def.steps_per_contact;
  // (its predecessor's cost leaves with it)
  const double pred_ms = predict_ms(slot_spheres(pred, record(pred).granules), dt, pred.steps_per_contact);
  c.available_ms = 0.8 * c.budget_ms - std::max(0.0, live_ms - pred_ms);
  c.steps_per_contact = pred.steps_per_contact;
  c.predicted_ms = predict_ms(4.0 * c.granules, dt, own);
  c.fits = !budget_on() || c.predicted_ms <= c.available_ms;
  const int n_half = std::max(kMinStepsPerContact, def.steps_per_contact / 2);
  if (!c.fits && own > n_half) {
    c.traded.push_back("substeps");
    c.rung = kTradeSubstepsRung;
    c.steps_per_contact = n_half;
    c.predicted_ms = predict_ms(4.0 * c.granules, dt, n_half);
    c.fits = c.predicted_ms <= c.available_ms;
  }
  c.req.steps_per_contact = c.steps_per_contact;
  return c;
}

}  // namespace sandpatch
