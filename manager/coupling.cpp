// The terrain manager's coupling (Stage::Dem, Stage::Sleep): which patch carries each body,
// the bodies' shells in the patches' simulations, the contact forces handed to Bullet, and
// patches falling asleep. See terrain_manager_impl.hpp.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>

#include <omp.h>

#include "manager/shell.hpp"
#include "particles/granule.hpp"
#include "manager/terrain_manager_impl.hpp"

namespace sandpatch {

using manager_detail::body_key;
using manager_detail::eig;
using manager_detail::quat;
using manager_detail::v3;

namespace {

// How far (sim units) a shell whose sphere centres are at `shell` (sim units) must rise so that
// none of its spheres overlaps the ground that would hold it up in the patch's DEM, here and
// anywhere along the horizontal displacement `sweep` (sim units, where the body goes in this
// frame, sampled every r): a granule sphere below a shell sphere's centre (ids [0,
// granule_spheres): the fill is uploaded before any shell), the terrain grid outside the
// filled rectangle, or the rectangle's sides up to the outside surface (particles/dem.hpp
// TerrainGrid; shaders/dem/physics_common.glsl boundary_plane). Granules beside or above a
// sphere are left to the DEM (a lift would not clear them). At most 2 r: a shell deeper than
// that is in the soil, not arriving on it.
double lift_to_clear(const DemBackend& sim, std::size_t granule_spheres, const std::vector<Vec3>& shell, Vec3 sweep) {
  if (shell.empty()) return 0;
  const float r = sim.def().particle_radius, reach = 2.0f * r;
  sweep.y = 0;
  const float travel = std::sqrt(sweep.x * sweep.x + sweep.z * sweep.z);
  const int samples = travel > 0 ? std::min(64, int(std::ceil(travel / r))) : 0;
  Vec3 lo = shell[0], hi = shell[0];
  for (const Vec3& w : shell) {
    lo = {std::min(lo.x, w.x), std::min(lo.y, w.y), std::min(lo.z, w.z)};
    hi = {std::max(hi.x, w.x), std::max(hi.y, w.y), std::max(hi.z, w.z)};
  }
  lo = {lo.x + std::min(0.0f, sweep.x), lo.y, lo.z + std::min(0.0f, sweep.z)};
  hi = {hi.x + std::max(0.0f, sweep.x), hi.y, hi.z + std::max(0.0f, sweep.z)};
  const std::vector<Vec3> all = sim.particle_positions();
  std::vector<Vec3> near;
  for (std::size_t k = 0; k < std::min(granule_spheres, all.size()); ++k) {
    const Vec3& g = all[k];
    if (g.x > lo.x - reach && g.x < hi.x + reach && g.z > lo.z - reach && g.z < hi.z + reach && g.y > lo.y - reach &&
        g.y < hi.y)
      near.push_back(g);
  }
  const TerrainGrid& t = sim.def().terrain;
  double need = 0;
  for (int k = 0; k <= samples; ++k) {
    const float f = samples > 0 ? float(k) / float(samples) : 0.0f;
    for (Vec3 w : shell) {
      w = {w.x + f * sweep.x, w.y, w.z + f * sweep.z};
      for (const Vec3& g : near) {
        if (!(g.y < w.y)) continue;
        const float dx = g.x - w.x, dz = g.z - w.z, dy = w.y - g.y, rho2 = dx * dx + dz * dz;
        if (rho2 + dy * dy >= reach * reach) continue;
        need = std::max(need, double(std::sqrt(reach * reach - rho2) - dy));
      }
      if (t.empty()) continue;
      const bool outside = w.x < t.fill_min_x || w.x > t.fill_max_x || w.z < t.fill_min_z || w.z > t.fill_max_z;
      if (outside) {
        const float h = t.height(w.x, w.z), ny = t.normal(w.x, w.z).y;
        if ((w.y - h) * ny < r) need = std::max(need, double(h + r / ny - w.y));
        continue;
      }
      // a side of the filled rectangle: a wall up to the outside surface, then its top edge
      const float gaps[4] = {w.x - t.fill_min_x, t.fill_max_x - w.x, w.z - t.fill_min_z, t.fill_max_z - w.z};
      for (int e = 0; e < 4; ++e) {
        if (!(gaps[e] < r)) continue;
        const float top = e == 0   ? t.height(t.fill_min_x - r, w.z)
                          : e == 1 ? t.height(t.fill_max_x + r, w.z)
                          : e == 2 ? t.height(w.x, t.fill_min_z - r)
                                   : t.height(w.x, t.fill_max_z + r);
        if (w.y - top < -r) continue;
        const float dy = std::max(0.0f, w.y - top);
        if (gaps[e] * gaps[e] + dy * dy < r * r) need = std::max(need, double(top + std::sqrt(r * r - gaps[e] * gaps[e]) - w.y));
      }
    }
  }
  return std::min(need, double(reach));
}

}  // namespace

Status TerrainManager::Impl::step_patches(double time, double dt) {
  ++frame;
  choose_carriers();
  std::vector<Slot*> awake;
  for (auto& s : slots) {
    if (s.state != SlotState::Active && s.state != SlotState::Asleep) continue;
    if (s.demotion.releasing) continue;  // held while it is demoted (activate)
    if (Status st = couple_before(s, dt); !st) return st;
    if (s.sim->asleep()) {
      hold_resting_bodies(s);
      continue;
    }
    awake.push_back(&s);
  }
  // (with a frame budget, a patch carrying no body may be held this frame: budget.cpp)
  const std::vector<Slot*> order = stepping_order(awake, dt);
  for (Slot* sp : order) {
    Slot& s = *sp;
    if (s.state == SlotState::Asleep) {
      s.state = SlotState::Active;
      s.asleep_for = 0;
      s.demotion = {};  // a demotion begun while it slept starts again
      events.push_back({PatchEventKind::Woke, s.patch, time, 0, record(s).granules});
      ++work.wakes;
    }
  }
  // The steps: each touches its own slot only (its DEM and the sums of the bodies it carries),
  // so patches may step side by side, one thread each (concurrent_patches); the results do
  // not depend on it (the DEM's do not depend on its threads). Then, in the same order either
  // way, each patch's coupling hands its forces to Bullet.
  std::vector<PatchStep> done(order.size());
  const int teams = concurrent_patches(order, dt);
  if (teams > 1) {
    // A patch whose step would begin by sorting its spheres and building its lists (a
    // successor's first step after its take-over, a shell enabled or parked) builds them
    // first on all threads: side by side, its one thread took about 1 ms for a car's track
    // patch of 5,100 spheres, while the other thread waited (docs/BENCHMARKS.md "Lists built
    // before the patches step side by side"). Its share of the frame's wall time counts it.
    std::vector<double> ahead_ms(order.size(), 0.0);
    for (std::size_t k = 0; k < order.size(); ++k) {
      const auto t0 = manager_detail::Clock::now();
      order[k]->sim->build_lists_now();
      ahead_ms[k] = manager_detail::ms_since(t0);
    }
    for (Slot* sp : order)
      if (Status st = sp->sim->set_threads(1); !st) return st;
    std::vector<int> by_cost(order.size());
    for (std::size_t k = 0; k < order.size(); ++k) by_cost[k] = int(k);
    std::stable_sort(by_cost.begin(), by_cost.end(), [&](int a, int b) {
      return awake_spheres(*order[std::size_t(a)]) > awake_spheres(*order[std::size_t(b)]);
    });
    const auto t0 = manager_detail::Clock::now();
#pragma omp parallel for num_threads(teams) schedule(dynamic, 1)
    for (int k = 0; k < int(order.size()); ++k) {
      const std::size_t i = std::size_t(by_cost[std::size_t(k)]);
      done[i] = step_patch(*order[i], dt);
    }
    const double wall = manager_detail::ms_since(t0);
    for (Slot* sp : order)
      if (Status st = sp->sim->set_threads(def.threads); !st) return st;
    // Each patch's share of the section's wall time: its thread's time scaled so that the
    // shares add up to the wall time (the report's DEM time is the frame's, not the threads').
    double threads_ms = 0;
    for (const PatchStep& d : done) threads_ms += d.ms;
    const double share = threads_ms > 0 ? wall / threads_ms : 1.0;
    for (PatchStep& d : done) d.share = share, d.ms *= share;
    for (std::size_t k = 0; k < done.size(); ++k) done[k].ms += ahead_ms[k];
    work.side_by_side = int(order.size());
    ++side_by_side_frames;
  } else {
    for (std::size_t i = 0; i < order.size(); ++i) {
      done[i] = step_patch(*order[i], dt);
      if (!done[i].status) break;
    }
  }
  for (std::size_t i = 0; i < order.size(); ++i) {
    Slot& s = *order[i];
    PatchStep& d = done[i];
    if (!d.status) return d.status;
    account_step(s, d.ms, d.prescribed ? &d.stats : nullptr, d.share);
    observe_cost(s, d.ms, dt);
    couple_after(s, dt, d.stepped);
    s.fade = std::min(s.fade + 1, def.fade_frames);
  }
  return Ok{};
}

// How many patches step side by side this frame, one thread each (1: one after another, each
// on all the DEM's threads). Side by side, the frame's DEM takes about the longest thread's
// share (patches handed to the first free thread, the largest first); one after another, the
// sum of the patches' steps, each over the threads at the parallel gain measured for patches
// of 1,000-4,000 granules (two threads 1.31-1.62 times one: docs/BENCHMARKS.md "Where the car
// scene's DEM time goes against `bench dem`"). Side by side only where that is the shorter, on
// the CPU backend (the GL backend's steps share one context and queue); measured in "Patches
// side by side".
int TerrainManager::Impl::concurrent_patches(const std::vector<Slot*>& order, double dt) const {
  if (order.size() < 2 || def.backend != "cpu") return 1;
  const int threads = def.threads > 0 ? def.threads : omp_get_max_threads();
  if (threads < 2 || omp_in_parallel()) return 1;
  const int teams = std::min(threads, int(order.size()));
  std::vector<double> cost;
  double sum = 0;
  for (const Slot* s : order) {
    const double c = predict_ms(awake_spheres(*s), dt, s->steps_per_contact);
    cost.push_back(c);
    sum += c;
  }
  std::sort(cost.begin(), cost.end(), std::greater<>());
  std::vector<double> busy(std::size_t(teams), 0.0);
  for (double c : cost) *std::min_element(busy.begin(), busy.end()) += c;
  const double side_by_side = *std::max_element(busy.begin(), busy.end());
  constexpr double kGainPerThread = 0.45;  // a patch on n threads: 1 + 0.45 (n - 1) times one
  const double one_after_another = sum / (1.0 + kGainPerThread * (threads - 1));
  return side_by_side < one_after_another ? teams : 1;
}

// One patch's DEM step of the frame (slot-local: its simulation and its carried bodies' sums).
TerrainManager::Impl::PatchStep TerrainManager::Impl::step_patch(Slot& s, double dt) {
  PatchStep out;
  const auto t_step = manager_detail::Clock::now();
  // The DEM names its own definition; say which knob of the terrain's trades it.
  auto name_knobs = [](Status st) {
    std::vector<Error> es = st.errors();
    for (Error& e : es)
      if (e.field == "step.dt_frame")
        e.detail = "lower the frame's dt, raise simulation.max_substeps (TerrainDef.max_substeps), lower "
                   "simulation.steps_per_contact (TerrainDef.steps_per_contact) or the material's stiffness";
    return Status(es);
  };
  for (Carried& c : s.carried) {
    c.f_sum.setZero();
    c.t_sum.setZero();
    out.prescribed = out.prescribed || (c.enabled && c.prescribed);
  }
  if (!out.prescribed) {
    if (Status st = s.sim->step(dt); !st) out.status = name_knobs(st);
  } else {
    // A kinematic or static shell gets no momentum from the granules, so the soil's force on
    // it is summed from the DEM's contact force substep by substep: the frame runs as its n
    // substeps one DEM step each (the same substep dt, float(dt / n), the same state).
    auto n = s.sim->substeps_for(dt);
    if (!n) {
      out.status = name_knobs(n.errors());
      return out;
    }
    StepStats& fs = out.stats;
    int stepped = 0;
    for (int k = 0; k < *n; ++k) {
      if (Status st = s.sim->step(dt / *n); !st) {
        out.status = name_knobs(st);
        return out;
      }
      const StepStats& one = s.sim->last_step();
      fs.substeps += one.substeps;
      fs.substep_dt = one.substeps > 0 ? one.substep_dt : fs.substep_dt;
      fs.contacts = one.contacts;
      fs.wall_contacts = one.wall_contacts;
      fs.neighbour_entries = one.neighbour_entries;
      fs.resorts += one.resorts;
      fs.shell_lists += one.shell_lists;
      fs.slept = one.slept;
      fs.guard_seconds += one.guard_seconds;
      fs.pair_seconds += one.pair_seconds;
      fs.body_seconds += one.body_seconds;
      fs.sort_seconds += one.sort_seconds;
      fs.submit_seconds += one.submit_seconds;
      fs.readback_seconds += one.readback_seconds;
      stepped += one.substeps > 0;
      for (Carried& c : s.carried)
        if (c.enabled && c.prescribed && one.substeps > 0) {
          c.f_sum += eig(s.sim->body_force(c.shell)).cast<double>();
          c.t_sum += eig(s.sim->body_torque(c.shell)).cast<double>();
        }
    }
    // The mean over the substeps that ran (the DEM may fall asleep within the frame; none
    // ran: the force of before stands, couple_after keeps it).
    for (Carried& c : s.carried) {
      c.f_sum /= double(std::max(stepped, 1));
      c.t_sum /= double(std::max(stepped, 1));
    }
    out.stepped = stepped > 0;
  }
  out.ms = manager_detail::ms_since(t_step);
  return out;
}

void TerrainManager::Impl::update_sleep(double time, double dt) {
  for (auto& s : slots) {
    if (s.state == SlotState::Active && s.sim->asleep()) {
      s.state = SlotState::Asleep;
      // The bodies it carries stop with it (they keep no residual drift while it sleeps).
      for (const auto& c : s.carried)
        if (c.enabled && !c.prescribed && world->alive(c.body)) {
          BodyState b = world->state(c.body);
          b.linear_velocity.setZero();
          b.angular_velocity.setZero();
          world->set_state(c.body, b);
        }
      events.push_back({PatchEventKind::Asleep, s.patch, time + dt, 0, record(s).granules});
    }
    if (s.state == SlotState::Asleep) s.asleep_for += dt;
  }
}

// Whether a body's bounds reach into a slot's region (and down to its granules).
// `inside`: the footprint lies within the patch's DEM terrain, the filled region and the
// apron around it, where the simulation's terrain grid is solid up to the surface.
bool TerrainManager::Impl::engages(const Slot& s, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, bool* inside,
                                   double above) const {
  const double sp = hf->spacing();
  const double x0 = hf->origin_x() + s.region.i0 * sp, x1 = x0 + (s.region.ni - 1) * sp;
  const double z0 = hf->origin_z() + s.region.j0 * sp, z1 = z0 + (s.region.nj - 1) * sp;
  const double surface_top = hf->origin_y() + s.top_local;
  const bool overlap = lo.x() < x1 && hi.x() > x0 && lo.z() < z1 && hi.z() > z0 && lo.y() < surface_top + above;
  // Within the filled region the granules carry the body; a body across the region's edge
  // rests partly on the terrain grid outside it. Both are in the DEM, so a body anywhere over
  // the DEM's terrain (region + apron) is carried by the DEM alone: with the heightfield too,
  // a body at rest across the edge was held by Bullet at the heightfield's surface while its
  // shell (which keeps its own state while the body rests) settled lower into the granules,
  // so the DEM's force pulled the body down by up to its weight and the heightfield pushed
  // back twice it (measured, ExtremesManager.HundredBodiesAtOnceOnTwoSlots: -19.6 N and
  // +39.2 N on a 2 kg sphere), and the patch never slept.
  const double ax0 = hf->origin_x() + s.apron.i0 * sp, ax1 = hf->origin_x() + (s.apron.i0 + s.apron.ni - 1) * sp;
  const double az0 = hf->origin_z() + s.apron.j0 * sp, az1 = hf->origin_z() + (s.apron.j0 + s.apron.nj - 1) * sp;
  // Outside the region the DEM's ground is the higher of its floor plane and the terrain
  // grid, so it is the heightfield only where the surface is above the floor (not over bare
  // rock below a flat bedrock's floor, docs/extremes.md): there the heightfield stays on
  // (ExtremesManager.FlatBedrockMeetingTheSurface: a body held up on the floor plane over the
  // rock pushed granules onto it, which raised the rock by 11 cm).
  const double margin = 2.0 * radius_world(s);
  *inside = lo.x() > x0 + margin && hi.x() < x1 - margin && lo.z() > z0 + margin && hi.z() < z1 - margin;
  if (!*inside && lo.x() > ax0 + margin && hi.x() < ax1 - margin && lo.z() > az0 + margin && hi.z() < az1 - margin) {
    bool faithful = true;
    const int i0 = std::max(0, int(std::floor((lo.x() - hf->origin_x()) / sp)));
    const int i1 = std::min(hf->samples_x() - 1, int(std::ceil((hi.x() - hf->origin_x()) / sp)));
    const int j0 = std::max(0, int(std::floor((lo.z() - hf->origin_z()) / sp)));
    const int j1 = std::min(hf->samples_z() - 1, int(std::ceil((hi.z() - hf->origin_z()) / sp)));
    for (int j = j0; j <= j1 && faithful; ++j)
      for (int i = i0; i <= i1 && faithful; ++i) faithful = hf->height(i, j) > s.floor_local;
    *inside = faithful;
  }
  return overlap;
}

double TerrainManager::Impl::engage_limit(const Slot& s, RigidBodyId b) const {
  for (const Carried& c : s.carried)
    if (c.body.index == b.index && c.body.generation == b.generation && c.enabled)
      return c.tool ? carry_height : 0.5 * engage_height;
  return join_height(s, b);
}

double TerrainManager::Impl::join_height(const Slot& s, RigidBodyId b) const {
  const BodyState st = world->state(b);
  Eigen::Vector3d lo, hi;
  world->bounds(b, &lo, &hi);
  const double reach = 0.5 * (hi - lo).norm();  // m, the farthest point of the body from its centre, at most
  const double approach = std::max(0.0, -double(st.linear_velocity.y())) + double(st.angular_velocity.norm()) * reach;  // m/s
  return std::min(0.5 * engage_height, 4.0 * double(radius_world(s)) + approach * join_lookahead);
}

int TerrainManager::Impl::granules_within(const Slot& s, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
  const std::size_t per = s.sim->granule_shape().offsets.size();
  const std::size_t n = std::size_t(records[std::size_t(&s - slots.data())].granules);
  if (per == 0 || n == 0) return 0;
  const std::vector<Vec3> p = s.sim->particle_positions();  // sim units; the granules' spheres first
  const double r = radius_world(s);
  int count = 0;
  for (std::size_t g = 0; g < n && (g + 1) * per <= p.size(); ++g) {
    Vec3 c{0, 0, 0};
    for (std::size_t k = 0; k < per; ++k) c = c + p[g * per + k];
    const auto w = s.sim->def().scale.position_to_world(c * (1.0f / float(per)));  // m, world
    bool in = true;
    // (above its lowest point: the granules under a plate or a blade's edge are not in it)
    for (int a = 0; a < 3; ++a) in = in && w[std::size_t(a)] >= (a == 1 ? lo[a] : lo[a] - r) && w[std::size_t(a)] <= hi[a] + r;
    count += in;
  }
  return count;
}

// The carrier of every body (see Impl::carrier).
void TerrainManager::Impl::choose_carriers() {
  std::unordered_map<std::int64_t, int> next;
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    const auto prev = carrier.find(body_key(b));
    int best = -1;
    double best_area = -1, prev_area = -1;
    for (int k = 0; k < int(slots.size()); ++k) {
      const Slot& sl = slots[std::size_t(k)];
      if ((sl.state != SlotState::Active && sl.state != SlotState::Asleep) || sl.demotion.releasing) continue;
      bool inside = false;
      if (!engages(sl, lo, hi, &inside, engage_limit(sl, b))) continue;
      const PatchRequest r = rect(sl);
      const double area = std::max(0.0, std::min(hi.x(), r.x1) - std::max(lo.x(), r.x0)) *
                          std::max(0.0, std::min(hi.z(), r.z1) - std::max(lo.z(), r.z0));
      if (area > best_area) best = k, best_area = area;
      if (prev != carrier.end() && prev->second == k) prev_area = area;
    }
    if (best < 0) continue;
    if (prev_area >= 0 && prev_area >= 0.5 * best_area) {
      next[body_key(b)] = prev->second;
      continue;
    }
    // A body lying on the terrain is not taken up by a patch it is not in yet: it lies where
    // its last patch or the heightfield left it, at or below the surface the new patch's fill
    // was cut to (sunk into the granules of a patch just demoted), and the top granules of a
    // fill reach about a granule radius above that surface; a shell started there was thrown
    // out at 1-3 m/s (measured in the hundred-bodies case). It is taken when it moves.
    if (world->motion(b) == RigidMotion::Dynamic && (lying(b, lo, hi) || settling(b))) {
      if (prev_area >= 0) next[body_key(b)] = prev->second;  // nor handed to another one
      continue;
    }
    next[body_key(b)] = best;
  }
  carrier.swap(next);
  // A body no patch carries meets the heightfield, whatever patch last carried it (one that
  // is being released, held and not coupled, left a car's wheel with its heightfield
  // collision off: it fell through the terrain for 0.15 s, and the patch that took it up
  // next found it 0.3 m deep in its granules).
  for (RigidBodyId b : world->bodies())
    if (!carried_anywhere(b)) world->set_terrain_collision(b, true);
}

// A body lying on the terrain: its lowest point within one granule diameter (at the coarsest
// scale) of the surface under its centre, slower than 10 sleep_speed (m/s; Bullet's contacts
// on the heightfield jitter resting bodies at about sleep_speed).
bool TerrainManager::Impl::lying(RigidBodyId b, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
  const BodyState st = world->state(b);
  // A kinematic body moving along its prescribed path is not lying anywhere, however slowly
  // it goes (a plate pressed into the soil at a few cm/s).
  if (world->motion(b) == RigidMotion::Kinematic && (st.linear_velocity.squaredNorm() > 0 || st.angular_velocity.squaredNorm() > 0))
    return false;
  const double reach = 0.5 * (hi - lo).norm(), slow = 10.0 * def.sleep_speed;
  if (st.linear_velocity.norm() >= slow || st.angular_velocity.norm() * reach >= slow) return false;
  double s_max = 0;
  for (double sc : scales()) s_max = std::max(s_max, sc);
  const double cx = 0.5 * (lo.x() + hi.x()) - hf->origin_x(), cz = 0.5 * (lo.z() + hi.z()) - hf->origin_z();
  const double surface = hf->origin_y() + hf->sample(float(cx), float(cz));
  return lo.y() < surface + 2.0 * def.material.radius * s_max;
}

Status TerrainManager::Impl::couple_before(Slot& slot, double dt) {
  const double s = slot.scale;
  const int self = int(&slot - slots.data());
  // Bodies removed from the world since the last frame: their shells leave the patch.
  for (auto it = slot.carried.begin(); it != slot.carried.end();) {
    if (world->alive(it->body)) {
      ++it;
      continue;
    }
    if (Status e = slot.sim->set_body_enabled(it->shell, false); !e) return e.errors();
    it = slot.carried.erase(it);
  }
  // Bodies joined by joints: one collision group in the DEM too, so their shells do not
  // touch (Bullet does not collide them; a wheel's shell against its chassis' pushed the
  // wheels outward with about 6 kN in the vehicle scene). Granules touch every shell.
  const std::vector<std::int32_t> groups = world->joint_groups();
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    bool inside = false;
    bool touch = engages(slot, lo, hi, &inside, engage_limit(slot, b)) && carries(self, b);
    auto it = std::find_if(slot.carried.begin(), slot.carried.end(),
                           [&](const Carried& c) { return c.body.index == b.index && c.body.generation == b.generation; });
    // A dynamic body on joints whose shell felt no granule over the last frame and that is a
    // sphere diameter above its join height leaves the patch (a vehicle's chassis that dipped
    // toward the sand over a bump; a tool with soil in it feels the soil); the diameter keeps
    // it from joining and leaving frame after frame. (A free body keeps its shell up to
    // engage_height / 2: a ball bouncing in its crater stays in the patch.)
    if (touch && it != slot.carried.end() && it->enabled && !it->prescribed && !it->felt_soil &&
        groups[std::size_t(b.index)] > 0 &&
        lo.y() > hf->origin_y() + slot.top_local + join_height(slot, b) + 2.0 * double(radius_world(slot)))
      touch = false;
    if (!touch && it == slot.carried.end()) continue;
    BodyState st = world->state(b);
    const bool fresh = it == slot.carried.end();
    // A body arriving on the patch (its shell made or enabled this frame) starts touching the
    // patch's ground, not inside it. Bullet held it on the heightfield, where its shell, whose
    // spheres are centred on its surface, reaches a granule radius into the DEM's terrain grid
    // and into the granules of a fill cut to that surface; started there, the spheres' overlap
    // threw it up (a 20 kg box driven at 3.5 m/s onto a patch: 2.6 kN over its first frame,
    // +2 m/s). It is set on that ground instead, its velocities kept: raised by the least
    // height that clears the ground under its shell now and along its path over this frame
    // (lift_to_clear, at most 2 r; none for a body coming down from above, nor for one in a
    // hollow the fill left for it, clear_bodies, until it moves into the hollow's side). A body
    // joined to others is not moved alone (its joints would pull it back): left to the DEM.
    // (A body this patch took over from its predecessor rests in the granules it took over:
    // it is not lifted; take_over.)
    const auto inherited = std::find(slot.inherited.begin(), slot.inherited.end(), std::pair<int, int>{b.index, b.generation});
    const bool taken_over = inherited != slot.inherited.end();
    if (taken_over && touch) slot.inherited.erase(inherited);
    if (touch && !taken_over && (fresh || !it->enabled) && world->motion(b) == RigidMotion::Dynamic && groups[std::size_t(b.index)] == 0) {
      auto pts = shell_points(b, s);
      if (!pts) return pts.errors();
      const Vec3 c = slot.sim->def().scale.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
      const Quat q = quat(st.orientation);
      std::vector<Vec3> shell;
      shell.reserve(pts->size());
      for (const Eigen::Vector3f& e : *pts) shell.push_back(c + rotate(q, v3(e)));
      const std::size_t granule_spheres = std::size_t(record(slot).granules) * slot.sim->granule_shape().offsets.size();
      const Vec3 sweep = v3(Eigen::Vector3f(st.linear_velocity * float(dt / s)));
      if (const double lift = lift_to_clear(*slot.sim, granule_spheres, shell, sweep); lift > 0) {
        st.position.y() += lift * s;
        world->set_state(b, st);
        lift_max = std::max(lift_max, lift * s);
        ++lifts;
      }
    }
    if (fresh) {
      auto pts = shell_points(b, s);
      if (!pts) return pts.errors();
      ShellDef sh;
      for (const auto& p : *pts) sh.offsets.push_back(v3(p));
      sh.radii = {def.material.radius};
      const bool prescribed = world->motion(b) != RigidMotion::Dynamic;
      if (prescribed) {
        sh.motion = MotionType::Kinematic;  // kinematic and static bodies: the granules do not move it
      } else {
        sh.motion = MotionType::Dynamic;
        sh.mass = world->mass(b);  // the body enters with its own mass (mass ratio 1)
        sh.inertia = v3(Eigen::Vector3f(world->principal_inertia(b) / float(s * s)));
      }
      sh.position = slot.sim->def().scale.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
      sh.orientation = quat(st.orientation);
      sh.group = groups[std::size_t(b.index)];
      auto id = slot.sim->add_shell(sh);
      if (!id) return id.errors();
      Carried nc{b, *id, true, Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero()};
      nc.prescribed = prescribed;
      nc.set_position = st.position;
      nc.set_orientation = st.orientation;
      slot.carried.push_back(nc);
      it = slot.carried.end() - 1;
    }
    Carried& c = *it;
    c.tool = c.prescribed || groups[std::size_t(b.index)] > 0;
    if (const std::int32_t g = groups[std::size_t(b.index)]; !fresh && slot.sim->body_group(c.shell) != g)
      if (Status e = slot.sim->set_body_group(c.shell, g); !e) return e.errors();  // a joint added or removed
    const bool reenabled = touch && !c.enabled;  // parked until now: its state must be set
    if (reenabled || fresh) c.felt_soil = true;  // (until its first frame says)
    if (touch != c.enabled) {
      // A tool let go of with granules in it (lifted above carry_height, or out over the
      // patch's side): they fall. Reported with its height and what it held.
      if (!touch && c.tool) {
        if (const int held = granules_within(slot, lo, hi); held > 0) {
          SoilDrop d;
          d.name = world->definition(b).name;
          d.time = now;
          d.patch = slot.patch;
          d.height = lo.y() - (hf->origin_y() + slot.top_local);
          d.granules = held;
          d.volume = held * granule_volume(s) / (slot.cut_packing > 0 ? double(slot.cut_packing) : 0.6);
          soil_drops.push_back(d);
          events.push_back({PatchEventKind::SoilDropped, slot.patch, now, 0, held, d.name, d.height, carry_height, d.volume});
        }
      }
      if (Status e = slot.sim->set_body_enabled(c.shell, touch); !e) return e.errors();
      c.enabled = touch;
    }
    // Only the carrier decides the heightfield collision (a body no patch carries meets it:
    // choose_carriers, just before); one its carrier lets go of meets it too (a joined body
    // that felt no soil above its join height, above: its collision stayed as the carrier last
    // set it, off).
    if (touch) world->set_terrain_collision(b, !inside);
    else if (carries(self, b)) world->set_terrain_collision(b, true);
    if (!touch) continue;
    // The shell starts the frame where Bullet has the body.
    c.v0 = st.linear_velocity;
    c.w0 = st.angular_velocity;
    // A body at rest keeps the shell's own state: setting it wakes the patch and restarts
    // its sleep clock (a patch carrying a resting body never fell asleep before this).
    Eigen::Vector3d blo, bhi;
    world->bounds(b, &blo, &bhi);
    const double reach = 0.5 * (bhi - blo).norm();
    const bool at_rest = st.linear_velocity.norm() <= def.sleep_speed && st.angular_velocity.norm() * reach <= def.sleep_speed;
    if (c.prescribed) {
      // A prescribed shell is never slowed by the granules: faster than one can be stopped
      // within 2 granule radii (speed sqrt(m_pt / k_n) > 2 r, the DEM's overlap guard for an
      // immovable body, particles/dem.hpp, off in patches) it may push granules through its
      // sphere surface. Not refused (the path is the caller's): reported (tools_too_fast).
      {
        const GranuleShape& g = slot.sim->granule_shape();
        const double m_pt = point_effective_mass(g.mass, g.inertia, g.centre_distance);
        const double kn = slot.sim->def().material.normal_stiffness, r = slot.sim->def().particle_radius;
        const double limit = s * 2.0 * r * std::sqrt(kn / m_pt);  // m/s, world
        const double speed = st.linear_velocity.norm() + st.angular_velocity.norm() * reach;
        if (m_pt > 0 && speed > limit) {
          FastTool& f = fast_tools[body_key(b)];
          f.name = world->definition(b).name;
          if (speed > f.speed) f.speed = speed, f.limit = limit;
          ++f.frames;
          if (f.last < 0 || now - f.last > 1.5 * dt)  // it goes over (again)
            events.push_back({PatchEventKind::TooFastForGranules, slot.patch, now, 0, 0, f.name, speed, limit, 0});
          f.last = now;
        }
      }
      // The shell starts the frame at Bullet's pose with the prescribed velocities, and the
      // DEM moves it along them over the frame's substeps to where Bullet takes the body (a
      // straight line; the rotation at a constant rate): it follows the body through the
      // frame instead of jumping once per frame. Still and where it was last put: left alone
      // (setting it would keep the patch awake).
      const bool still = st.linear_velocity.squaredNorm() == 0 && st.angular_velocity.squaredNorm() == 0;
      const bool moved = (st.position - c.set_position).norm() > 0 || !st.orientation.isApprox(c.set_orientation, 0);
      if (still && !moved && !fresh && !reenabled) continue;
      c.set_position = st.position;
      c.set_orientation = st.orientation;
    } else if (at_rest && !fresh && !reenabled) {
      // ... while its shell rests too. A body held still in the air by a joint has a shell
      // that falls freely in the DEM; left alone, it fell a frame's g dt faster each frame, and
      // the change of momentum below gave the body one more m g of "soil force" each frame (a
      // bucket held 0.5 m over the sand by its arm's servos was pushed down by 1-4 kN).
      const double shell_speed = double(eig(slot.sim->body_velocity(c.shell)).norm()) * s;
      if (shell_speed <= def.sleep_speed) continue;
    }
    const Vec3 p = slot.sim->def().scale.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
    if (Status e = slot.sim->set_body_state(c.shell, p, quat(st.orientation), v3(Eigen::Vector3f(st.linear_velocity / float(s))),
                                           v3(st.angular_velocity));
        !e)
      return e.errors();
    if (st.linear_velocity.norm() > def.sleep_speed) slot.sim->wake();
  }
  return Ok{};
}

// While a patch sleeps, the bodies it carries rest on it: Bullet gets their weight back as
// the support force, so they stay where the patch left them.
void TerrainManager::Impl::hold_resting_bodies(Slot& slot) {
  for (const Carried& c : slot.carried)
    if (c.enabled && c.prescribed && world->alive(c.body)) {
      soil[body_key(c.body)] = {c.force, c.torque};  // the granules rest as they last pushed it
    } else if (c.enabled && world->alive(c.body)) {
      const Eigen::Vector3f f = -world->mass(c.body) * def.gravity.cast<float>();
      world->apply_force(c.body, f, Eigen::Vector3f::Zero());
      soil[body_key(c.body)] = {f, Eigen::Vector3f::Zero()};
    }
}

void TerrainManager::Impl::couple_after(Slot& slot, double dt, bool stepped) {
  const double s = slot.scale;
  for (Carried& c : slot.carried) {
    if (!c.enabled || !world->alive(c.body)) continue;
    if (c.prescribed) {
      // Nothing moves a kinematic or static body: the mean contact force over the frame is
      // only read (particles/scale.hpp: F_w = s F_sim, T_w = s^2 T_sim, mass ratio 1).
      const ParticleScale& ps = slot.sim->def().scale;
      if (stepped) {
        c.force = eig(ps.force_to_world(v3(Eigen::Vector3f(c.f_sum.cast<float>()))));
        c.torque = eig(ps.torque_to_world(v3(Eigen::Vector3f(c.t_sum.cast<float>()))));
      }
      soil[body_key(c.body)] = {c.force, c.torque};
      continue;
    }
    // Mean contact force and torque over the frame from the shell's change of momentum.
    const Eigen::Vector3f v1 = eig(slot.sim->body_velocity(c.shell)) * float(s);
    const Eigen::Vector3f w1 = eig(slot.sim->body_angular_velocity(c.shell));
    const float m = world->mass(c.body);
    const Eigen::Vector3f f = m * ((v1 - c.v0) / float(dt) - def.gravity.cast<float>());
    c.felt_soil = f.norm() > 1e-3f * m * def.gravity.cast<float>().norm();
    const Eigen::Matrix3f R = world->state(c.body).orientation.toRotationMatrix();
    const Eigen::Matrix3f I = R * world->principal_inertia(c.body).asDiagonal() * R.transpose();
    const Eigen::Vector3f t = I * (w1 - c.w0) / float(dt);
    world->apply_force(c.body, f, t);
    soil[body_key(c.body)] = {f, t};
  }
}

// A body's shell: its surface sampled at the granule sphere spacing (sim units). Meshes go
// through their signed distance field (0.2–0.9 s for a few thousand triangles), cached by
// sample_shell per mesh; plan() asks once for every new body, so the cost falls in the frame
// the body appears, not in the frame it first touches a patch.
Result<std::vector<Eigen::Vector3f>> TerrainManager::Impl::shell_points(RigidBodyId b, double scale) const {
  return shell_points(world->definition(b).shape, scale);
}

Result<std::vector<Eigen::Vector3f>> TerrainManager::Impl::shell_points(RigidShape shape, double scale) const {
  return scaled_shell(def, std::move(shape), scale);
}

// The shell in sim units at particle scale `scale`: the shape shrunk by 1 / scale, sampled
// every 1.5 granule radii (the granules' own spacing in the simulation).
Result<std::vector<Eigen::Vector3f>> scaled_shell(const TerrainManagerDef& def, RigidShape shape, double scale) {
  const float inv = float(1.0 / scale);
  shape.radius *= inv;
  shape.height *= inv;
  shape.half_extents *= inv;
  for (auto& v : shape.vertices) v *= inv;
  return sample_shell(shape, 1.5f * def.material.radius, def.material.radius, def.shell_particles_per_slot);
}

Status check_shell(const TerrainManagerDef& def, const RigidShape& shape) {
  double finest = def.particle_scale;
  for (const auto& b : def.scale_bands) finest = std::min(finest, b.particle_scale);
  auto pts = scaled_shell(def, shape, finest);
  if (pts) return Ok{};
  return pts.errors();
}

Status TerrainManager::check_shell(const RigidShape& shape) const { return sandpatch::check_shell(impl_->def, shape); }

}  // namespace sandpatch
