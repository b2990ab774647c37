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
  return std::max(s.sim->particle_count(), 4 * (granules + int(s.pending.size()) - int(s.uploaded)));
}

double TerrainManager::Impl::substeps(double dt) const {
  if (slots.empty()) return 1;
  auto n = slots.front().sim->substeps_for(dt);
  return n ? double(*n) : 1.0;
}

double TerrainManager::Impl::predict_ms(double spheres, double dt) const {
  return load * substeps(dt) * (cost_a_ms + cost_b_ms * spheres);
}

// (a patch the budget may hold, one no body wants, leaves its room to a new one)
double TerrainManager::Impl::live_cost_ms(double dt) const {
  double ms = 0;
  for (const Slot& s : slots)
    if (s.state == SlotState::Filling || (s.state == SlotState::Active && (!budget_on() || wanted(s))))
      ms += predict_ms(slot_spheres(s, record(s).granules), dt);
  return ms;
}

// Whether a patch is wanted this frame: it carries a body, or a body is over or heading for
// its region (its bounds, grown by lod.margin and by how far it goes in lod.horizon at its
// horizontal speed, overlap the region). A patch not wanted (its body left, or was removed)
// may be held by the budget and does not count against a new patch's room.
bool TerrainManager::Impl::wanted(const Slot& s) const {
  for (const Carried& c : s.carried)
    if (c.enabled) return true;
  const PatchRequest r = rect(s);
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    const Eigen::Vector3f v = world->state(b).linear_velocity;
    const double reach = def.lod.margin + std::hypot(double(v.x()), double(v.z())) * def.lod.horizon;
    if (lo.x() - reach < r.x1 && hi.x() + reach > r.x0 && lo.z() - reach < r.z1 && hi.z() + reach > r.z0) return true;
  }
  return false;
}

// Which awake patches step this frame. Wanted patches always step. The others (settling
// after their body left) step, the longest held first, while the predicted DEM of everything
// stepped so far fits 80 % of the budget (the share `choose` gives the DEM); one that does not
// fit is held this frame: not stepped, its granules where they are, its time behind the
// frame's (nothing outside the patch reads it). A patch is held at most kMaxHeldFrames in a
// row, so it still settles and sleeps, at a fraction of the rate. Without a budget every
// awake patch steps, in slot order.
std::vector<Slot*> TerrainManager::Impl::stepping_order(const std::vector<Slot*>& awake, double dt) {
  if (!budget_on()) return awake;
  constexpr int kMaxHeldFrames = 30;
  std::vector<std::pair<Slot*, bool>> order;
  for (Slot* s : awake) order.push_back({s, wanted(*s)});
  std::stable_sort(order.begin(), order.end(), [&](const auto& a, const auto& b) {
    if (a.second != b.second) return a.second;
    return a.first->held > b.first->held;
  });
  const double avail = 0.8 * budget_ms(dt);
  double used = 0;
  std::vector<Slot*> step;
  for (auto [s, want] : order) {
    const double ms = predict_ms(s->sim->particle_count(), dt);
    if (!want && used + ms > avail && s->held < kMaxHeldFrames) {
      ++s->held;
      ++budget_held;
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
  const double pred = predict_ms(s.sim->particle_count(), dt) / load;
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
// Whole multiples, so a coarser rung's tiles are its base scale's (derive_tile_set).
constexpr Rung kLadder[] = {{1, 1}, {1, 0.5}, {2, 0.5}, {3, 0.5}};
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
  // The rungs a request may take: those of the scales made at creation (a patch asked for
  // ahead of a body starts from its own requested scale).
  const std::vector<double> made = all_scales();
  for (const Rung& g : kLadder) {
    const double s = c.requested_scale * g.scale;
    if (std::find(made.begin(), made.end(), s) == made.end()) continue;
    PatchRequest q = r;
    const double trim = r.apron * (1.0 - g.apron);
    if (trim > 0 && q.x1 - q.x0 > 2 * trim && q.z1 - q.z0 > 2 * trim) q.x0 += trim, q.x1 -= trim, q.z0 += trim, q.z1 -= trim;
    const int n = predict_granules(q, s);
    const double ms = predict_ms(4.0 * n, dt);
    c.scale = s, c.req = q, c.granules = n, c.predicted_ms = ms, c.rung = int(&g - kLadder);
    c.req.particle_scale = s;
    if (n <= def.granules_per_slot && ms <= c.available_ms) {
      c.fits = true;
      break;
    }
  }
  return c;
}

}  // namespace sandpatch
