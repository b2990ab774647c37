// The terrain manager's filling (Stage::Activation): pre-settled tiles, promotion of a request
// into a pool slot (heightfield -> granules), and the granules' upload in chunks. See
// terrain_manager_impl.hpp.
#include <algorithm>
#include <string_view>
#include <numbers>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "manager/terrain_manager_impl.hpp"
#include "manager/tile_cache.hpp"

namespace sandpatch {

using manager_detail::Clock;
using manager_detail::ms_since;
using manager_detail::v3;

// One conversion part a frame (docs/manager.md "No frame does a whole patch's work"): a
// promotion is its slot's reset, then the fill's cut, then uploads of at most
// fill_granules_per_frame granules, each part in its own frame; a patch released for a
// request is demoted one part a frame while it is held (not stepped); the demotion stage's
// idle demotions take a frame in which no part ran. Only a patch a body would reach within
// two frames is finished at once (every part it has left, in this frame).
Status TerrainManager::Impl::activate(double time, double dt) {
  // Patches a body is about to reach: everything they have left, now (and again after the
  // queue is served: a patch promoted for a body that close is finished in the same frame).
  auto finish_due = [&]() -> Status {
    for (auto& s : slots) {
      if (s.state != SlotState::Filling) continue;
      bool due = false;
      // (a successor covers its bodies from the start, carried meanwhile by the patch it will
      // take over: it is due when a body would leave that patch's region within two frames)
      const Slot* pred = s.predecessor >= 0 ? &slots[std::size_t(s.predecessor)] : nullptr;
      for (RigidBodyId b : world->bodies()) {
        Eigen::Vector3d lo, hi;
        world->bounds(b, &lo, &hi);
        bool inside = false;
        const Eigen::Vector3d v = world->state(b).linear_velocity.cast<double>();
        const Eigen::Vector3d ahead = 2.0 * dt * v;
        const Eigen::Vector3d a = lo + ahead.cwiseMin(0.0), z = hi + ahead.cwiseMax(0.0);
        if (!engages(s, a, z, &inside)) continue;
        if (pred) {
          const PatchRequest p = rect(*pred);
          if (a.x() >= p.x0 && z.x() <= p.x1 && a.z() >= p.z0 && z.z() <= p.z1) continue;
          // A body the predecessor carries is due only when it would pass one of the sides the
          // successor reaches beyond (a wheel straddling the side between a car's two track
          // patches, or its chassis riding above them, made every successor due at once).
          bool carried = false;
          for (const Carried& c : pred->carried)
            carried = carried || (c.enabled && c.body.index == b.index && c.body.generation == b.generation);
          if (carried) {
            const PatchRequest q = rect(s);
            const double e = 1e-6;
            const bool leaving = (q.x0 < p.x0 - e && a.x() < p.x0) || (q.x1 > p.x1 + e && z.x() > p.x1) ||
                                 (q.z0 < p.z0 - e && a.z() < p.z0) || (q.z1 > p.z1 + e && z.z() > p.z1);
            if (!leaving) continue;
          } else if (carried_anywhere(b)) {
            continue;  // (another patch carries it)
          }
          // Nor one that would not touch the sand within these two frames, carried or not: its
          // lowest point (moved two frames on, linearly and, at its reach, by its turning) not
          // within a granule sphere diameter of the surface. A car's chassis riding above the
          // sand: its front, 0.65 m ahead of the front wheels, made the car's successors due as
          // they were asked, and, with the height at which its shell would join a patch
          // (join_height, which grows as it pitches), still made 3 of 10 due under a 0.5 ms
          // budget with its lowest corner 0.38 m above the sand.
          const double reach = 0.5 * (hi - lo).norm();
          const double turning = double(world->state(b).angular_velocity.norm()) * reach * 2.0 * dt;  // m
          if (!engages(s, a, z, &inside, 2.0 * radius_world(s) + turning)) continue;
        }
        due = true;
      }
      if (!due) continue;
      ++work.urgent_fills;
      ++urgent_fills;
      if (!s.cut)
        if (Status st = cut(s, time, kWhole); !st) return st;
      if (Status st = upload(s, s.pending.size(), time); !st) return st;
    }
    return Ok{};
  };
  if (Status st = finish_due(); !st) return st;
  int used = 0;
  for (auto& s : slots) used += s.state != SlotState::Free;
  peak_slots = std::max(peak_slots, used);
  if (work.conversion_parts > 0) return Ok{};
  // A promotion under way: its next part (the one promoted first, when two are).
  Slot* filling = nullptr;
  for (auto& s : slots)
    if (s.state == SlotState::Filling && (!filling || s.patch < filling->patch)) filling = &s;
  if (filling) {
    const auto t0 = Clock::now();
    const bool cutting = !filling->cut;
    const Status st = cutting ? cut(*filling, time, kCutUnitsPerFrame) : upload(*filling, std::size_t(def.fill_granules_per_frame), time);
    time_part(cutting ? Part::Cut : Part::Upload, ms_since(t0));
    return st;
  }
  // A release under way: its next part, or none if a body came back to it. Not while a
  // patch asked for ahead of a carried body (a successor, or one abutting ahead) waits and a
  // slot is free for it: the release has no body waiting on it, that request has one coming
  // (waiting, its fill fell whole into the frame the body reached it: `urgent_fills`).
  const bool slot_free = std::any_of(slots.begin(), slots.end(), [](const Slot& s) { return s.state == SlotState::Free; });
  const bool carried_waits =
      std::any_of(queue.begin(), queue.end(), [](const PatchRequest& q) { return q.successor_of >= 0 || q.ahead_of_carried; });
  for (auto& s : slots) {
    if (slot_free && carried_waits) break;
    if (!s.demotion.releasing) continue;
    if (!s.superseded && wanted_for_release(s)) {  // (a patch taken over is demoted whatever is over it)
      s.demotion = {};
      break;
    }
    if (Status st = demote(s, time, false, /*staged=*/true); !st) return st;
    released += s.state == SlotState::Free;
    return Ok{};
  }
  // Serve the queue: the first request that may start takes a free slot, at the scale and
  // extent the frame budget allows (budget.cpp); a request that does not fit waits while other
  // patches live.
  const double live_ms = live_cost_ms(dt);
  for (auto it = queue.begin(); it != queue.end();) {
    auto free = std::find_if(slots.begin(), slots.end(), [](const Slot& s) { return s.state == SlotState::Free; });
    if (free == slots.end()) {
      // A patch no body is over gives its slot to the request: demoted one part a frame,
      // the request promoted in the frame after the last part.
      auto r = release_idle(time, it->successor_of >= 0 || it->ahead_of_carried);
      if (!r) return r.errors();
      break;
    }
    // A successor (planning.cpp ask_successor) overlaps the patch it will take over, and only
    // that one; it takes that patch's scale and N, and replaces its cost rather than adding to it.
    Slot* pred = nullptr;
    if (it->successor_of >= 0) {
      for (Slot& sl : slots)
        if (sl.ready() && sl.patch == it->successor_of && !sl.superseded && !sl.demotion.releasing) pred = &sl;
      bool clear = pred != nullptr;
      for (const Slot& sl : slots)
        if (clear && sl.live() && &sl != pred && rect(sl).overlaps(*it)) clear = false;
      if (!clear) {
        it = queue.erase(it);
        continue;
      }
    } else if (overlaps_patch(*it) || !has_soil(*it)) {
      it = queue.erase(it);
      continue;
    }
    const BudgetChoice c = pred ? choose_successor(*it, *pred, dt, live_ms) : choose(*it, dt, live_ms);
    // (a live patch no body wants any more is being wound down: it does not make a request
    // wait, as it does not take a new patch's room; budget.cpp wanted)
    const bool others = std::any_of(slots.begin(), slots.end(), [&](const Slot& s) {
      return s.state == SlotState::Filling || (s.live() && (!budget_on() || wanted(s)));
    });
    // A patch asked for ahead of a body that a live patch carries (planning.cpp extend) does
    // not wait: waiting, the body reaches its patch's edge before the next patch is filled,
    // and then either the whole fill falls in one frame or the body stops at the edge. It is
    // filled part by part at the rung the budget chose, and counted as an overrun.
    if (!c.fits && others && !it->ahead_of_carried) {
      ++budget_waits;
      ++it->waited_frames;
      ++it;
      continue;
    }
    if (!pred && !has_soil(c.req)) {
      it = queue.erase(it);
      continue;
    }
    const auto t0 = Clock::now();
    if (Status s = promote(*free, c.req, time); !s) return s;
    time_part(Part::Reset, ms_since(t0));
    if (pred) {
      free->predecessor = int(pred - slots.data());
      pred->successor = int(free - slots.begin());
    }
    free->predicted_granules = c.granules;
    free->budget_entry = -1;
    budget_overruns += !c.fits;
    if (budget_on()) {
      free->budget_entry = int(budget_log.size());
      budget_log.push_back({{"patch", free->patch},
                            {"time_s", time},
                            {"requested_scale", c.requested_scale},
                            {"particle_scale", free->scale},
                            {"apron_m", it->apron},
                            {"apron_used_m", it->apron - std::max(c.req.x0 - it->x0, c.req.z0 - it->z0)},
                            {"rung", c.rung},
                            {"granules", c.granules},
                            {"granules_predicted", c.granules},
                            {"predicted_ms", c.predicted_ms},
                            {"available_ms", c.available_ms},
                            {"fits", c.fits},
                            {"body_cap_scale", c.body_cap},
                            {"cap_bound", c.cap_bound},
                            {"traded", c.traded},
                            {"steps_per_contact", free->steps_per_contact > 0 ? free->steps_per_contact : def.steps_per_contact}});
      if (c.body_cap > 0) budget_log.back()["capped_by"] = {{"body", c.capped_by}, {"smallest_dimension_m", c.capped_size_m}};
      // A patch that does not fit even with half the substeps (rung 5) joins patches that
      // step at the full N (made when they fitted): those take its N from now on, so the
      // frames in which they step together (a car straddling the edge between two patches)
      // cost what the budget's last rung assumed.
      if (!c.fits && free->steps_per_contact > 0)
        if (Status st = trade_live_substeps(*free, time); !st) return st;
    }
    queue.erase(it);
    if (Status st = finish_due(); !st) return st;
    break;
  }
  used = 0;
  for (auto& s : slots) used += s.state != SlotState::Free;
  peak_slots = std::max(peak_slots, used);
  return Ok{};
}

// The live patches other than `to` that step at a larger N than `to` (a patch the budget
// promoted at half the substeps and still over it) take its N: set_steps_per_contact on
// their DEM, their budget entry notes "substeps (live)" and when.
Status TerrainManager::Impl::trade_live_substeps(const Slot& to, double time) {
  const int n = to.steps_per_contact;
  for (Slot& s : slots) {
    if (&s == &to || s.state == SlotState::Free || !s.sim || s.sim->def().accuracy_steps_per_contact <= n) continue;
    if (Status st = s.sim->set_steps_per_contact(n); !st) return st;
    s.steps_per_contact = n;
    ++budget_live_trades;
    if (s.budget_entry >= 0 && s.budget_entry < int(budget_log.size())) {
      auto& e = budget_log[std::size_t(s.budget_entry)];
      e["traded"].push_back("substeps (live)");
      e["steps_per_contact"] = n;
      e["live_trade_s"] = time;
    }
  }
  return Ok{};
}

// The first pre-settled tile of a scale, for patches patch_depth deep plus half as much
// relief (granule_tile.hpp); deeper patches settle deeper tiles when they come (tile_for).
Status TerrainManager::Impl::add_tile_set(double scale) {
  TileSet& set = tile_sets.emplace_back();
  set.scale = scale;
  GranuleTileDef& td = set.def;
  td.radius = def.material.radius;
  td.material = sim_def(scale).material;
  // A bed at rest does not depend on the unloading branch of a hysteretic spring, but its pour
  // does: every impact of the settling keeps its overlap's plastic set, and at game stiffness
  // (2e4 N/m under 4 cm granules) the tile compacted to a packing of 0.90 against the linear
  // law's 0.61 (docs/dem.md "Which normal law is the default"). So a hysteretic material's tile
  // is poured with the linear spring at the same binary restitution (1/sqrt(lambda) of its
  // dashpot's), and the patch then loads its contacts along the same loading branch k_n.
  if (td.material.unloading_stiffness_ratio > 1.0f) {
    td.material.restitution =
        std::clamp(td.material.restitution / std::sqrt(td.material.unloading_stiffness_ratio), 0.05f, 1.0f);
    td.material.unloading_stiffness_ratio = 1.0f;
  }
  td.gravity = v3(Eigen::Vector3f((def.gravity / scale).cast<float>()));
  td.seed = def.seed;
  td.threads = def.threads;
  {
    // The tile's period: a whole number of heightfield cells near 6 lattice spacings.
    const GranuleShape shape = make_granule_shape(def.material.radius, 1.0f, def.material.density);
    const double a = 2.0 * (shape.centre_distance + shape.radius) * 1.02 * scale;  // m, world
    set.cells = std::max(1, int(std::ceil(6.0 * a / hf->spacing())));
    td.box_side = float(set.cells * double(hf->spacing()) / scale);
  }
  td.surface_probe = float(def.surface_probe) * def.material.radius;
  // Settled with μ ≤ 0.2 the block packs denser (solid fraction of the spheres 0.527 against
  // 0.472 at μ = 0.5, same settling time; μ = 0 did not come to rest in 4 s), closer to sand
  // at rest, which a body then displaces (a crater with a rim) rather than compacts.
  td.settle_friction = std::min(0.2f, def.material.friction);
  // The first tile holds a patch of up to 2 tile periods anywhere on this terrain: its fill
  // depth is the patch depth plus the terrain's relief over such a window (bounded from the
  // min/max of blocks of one period; 3 × 3 blocks cover any window of 2 periods). Settling
  // a deeper tile when a patch comes costs seconds in that frame (measured: 24.8 s on the
  // default scene under load), so start-up pays it.
  const Heightfield& h = *hf;
  double relief = 0;
  {
    const int B = set.cells, bx = (h.samples_x() + B - 1) / B, bz = (h.samples_z() + B - 1) / B;
    std::vector<float> lo(std::size_t(bx) * bz, std::numeric_limits<float>::max()), hi(lo.size(), -std::numeric_limits<float>::max());
    for (int j = 0; j < h.samples_z(); ++j)
      for (int i = 0; i < h.samples_x(); ++i) {
        const std::size_t k = std::size_t(j / B) * bx + std::size_t(i / B);
        lo[k] = std::min(lo[k], h.height(i, j));
        hi[k] = std::max(hi[k], h.height(i, j));
      }
    for (int cj = 0; cj < bz; ++cj)
      for (int ci = 0; ci < bx; ++ci) {
        float a = std::numeric_limits<float>::max(), b = -a;
        for (int j = cj; j < std::min(bz, cj + 3); ++j)
          for (int i = ci; i < std::min(bx, ci + 3); ++i) {
            a = std::min(a, lo[std::size_t(j) * bx + i]);
            b = std::max(b, hi[std::size_t(j) * bx + i]);
          }
        relief = std::max(relief, double(b - a));
      }
  }
  // (At most the patch depth again of relief: steeper terrain settles deeper tiles when a
  // patch there needs one, rather than making every start-up slow. A budget's coarser rung that
  // settles its own tiles (budget.cpp kLadder) takes the patch depth again whatever the relief:
  // its patches travel under vehicles whose ruts and rims raise the surface a successor is cut
  // to, and a tile settled in a frame took 1.9 s of it.)
  const double depth0 = patch_depth_at(scale);
  const double above = coarser_rung(scale) ? depth0 : std::min(relief, depth0);
  if (auto t = tile_for(set, (depth0 + above) / scale); !t) return t.errors();
  return Ok{};
}

// A set for scale m × s of a set made for s (m a whole number, the budget's coarser rungs):
// the same tiles, m times as many heightfield cells per period. Its tiles were settled under
// g / s, not g / (m s): at the coarser scale the fill rises by less than the tile's rebound
// (GranuleTile::rebound, a few per cent of a radius). A deeper tile it needs is settled
// under its own gravity.
bool TerrainManager::Impl::derive_tile_set(double scale) {
  for (const TileSet& base : tile_sets) {
    const double m = scale / base.scale;
    if (std::abs(m - std::round(m)) > 1e-9 || m < 2) continue;
    TileSet set = base;
    set.scale = scale;
    set.cells = base.cells * int(std::round(m));
    set.def.gravity = v3(Eigen::Vector3f((def.gravity / scale).cast<float>()));
    tile_sets.push_back(std::move(set));
    return true;
  }
  return false;
}

// Lattice layers that settle into a tile of at least `depth` (m, sim units) of period_y: a
// first guess (0.8 × 2 bounding radii a settled layer); one too shallow is settled again with
// the layers scaled by what it gave (tile_for). The guess errs shallow (a jittered lattice
// settles to about half that), so a first start-up settles a scene's tile twice; the tile it
// ends with is about 1.3 times the fill deep. Settled to just the fill's depth in one go
// (measured), fills took the tile's floor-packed bottom layers and leach_3's ledgers closed at
// -6 % instead of +1.2 %, and the round trip and no-hop tests moved past their bounds; the
// build settles the default scene's tiles instead (apps/sandpatch/CMakeLists.txt).
int TerrainManager::Impl::tile_layers(const GranuleTileDef& td, double fill_depth) const {
  (void)td;
  const GranuleShape shape = make_granule_shape(float(def.material.radius), 1.0f, def.material.density);
  const double layer = 2.0 * (shape.centre_distance + shape.radius) * 0.8;  // settled layer height, about
  return std::max(6, int(std::ceil(fill_depth * 1.6 / layer)) + 3);
}

// The shallowest tile of a set whose period holds a fill `depth` (m, sim units) deep.
Result<const GranuleTile*> TerrainManager::Impl::tile_for(TileSet& set, double fill_depth) {
  std::vector<GranuleTile>& tiles = set.tiles;
  auto holds = [&](const GranuleTile& t) { return fill_depth - t.surface_offset <= t.period_y; };
  for (const GranuleTile& t : tiles)
    if (holds(t)) return &t;
  GranuleTileDef td = set.def;
  td.layers = tile_layers(td, 1.1 * fill_depth);
  for (int attempt = 0; attempt < 3; ++attempt) {
    const auto t0 = Clock::now();
    if (def.on_settle) {
      char what[160];
      std::snprintf(what, sizeof what, "settling a granule tile (particle scale %g, %d lattice layers, %.2f m deep)", set.scale,
                    td.layers, fill_depth * set.scale);
      const std::string name = what;
      td.on_progress = [this, name, t0](double done, double max) { def.on_settle(name, done, max, ms_since(t0) * 1e-3); };
    }
    TileCacheOutcome from;
    auto t = cached_granule_tile(td, tile_cache, &from, tile_fallback);
    if (!from.note.empty()) tile_cache_notes.push_back(from.note);
    ++tiles_from[int(from.source)];
    tiles_settled_ms += ms_since(t0);
    if (!t) return t.errors();
    if (holds(*t)) {
      tiles.push_back(std::move(*t));
      std::sort(tiles.begin(), tiles.end(), [](const GranuleTile& a, const GranuleTile& b) { return a.period_y < b.period_y; });
      return tile_for(set, fill_depth);
    }
    // Too shallow: scale the lattice layers by what this one settled to (a block settles
    // to a depth roughly proportional to its layers, less the rough top) and try again.
    const double got = std::max(1e-6, double(t->period_y) + t->surface_offset);
    td.layers = int(std::ceil(td.layers * 1.05 * (fill_depth + 2.0 * double(t->shape.centre_distance + t->shape.radius)) / got));
  }
  return Error{"", "terrain.patch_depth", std::to_string(fill_depth * set.scale),
               "no pre-settled granule tile this deep could be made; lower terrain.patch_depth"};
}

SimulationDef TerrainManager::Impl::sim_def(double scale) const {
  SimulationDef sd;
  sd.max_bodies = def.granules_per_slot + 64;
  sd.max_particles = 4 * def.granules_per_slot + def.shell_particles_per_slot;
  sd.particle_radius = def.material.radius;
  sd.material.density = def.material.density;
  sd.material.normal_stiffness = def.material.stiffness;
  sd.material.restitution = def.material.restitution;
  sd.material.friction = def.material.friction;
  sd.material.tangential_stiffness_ratio = def.material.tangential_stiffness_ratio;
  sd.material.unloading_stiffness_ratio = def.material.unloading_stiffness_ratio;
  sd.gravity_world = v3(Eigen::Vector3f(def.gravity.cast<float>()));
  sd.sleep_speed = float(def.sleep_speed / scale);
  sd.sleep_time = float(def.sleep_time);
  sd.region_sleep_time = float(def.region_sleep_time);
  sd.sleep_regions = def.sleep_regions && def.backend == "cpu";  // (the GL backend steps every granule)
  sd.threads = def.threads;
  // dt <= t_c / N; a frame may take as many substeps as 64 at N = 20 allowed (the same
  // frame length in contact times), so a finer N never refuses a frame a coarser one runs.
  sd.accuracy_steps_per_contact = def.steps_per_contact;
  sd.max_substeps = def.max_substeps > 0 ? def.max_substeps : std::max(64, (64 * def.steps_per_contact + 19) / 20);
  // The DEM's overlap guard refuses a step when a body could overlap something immovable by
  // more than a fraction of r. In a patch a body lands on granules that give way (a 30 kg
  // barrel at 3 m/s on k_n = 2e4 N/m trips it while the bed stops it within 0.2 m:
  // TerrainManager.BarrelLeavesCraterAndRim), and refusing a frame mid-run helps no one; so
  // the guard is off here and the patch floor, 2 granule layers deep at least, stops bodies.
  sd.max_overlap_fraction = 0;
  // Neighbour-list skin 0.5 r (the DEM's default is 0.2 r): the list is rebuilt whenever one
  // sphere has moved skin/2, and a patch under a landing or rolling body always has fast
  // granules and shell spheres, so it rebuilt every 2-3 substeps at 0.2 r, and the rebuilds were
  // over half of its DEM time. At 0.5 r: 2.3x fewer rebuilds for about as costly a pair pass,
  // 1.3x the sphere-steps/s at one thread (docs/BENCHMARKS.md, "The DEM inside a scene").
  sd.cell_skin = 0.5f * def.material.radius;
  return sd;
}

Status TerrainManager::Impl::promote(Slot& slot, const PatchRequest& req, double time) {
  const auto t0 = Clock::now();
  PatchRecord& rec = record(slot);
  const double s = scale_for(req);
  auto reg = region_for(req, s);
  if (!reg) return reg.errors();
  const GridRegion region = *reg;
  const float sp = hf->spacing();
  float lo = 0, hi = 0;
  double floor_local = floor_of(region, s, &lo, &hi);
  // (a successor keeps its predecessor's floor and frame height: the granules it takes over
  // keep their heights; ask_successor made sure the floors agree)
  for (const Slot& p : slots)
    if (req.successor_of >= 0 && p.live() && p.patch == req.successor_of) {
      floor_local = p.floor_local;
      hi = std::max(hi, float(p.top_local));
    }
  if (!(floor_local < hi)) return Error{"", "patch request", "", "no soil above the bedrock there"};
  slot.patch = next_patch++;
  slot.scale = s;
  slot.region = region;
  const int band = 4;  // samples around the region where spilled granules rest on the terrain
  slot.apron = {std::max(0, region.i0 - band), std::max(0, region.j0 - band), 0, 0};
  slot.apron.ni = std::min(hf->samples_x(), region.i0 + region.ni + band) - slot.apron.i0;
  slot.apron.nj = std::min(hf->samples_z(), region.j0 + region.nj + band) - slot.apron.j0;
  slot.floor_local = floor_local;
  slot.top_local = hi;
  slot.origin = {hf->origin_x() + region.i0 * double(sp), hf->origin_y() + floor_local,
                 hf->origin_z() + region.j0 * double(sp)};
  rec.before_heights.resize(std::size_t(slot.apron.ni) * slot.apron.nj);
  hf->read(slot.apron, rec.before_heights.data());

  // The simulation: unit scale, patch-relative; the terrain around the region as a grid.
  SimulationDef sd = sim_def(s);
  // (the frame budget may have lowered the DEM's N for this patch: budget.cpp)
  if (req.steps_per_contact > 0) sd.accuracy_steps_per_contact = req.steps_per_contact;
  slot.steps_per_contact = req.steps_per_contact;
  const float W = float((region.ni - 1) * double(sp) / s), D = float((region.nj - 1) * double(sp) / s);
  const float top = float((hi - floor_local) / s);
  sd.bounds_min = {0, 0, 0};
  // Room above the surface for bodies' shells (spheres above the grid would all share its
  // top layer of cells and slow the search); shells engage only within `engage_height`.
  sd.bounds_max = {W, top + float(engage_height / s) + 2.0f * float(def.material.radius), D};
  sd.floor_height = 0;
  auto sc = ParticleScale::create(s, {slot.origin.x(), slot.origin.y(), slot.origin.z()});
  if (!sc) return sc.errors();
  sd.scale = *sc;
  TerrainGrid& tg = sd.terrain;
  tg.nx = slot.apron.ni;
  tg.nz = slot.apron.nj;
  tg.x0 = float((slot.apron.i0 - region.i0) * double(sp) / s);
  tg.z0 = float((slot.apron.j0 - region.j0) * double(sp) / s);
  tg.spacing = float(sp / s);
  tg.heights.resize(rec.before_heights.size());
  for (std::size_t k = 0; k < tg.heights.size(); ++k) tg.heights[k] = float((rec.before_heights[k] - floor_local) / s);
  tg.fill_min_x = 0;
  tg.fill_min_z = 0;
  tg.fill_max_x = W;
  tg.fill_max_z = D;
  if (Status st = slot.sim->reset(sd); !st) return st.errors();
  slot.pending.clear();
  slot.uploaded = 0;
  slot.cut = false;
  slot.cutter.reset();
  rec.granules = 0;
  rec.fill_spheres.clear();
  slot.fade = 0;
  slot.asleep_for = 0;
  slot.held = 0;
  slot.demotion = {};
  slot.carried.clear();
  slot.predecessor = slot.successor = slot.rebase_from = -1;
  slot.superseded = false;
  slot.inherited.clear();
  slot.state = SlotState::Filling;
  rec.fill_ms = ms_since(t0);
  ++work.conversion_parts;
  return Ok{};
}

// The promotion's second part: the fill cut from the pre-settled tile to the surface (the
// heights read by the first part), the bodies over it cleared, the render baseline and the
// ledger. The patch is then uploaded in chunks (upload).
Status TerrainManager::Impl::cut(Slot& slot, double time, std::size_t units) {
  const auto t0 = Clock::now();
  PatchRecord& rec = record(slot);
  const double s = slot.scale;
  const GridRegion region = slot.region;
  const float sp = hf->spacing();
  const double floor_local = slot.floor_local;
  auto sc = ParticleScale::create(s, {slot.origin.x(), slot.origin.y(), slot.origin.z()});
  if (!sc) return sc.errors();
  const PatchRequest req = rect(slot);
  ++work.conversion_parts;
  if (!slot.cutter) {
    // Granules from the pre-settled tile, cut to the surface (the heightfield the frames of
    // the cut read is the one the slot's reset read: no demotion writes it meanwhile, as no
    // other conversion part runs).
    const float W = float((region.ni - 1) * double(sp) / s), D = float((region.nj - 1) * double(sp) / s);
    const float top = float((slot.top_local - floor_local) / s);
    auto tile_r = tile_for(set_for(s), top);
    if (!tile_r) return tile_r.errors();
    const GranuleTile& tile = **tile_r;
    const Heightfield* h = hf;
    auto surface = [h, region, sp, s, floor_local](float x, float z) {
      const double xl = region.i0 * double(sp) + x * s, zl = region.j0 * double(sp) + z * s;
      return float((h->sample(float(xl), float(zl)) - floor_local) / s);
    };
    slot.cutter = std::make_unique<FillCut>(tile, W, D, surface);
    if (slot.predecessor >= 0) {
      // A successor places its fill only beyond its predecessor (below): the tile copies inside
      // the predecessor's region, but for those a period deep along each side the successor
      // reaches past (their granules decide what is kept across the seam), are not cut. (They
      // were three quarters of a car's track-patch cut, whose sort of every candidate took
      // 1.9 ms of one frame.)
      const GridRegion& q = slots[std::size_t(slot.predecessor)].region;
      const double P = double(tile.period_xz);
      auto local = [&](int samples) { return samples * double(sp) / s; };  // (sim units, from region's corner)
      double x0 = local(q.i0 - region.i0), x1 = local(q.i0 + q.ni - 1 - region.i0);
      double z0 = local(q.j0 - region.j0), z1 = local(q.j0 + q.nj - 1 - region.j0);
      if (region.i0 < q.i0) x0 += P;
      if (region.i0 + region.ni > q.i0 + q.ni) x1 -= P;
      if (region.j0 < q.j0) z0 += P;
      if (region.j0 + region.nj > q.j0 + q.nj) z1 -= P;
      // (widened by a hair: a copy ending on one of its lines lies within, round-off aside)
      const double e = 1e-4 * P;
      slot.cutter->skip_copies_within(float(x0 - e), float(x1 + e), float(z0 - e), float(z1 + e));
    }
    slot.cut_shape = tile.shape;
    slot.cut_rebound = tile.rebound;
    slot.cut_packing = tile.packing_fraction;
  }
  const bool finished = slot.cutter->step(units);
  if (!finished) {
    rec.fill_ms += ms_since(t0);
    return Ok{};
  }
  slot.pending = slot.cutter->take();
  slot.cutter.reset();
  if (slot.predecessor >= 0) {
    // A successor's fill only where it reaches past its predecessor (whose granules it takes
    // over, take_over): granules centred inside that patch's region are not placed. The region
    // is its own moved by whole tile periods, so the line between them is a tile wall.
    const PatchRequest p = rect(slots[std::size_t(slot.predecessor)]);
    std::size_t kept = 0;
    for (const PlacedGranule& g : slot.pending) {
      const auto w = sc->position_to_world(g.position);
      if (w[0] >= p.x0 && w[0] <= p.x1 && w[2] >= p.z0 && w[2] <= p.z1) continue;
      slot.pending[kept++] = g;
    }
    slot.pending.resize(kept);
  }
  struct {
    const GranuleShape& shape;
    float rebound, packing_fraction;
  } tile{slot.cut_shape, slot.cut_rebound, slot.cut_packing};
  if (Status st = clear_bodies(slot, *sc, tile.shape, s); !st) return st.errors();
  if (int(slot.pending.size()) > def.granules_per_slot) {
    return Error{"", "simulation.pool.granules_per_slot", std::to_string(def.granules_per_slot),
                 "too small: the patch around the contact at (" + std::to_string(0.5 * (req.x0 + req.x1)) + ", " +
                     std::to_string(0.5 * (req.z0 + req.z1)) + ") needs " + std::to_string(slot.pending.size()) +
                     " granules; raise it, or lower terrain.soil_depth / coarsen the granules"};
  }
  // The fill's spheres, heightfield-local (m), for the demotion's render baseline.
  rec.fill_rise = float(tile.rebound * s);
  rec.fill_spheres.clear();
  rec.fill_spheres.reserve(16 * slot.pending.size());
  for (const PlacedGranule& g : slot.pending)
    for (const Vec3& o : tile.shape.offsets) {
      const auto w = sc->position_to_world(g.position + rotate(g.orientation, o));
      rec.fill_spheres.insert(rec.fill_spheres.end(), {float(w[0] - hf->origin_x()), float(w[1] - hf->origin_y()),
                                                       float(w[2] - hf->origin_z()), radius_world(s)});
    }
  slot.cut = true;
  // Ledger: volume between the floor and the surface over the region.
  rec.ledger = Ledger{};
  rec.ledger.before = soil_volume(*hf, region, floor_local);
  rec.ledger.active = double(slot.pending.size()) * granule_volume(s) / tile.packing_fraction;
  rec.ledger.packing_fraction = tile.packing_fraction;
  rec.fill_ms += ms_since(t0);
  events.push_back({PatchEventKind::Promoted, slot.patch, time, rec.fill_ms, int(slot.pending.size())});
  ++work.promotions;
  work.granules_filled += int(slot.pending.size());
  if (slot.budget_entry >= 0 && slot.budget_entry < int(budget_log.size()))
    budget_log[std::size_t(slot.budget_entry)]["granules"] = int(slot.pending.size());
  return Ok{};
}

// The share of a body's weight the kept granules may push with: at most half, so the body is
// never pushed up (its net force stays downward) and settles onto them. Measured (docs/
// BENCHMARKS.md "Why the car stuck under a tight budget"): with the whole weight a resting box
// moved 7.5 mm (a 0.05 m sphere diameter), with half 0.48 mm as with no granule kept; a parked
// car's first patch at a coarse rung let it drive away with half or a quarter, not with none.
constexpr double kHeldWeight = 0.5;

// The fill leaves room for the bodies over the region. The fill's top granules reach about a
// radius above the surface it is cut to, where a body resting on the heightfield lies, and a
// shell's spheres are centred on the body's surface: filled through them, a shell started deep
// in granules and was thrown out (measured: a box driven across the terrain rose 0.46 m in
// 0.3 s). But a granule is removed whole, so clearing every granule that touches the shell left
// a hollow up to a granule deep under a resting body, and at a coarse particle scale the body
// fell into it (a parked car's wheels sank up to 0.21 m at scale 2, against 0.356 m granules,
// and at times could not climb out). So the fill keeps the granules that would hold the body up
// with at most half its weight: each granule touching the shell (centres closer than 2 r, sim
// units) pushes it with k_n times its overlaps; a granule pushing from below (every overlap's
// normal within 45 degrees of up) is kept, the least pushing first, while their sum stays
// within kHeldWeight of the body's weight (m g / s in sim units: F_w = s F_sim,
// particles/scale.hpp); the rest, and every granule touching a kinematic or static body, are
// not placed. A body in a joint group (a vehicle's wheels) holds its share of the group's
// weight.

Status TerrainManager::Impl::clear_bodies(Slot& slot, const ParticleScale& sc, const GranuleShape& shape, double s) {
  const float r = def.material.radius, reach = 2.0f * r;
  const double kn = def.material.stiffness;  // N/m (sim units)
  const std::vector<std::int32_t> groups = world->joint_groups();
  const PatchRequest a = rect(slot);
  const double pad = 2.0 * radius_world(s);
  auto over = [&](RigidBodyId b) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    return !(lo.x() > a.x1 + pad || hi.x() < a.x0 - pad || lo.z() > a.z1 + pad || hi.z() < a.z0 - pad);
  };
  // (the mass a body holds up: its own, or its joint group's over the group's bodies here)
  auto held_mass = [&](RigidBodyId b) {
    const std::int32_t g = groups[std::size_t(b.index)];
    if (g == 0) return double(world->mass(b));
    double m = 0;
    int here = 0;
    for (RigidBodyId o : world->bodies())
      if (groups[std::size_t(o.index)] == g) {
        m += world->mass(o);
        here += over(o);
      }
    return m / std::max(1, here);
  };
  for (RigidBodyId b : world->bodies()) {
    if (!over(b)) continue;
    auto pts = shell_points(b, s);
    if (!pts) return pts.errors();
    const BodyState st = world->state(b);
    const Vec3 c = sc.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
    const Quat q = manager_detail::quat(st.orientation);
    std::vector<Vec3> shell;
    shell.reserve(pts->size());
    Vec3 smin{1e30f, 1e30f, 1e30f}, smax{-1e30f, -1e30f, -1e30f};
    for (const Eigen::Vector3f& p : *pts) {
      const Vec3 w = c + rotate(q, manager_detail::v3(p));
      shell.push_back(w);
      smin = {std::min(smin.x, w.x), std::min(smin.y, w.y), std::min(smin.z, w.z)};
      smax = {std::max(smax.x, w.x), std::max(smax.y, w.y), std::max(smax.z, w.z)};
    }
    // The push of sphere p on the shell (N, sim units; 0 when apart); `below` false when an
    // overlap's normal is more than 45 degrees from up.
    auto push = [&](const Vec3& p, bool& below) {
      if (p.x < smin.x - reach || p.y < smin.y - reach || p.z < smin.z - reach || p.x > smax.x + reach ||
          p.y > smax.y + reach || p.z > smax.z + reach)
        return 0.0;
      double f = 0;
      for (const Vec3& w : shell) {
        const Vec3 d = w - p;
        const float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
        if (d2 >= reach * reach) continue;
        const float dist = std::sqrt(d2);
        if (!(d.y >= 0.70710678f * dist)) below = false;
        f += kn * double(reach - dist);
      }
      return f;
    };
    const bool dynamic = world->motion(b) == RigidMotion::Dynamic;
    const double weight = dynamic ? kHeldWeight * held_mass(b) * def.gravity.norm() / s : 0.0;  // N, sim units
    std::vector<std::pair<double, std::size_t>> touching;  // (push, pending index)
    std::vector<char> drop(slot.pending.size(), 0);
    for (std::size_t k = 0; k < slot.pending.size(); ++k) {
      const PlacedGranule& g = slot.pending[k];
      bool below = true;
      double f = 0;
      for (const Vec3& o : shape.offsets) f += push(g.position + rotate(g.orientation, o), below);
      if (f <= 0) continue;
      if (below && dynamic) touching.push_back({f, k});
      else drop[k] = 1;
    }
    std::sort(touching.begin(), touching.end());
    double held = 0;
    for (const auto& [f, k] : touching) {
      if (held + f <= weight) held += f;
      else drop[k] = 1;
    }
    std::size_t kept = 0;
    for (std::size_t k = 0; k < slot.pending.size(); ++k)
      if (!drop[k]) slot.pending[kept++] = slot.pending[k];
    slot.pending.resize(kept);
  }
  return Ok{};
}

// Uploads up to `budget` pending granules; the patch is Ready when all are in.
Status TerrainManager::Impl::upload(Slot& slot, std::size_t budget, double time) {
  const auto t0 = Clock::now();
  PatchRecord& rec = record(slot);
  const std::size_t end = std::min(slot.pending.size(), slot.uploaded + budget);
  for (; slot.uploaded < end; ++slot.uploaded) {
    const PlacedGranule& g = slot.pending[slot.uploaded];
    auto id = slot.sim->add_granule(g.position, g.orientation);
    if (!id) return id.errors();
    ++rec.granules;
    ++work.granules_uploaded;
  }
  rec.fill_ms += ms_since(t0);
  ++work.conversion_parts;
  if (slot.uploaded == slot.pending.size()) {
    slot.pending.clear();
    slot.pending.shrink_to_fit();
    if (slot.predecessor >= 0)
      if (Status st = take_over(slot); !st) return st;
    slot.state = SlotState::Active;
    events.push_back({PatchEventKind::Ready, slot.patch, time, rec.fill_ms, rec.granules});
    ++work.ready;
  }
  return Ok{};
}

// A successor's fill is in (docs/manager.md "A patch that travels with its body"): it takes
// over its predecessor's granules that lie inside its own walls (each sphere at least half a
// radius inside: a granule that strayed across the line between them stays with the
// predecessor, whose demotion writes it), with their velocities, and the bodies the
// predecessor carried (their shells are made in this patch at its first coupling and not
// lifted clear of the granules they rest in, couple_before). The predecessor is then held and
// demoted one part a frame (activate), writing its whole apron; this patch's heights at
// promotion over that apron wait for it (rebase) before its own demotion may start.
Status TerrainManager::Impl::take_over(Slot& b) {
  Slot& a = slots[std::size_t(b.predecessor)];
  b.predecessor = -1;
  a.successor = -1;
  if (!a.ready() || a.superseded) return Ok{};
  PatchRecord& ra = record(a);
  PatchRecord& rb = record(b);
  const double s = b.scale;
  const float sp = hf->spacing();
  const float r = def.material.radius;  // sim units
  const float W = float((b.region.ni - 1) * double(sp) / s), D = float((b.region.nj - 1) * double(sp) / s);
  const Eigen::Vector3d d = (a.origin - b.origin) / s;  // sim units: a's frame in b's
  const Vec3 shift{float(d.x()), float(d.y()), float(d.z())};
  const GranuleShape& shape = a.sim->granule_shape();
  const float rw = radius_world(s);
  int taken = 0;
  std::vector<BodyId> moved(std::size_t(std::max(0, ra.granules)));  // a's granule -> b's body
  for (int k = 0; k < ra.granules; ++k) {
    const BodyId g{k};
    const Vec3 p = a.sim->body_position(g) + shift;
    const Quat q = a.sim->body_orientation(g);
    bool inside = std::isfinite(p.x + p.y + p.z);
    for (const Vec3& o : shape.offsets) {
      const Vec3 x = p + rotate(q, o);
      inside = inside && x.x >= 0.5f * r && x.x <= W - 0.5f * r && x.z >= 0.5f * r && x.z <= D - 0.5f * r;
    }
    if (!inside) continue;
    if (rb.granules >= def.granules_per_slot) break;
    auto id = b.sim->add_granule(p, q);
    if (!id) return id.errors();
    if (Status st = b.sim->set_body_state(*id, p, q, a.sim->body_velocity(g), a.sim->body_angular_velocity(g)); !st) return st;
    // (still as long as it was: the part of a's bed at rest sleeps on in b, docs/dem.md
    // "Sleeping regions", rather than stepping another sleep_time after every move)
    Simulation::StillTime still = a.sim->still_time(g);
    still.anchor = still.anchor + shift;
    if (Status st = b.sim->set_still_time(*id, still); !st) return st;
    moved[std::size_t(k)] = *id;
    ++rb.granules;
    ++taken;
    for (const Vec3& o : shape.offsets) {
      const auto w = b.sim->def().scale.position_to_world(p + rotate(q, o));
      rb.fill_spheres.insert(rb.fill_spheres.end(), {float(w[0] - hf->origin_x()), float(w[1] - hf->origin_y()),
                                                     float(w[2] - hf->origin_z()), rw});
    }
  }
  if (std::string_view(a.sim->name()) == "cpu") {
    // Their springs with each other (and the floor's, where the floors are one): the part of
    // a's bed b takes over stays as it was held rather than settling again. (Not on the GL
    // backend: reading a patch's whole contact history back from the GPU took about 30 ms of
    // the take-over's frame on an H200, docs/BENCHMARKS.md "Carried springs".)
    std::vector<ContactSpring> springs;
    for (ContactSpring c : a.sim->contact_springs()) {
      const BodyId na = c.a.index < int(moved.size()) ? moved[std::size_t(c.a.index)] : BodyId{};
      if (!na.valid() || c.plane > 0 || (c.plane == 0 && shift.y != 0.0f)) continue;
      if (c.plane < 0) {
        c.b = c.b.index < int(moved.size()) ? moved[std::size_t(c.b.index)] : BodyId{};
        if (!c.b.valid()) continue;
      }
      c.a = na;
      springs.push_back(c);
    }
    if (Status st = b.sim->set_contact_springs(springs); !st) return st;
    springs_handed_over += (long long)springs.size();
  }
  rb.ledger.active = double(rb.granules) * granule_volume(s) / (rb.ledger.packing_fraction > 0 ? rb.ledger.packing_fraction : 0.6);
  // The bodies: a's shells parked, its carried list handed on.
  for (const Carried& c : a.carried) {
    if (c.enabled)
      if (Status st = a.sim->set_body_enabled(c.shell, false); !st) return st;
    if (c.enabled && world->alive(c.body)) b.inherited.push_back({c.body.index, c.body.generation});
  }
  a.carried.clear();
  a.superseded = true;
  // (its fill's render, done ahead while it lived (demote_idle), is kept; a render of its
  // granules begun before they last moved is not)
  if (a.demotion.stage > 1 || (a.demotion.stage == 1 && a.demotion.row > 0)) a.demotion = {};
  a.demotion.releasing = true;
  b.rebase_from = int(&a - slots.data());
  ++travels;
  work.granules_uploaded += taken;
  return Ok{};
}

}  // namespace sandpatch
