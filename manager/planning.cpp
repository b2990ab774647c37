// The terrain manager's planning (Stage::Lod): requests from predicted contacts, the queue,
// merging, and growth of a patch under a body heading past its edge (terrain_manager_impl.hpp);
// and the planning geometry (planning.hpp).
#include <algorithm>
#include <cmath>
#include <limits>

#include "manager/planning.hpp"
#include "manager/terrain_manager_impl.hpp"

namespace sandpatch {

using manager_detail::body_key;

Status TerrainManager::Impl::plan(double time) {
  std::vector<BodyMotion> motions;
  std::vector<RigidBodyId> motion_ids;  // the body of each motion
  std::vector<PatchRequest> planned;  // from planned paths
  for (RigidBodyId b : world->bodies()) {
    if (shells_sampled.insert(body_key(b)).second) {
      for (const TileSet& set : tile_sets) {
        auto pts = shell_points(b, set.scale);  // warms sample_shell's cache (meshes), per scale
        if (!pts) return pts.errors();
      }
    }
    // A tool on a planned path asks for its patch from the path, not from a ballistic guess
    // (which, for a bucket carrying soil in the air, predicted contacts ahead and grew a
    // patch there: the soil fell where the bucket left the first patch).
    if (plan_path(b, time, planned)) continue;
    BodyMotion m;
    world->bounds(b, &m.lo, &m.hi);
    const BodyState st = world->state(b);
    m.velocity = st.linear_velocity.cast<double>();
    // A body at rest for two frames in a row (a free body cannot be: gravity moves it)
    // lies on the terrain and disturbs nothing: it asks for no patch. Without this rule a
    // resting body asked again after every demotion and a queue never drained.
    const double reach = 0.5 * (m.hi - m.lo).norm();
    // (A kinematic body moving along its prescribed path, however slowly, is not resting.)
    const bool prescribed_moving = world->motion(b) == RigidMotion::Kinematic &&
                                   (st.linear_velocity.squaredNorm() > 0 || st.angular_velocity.squaredNorm() > 0);
    const bool still = !prescribed_moving && st.linear_velocity.norm() <= def.sleep_speed &&
                       st.angular_velocity.norm() * reach <= def.sleep_speed;
    int& frames_still = still_frames[body_key(b)];
    frames_still = still ? frames_still + 1 : 0;
    if (frames_still >= 2 || settling(b)) continue;
    // A body lying on the heightfield (slow, at the surface) that no patch carries asks for
    // none either: a patch would not take it up (lying), and its requests made patches come
    // and go under it.
    if (!carried_anywhere(b) && lying(b, m.lo, m.hi)) continue;
    motions.push_back(m);
    motion_ids.push_back(b);
  }
  // Requests are clipped to the terrain: a body landing at its edge asks for what exists
  // (before, a request reaching past the edge was never `covered` by the clipped patch and
  // made it `extend` - demote and promote again - every frame). Merged requests stay within
  // what one slot holds (before: unbounded, and bodies landing side by side merged into one
  // patch no slot could hold, an error mid-run).
  auto predicted = predict_contacts(*hf, motions, def.gravity, def.lod);
  predicted.insert(predicted.end(), planned.begin(), planned.end());
  for (auto& r : predicted) clip_to_terrain(*hf, r);
  auto reqs = merge_requests(std::move(predicted), max_merged_side());
  // A queued request lapses when no body predicts a contact there any more (its body came
  // to rest on the heightfield meanwhile); requests made with request_patch() stay.
  for (auto it = queue.begin(); it != queue.end();) {
    bool live = it->bodies.empty();
    for (const auto& r : reqs) live = live || it->overlaps(r);
    if (live) {
      ++it;
    } else {
      // One that waited for the frame budget: the bodies it was for now lie on the heightfield,
      // where a patch would have taken them (the report's budget.lapsed_after_waiting).
      if (it->waited_frames > 0 && budget_log_lapsed.size() < 256) {
        std::vector<std::string> names;
        for (RigidBodyId b : world->bodies()) {
          const Eigen::Vector3d p = world->state(b).position;
          if (!(p.x() >= it->x0 && p.x() <= it->x1 && p.z() >= it->z0 && p.z() <= it->z1)) continue;
          const std::string& n = world->definition(b).name;
          names.push_back(n.empty() ? "#" + std::to_string(b.index) : n);  // (unnamed: its index)
        }
        budget_log_lapsed.push_back({{"time_s", time},
                                     {"waited_frames", it->waited_frames},
                                     {"region_m", {it->x0, it->z0, it->x1, it->z1}},
                                     {"bodies", names}});
      }
      it = queue.erase(it);
      ++lapsed_requests;
    }
  }
  for (auto& r : reqs) {
    if (covered(r) || !has_soil(r)) continue;
    if (overlaps_patch(r)) {
      if (auto e = extend(r, time, motion_ids); !e) return e.errors();
      continue;
    }
    bool queued = false;
    for (const auto& q : queue) queued = queued || q.overlaps(r);
    if (!queued) {
      queue.push_back(r);
      events.push_back({PatchEventKind::Requested, -1, time, 0, 0});
    }
  }
  std::stable_sort(queue.begin(), queue.end(), [](const PatchRequest& p, const PatchRequest& q) {
    if (p.time_to_contact != q.time_to_contact) return p.time_to_contact < q.time_to_contact;
    return p.speed > q.speed;
  });
  return Ok{};
}

// A tool on a planned path (its keyframes, known ahead): the stretch of the path that works
// the ground is the run of path samples within reach of it around its first contact from now
// on (lowest point within lod.margin of the highest surface sample under the footprint): before
// the contact, lowest point below that surface + engage_height / 2 (where a patch's shell
// engages the body: coupling.cpp engages); after it, below the surface + carry_height (where
// the patch still carries what the tool scooped), so a carry up to 1 m high stays in the
// patch that dug it. One request covers the stretch's footprint plus lod.apron,
// asked for when that contact is within lod.horizon: the dig, the carry in the air and the
// dump are one patch, so the granules the tool scoops stay in the simulation that carries
// them until they are poured out (docs/manager.md "Tools on a planned path"). Without a
// contact ahead (the tool carrying, or past its path) nothing is asked for: the patch it is in
// covers the stretch. A stretch more than a slot holds is not asked for: the body is then
// predicted ballistically like any other (patches ahead of it) for the rest of its path, and
// the report's planned_paths says so. A game-driven tool's path (its motion held for
// lod.horizon, World look_ahead) is planned for by the same rules, frame by frame: a stretch
// too big in one frame is followed ballistically in that frame only.
bool TerrainManager::Impl::plan_path(RigidBodyId b, double time, std::vector<PatchRequest>& out) {
  const auto it = paths.find(body_key(b));
  if (it == paths.end() || it->second.empty()) return false;
  const bool extrapolated_path = extrapolated.count(body_key(b)) > 0;
  if (const auto l = path_log.find(body_key(b)); l != path_log.end() && l->second.too_big_frames > 0 && !extrapolated_path)
    return false;
  const std::vector<TerrainManager::PathPose>& path = it->second;
  // the sample the body is at (the last at or before now), then the later ones
  std::size_t first = std::size_t(std::upper_bound(path.begin(), path.end(), time + 1e-9,
                                                   [](double t, const TerrainManager::PathPose& p) { return t < p.t; }) -
                                  path.begin());
  if (first > 0) --first;
  auto ground = [&](const TerrainManager::PathPose& p) { return max_height_under(*hf, p.lo.x(), p.lo.z(), p.hi.x(), p.hi.z()); };
  // (within `above` m of the ground: engage_height / 2 on the way to the contact, where a
  // patch's shell engages the tool; carry_height after it, up to which the patch carries what
  // the tool scooped, coupling.cpp engage_limit)
  auto in_reach = [&](const TerrainManager::PathPose& p, double above) {
    const double g = ground(p);
    return std::isfinite(g) && p.lo.y() < g + above;
  };
  std::size_t k0 = path.size();
  for (std::size_t k = first; k < path.size() && path[k].t <= time + def.lod.horizon; ++k) {
    const double g = ground(path[k]);
    if (std::isfinite(g) && path[k].lo.y() <= g + def.lod.margin) {
      k0 = k;
      break;
    }
  }
  if (k0 == path.size()) return true;
  std::size_t s = k0, e = k0;
  // (An extrapolated path's stretch starts at its contact: what lies before it is the game's
  // tool on its way there, in the air, and no patch is needed under it.)
  while (!extrapolated_path && s > first && in_reach(path[s - 1], 0.5 * engage_height)) --s;
  while (e + 1 < path.size() && in_reach(path[e + 1], carry_height)) ++e;
  Eigen::Vector3d lo = path[s].lo, hi = path[s].hi;
  for (std::size_t k = s; k <= e; ++k) lo = lo.cwiseMin(path[k].lo), hi = hi.cwiseMax(path[k].hi);
  PatchRequest r;
  r.x0 = lo.x() - def.lod.apron, r.x1 = hi.x() + def.lod.apron;
  r.z0 = lo.z() - def.lod.apron, r.z1 = hi.z() + def.lod.apron;
  r.apron = def.lod.apron;
  r.time_to_contact = std::max(0.0, path[k0].t - time);
  r.speed = double(world->state(b).linear_velocity.norm());
  r.bodies = {-1};  // (not a BodyMotion index: it lapses when the path asks for it no more)
  clip_to_terrain(*hf, r);
  if (r.x1 - r.x0 < 1e-6 || r.z1 - r.z0 < 1e-6 || covered(r)) return true;
  PathLog& log = path_log[body_key(b)];
  log.name = world->definition(b).name;
  log.extrapolated = extrapolated_path;
  log.last = r;
  log.from = path[s].t, log.to = path[e].t;
  // (its region as if no patch were live: predict_granules would move it clear of the live
  // ones, or find no room and predict none)
  {
    const double sc = scale_for(r);
    log.granules = 0;
    if (auto reg = patch_region(*hf, r, set_for(sc).cells)) {
      float lo_h = 0, hi_h = 0;
      const double fl = floor_of(*reg, sc, &lo_h, &hi_h);
      const TileSet& set = set_for(sc);
      const double pf = set.tiles.empty() ? 0.6 : set.tiles.front().packing_fraction;
      log.granules = int(std::clamp(soil_volume(*hf, *reg, fl) * pf / granule_volume(sc), 0.0, 1e9));
    }
  }
  if (log.granules > def.granules_per_slot) {
    ++log.too_big_frames;
    return false;
  }
  ++log.asked_frames;
  out.push_back(std::move(r));
  return true;
}

// The scale a request is promoted at (Leach & Marais §4.3, §6.3 scenario 2): its own (a
// patch asked for ahead of a body keeps the scale of the one it is in), else the first band whose max_distance reaches
// the 3-D distance from the camera to the request's centre on the surface (the last band's
// beyond), else particle_scale.
double TerrainManager::Impl::scale_for(const PatchRequest& r) const {
  if (r.particle_scale > 0) return r.particle_scale;
  if (def.scale_bands.empty()) return def.particle_scale;
  const double x = 0.5 * (r.x0 + r.x1), z = 0.5 * (r.z0 + r.z1);
  const double y = hf->origin_y() + hf->sample(float(x - hf->origin_x()), float(z - hf->origin_z()));
  const double d = (Eigen::Vector3d(x, y, z) - camera).norm();
  for (const auto& b : def.scale_bands)
    if (d <= b.max_distance) return b.particle_scale;
  return def.scale_bands.back().particle_scale;
}

// m: the widest square request that merging may make, so that one slot holds its patch: the
// side of a patch_depth-deep square of granules_per_slot granules at the first tile's
// packing, with 20 % to spare, less the rounding out to whole tile periods (patch_region:
// up to one period and a sample on each axis). Requests wider than that are not merged
// (each single request is still checked against the capacity in promote()).
double TerrainManager::Impl::max_merged_side() const {
  const double fill = std::min(def.patch_depth, def.soil_depth);  // m
  // (With scale bands, at the finest scale: the most granules per area.)
  double side = std::numeric_limits<double>::max();
  for (const TileSet& t : tile_sets) {
    const double pf = t.tiles.empty() ? 0.5 : t.tiles.front().packing_fraction;
    const double area = def.granules_per_slot * granule_volume(t.scale) / (pf * std::max(fill, 1e-6)) / 1.2;  // m²
    side = std::min(side, std::sqrt(area) - (max_cells() + 1) * double(hf->spacing()));
  }
  return side;
}

// Whether a request can become a patch: its region is on the terrain and has soil above the
// bedrock. (A body falling just past the terrain's edge, or onto bare rock, asks for a
// patch that cannot exist; before, promote() failed the whole frame with an error.)
bool TerrainManager::Impl::has_soil(const PatchRequest& r) const {
  const double s = scale_for(r);
  auto reg = region_for(r, s);
  if (!reg) return false;
  float lo = 0, hi = 0;
  return floor_of(*reg, s, &lo, &hi) < hi;
}

// The region a request is promoted over at scale s: patch_region (whole tile periods), moved
// clear of the live patches' regions where the rounding pushed it into one (a patch asked for
// ahead of another abuts it: they share the boundary's samples, not cells).
Result<GridRegion> TerrainManager::Impl::region_for(const PatchRequest& r, double s) const {
  if (r.successor_of >= 0) return GridRegion{r.region_i0, r.region_j0, r.region_ni, r.region_nj};  // (overlaps its predecessor)
  auto reg = patch_region(*hf, r, set_for(s).cells);
  if (!reg) return reg;
  GridRegion g = *reg;
  for (const Slot& sl : slots) {
    if (!sl.live()) continue;
    const GridRegion& R = sl.region;
    const bool over_i = g.i0 < R.i0 + R.ni - 1 && R.i0 < g.i0 + g.ni - 1;
    const bool over_j = g.j0 < R.j0 + R.nj - 1 && R.j0 < g.j0 + g.nj - 1;
    if (!over_i || !over_j) continue;
    // The smallest move along one axis that leaves them sharing at most a line of samples.
    const int moves[4] = {R.i0 + R.ni - 1 - g.i0, R.i0 - (g.i0 + g.ni - 1), R.j0 + R.nj - 1 - g.j0, R.j0 - (g.j0 + g.nj - 1)};
    int best = -1;
    for (int k = 0; k < 4; ++k) {
      const bool along_i = k < 2;
      const int lo = along_i ? g.i0 + moves[k] : g.j0 + moves[k];
      const int hi = lo + (along_i ? g.ni : g.nj) - 1;
      if (lo < 0 || hi > (along_i ? hf->samples_x() : hf->samples_z()) - 1) continue;
      if (best < 0 || std::abs(moves[k]) < std::abs(moves[best])) best = k;
    }
    if (best < 0) return Error{"", "patch request", "", "no room beside the live patch"};
    (best < 2 ? g.i0 : g.j0) += moves[best];
  }
  return g;
}

bool TerrainManager::Impl::covered(const PatchRequest& r) const {
  for (const Slot& s : slots) {
    if (s.state == SlotState::Free) continue;
    const double sp = hf->spacing();
    const double x0 = hf->origin_x() + s.region.i0 * sp, x1 = x0 + (s.region.ni - 1) * sp;
    const double z0 = hf->origin_z() + s.region.j0 * sp, z1 = z0 + (s.region.nj - 1) * sp;
    if (r.x0 >= x0 && r.x1 <= x1 && r.z0 >= z0 && r.z1 <= z1) return true;
  }
  return false;
}

bool TerrainManager::Impl::overlaps_patch(const PatchRequest& r) const {
  for (const Slot& s : slots)
    if (s.state != SlotState::Free && rect(s).overlaps(r)) return true;
  return false;
}

// A body in a patch heading past its edge (its predicted contact reaches beyond the region):
// a patch is asked for ahead of it, abutting the one it is in, over the part of its request
// that the patch does not cover on a side it passes (the one it passes most that has room), or
// the patch travels (ask_successor); each patch the request overlaps is looked at. It goes to
// the front of the queue; filled in chunks over the next frames (at once when the body would
// reach it within two frames), it takes the body over when it holds most of the body's
// footprint (one carrier per body, coupling.cpp), and the patch left behind is released when a request needs its
// slot (release_idle) or after idle_timeout. Nothing is demoted and filled again in one frame
// (before, the patch was demoted and the union promoted in the same frame: a whole patch's
// work twice in one frame). Returns whether it asked.
Result<bool> TerrainManager::Impl::extend(const PatchRequest& r, double time, const std::vector<RigidBodyId>& ids) {
  bool asked = false;
  for (Slot& s : slots) {
    if ((s.state != SlotState::Active && s.state != SlotState::Asleep) || !rect(s).overlaps(r)) continue;
    if (s.superseded) continue;  // (its successor carries the bodies now)
    const PatchRequest a = rect(s);
    // Only when the predicted contact itself (the request without its apron) comes within
    // two granule diameters of the patch's edge: a body settling near the middle whose
    // apron pokes out by a few mm must not make the patch grow.
    // A side of the patch on the terrain's edge cannot be crossed (requests are clipped there).
    // The margin holds on the sides the request's bodies move toward, by at least the margin
    // within lod.horizon; on the others only the contact reaching past the edge itself asks (a
    // wheel running alongside a patch's side 0.3 m from it, jostled sideways as it sank in,
    // asked at once for patches on both sides, which held two slots for nothing).
    const double m = 4.0 * radius_world(s), ap = r.apron, e = 1e-6;
    const double toward = m / std::max(1e-6, double(def.lod.horizon));  // m/s
    double mm[4] = {0, 0, 0, 0};
    for (int k : r.bodies) {
      if (k < 0 || k >= int(ids.size())) continue;
      const Eigen::Vector3f v = world->state(ids[std::size_t(k)]).linear_velocity;
      if (v.x() <= -toward) mm[0] = m;
      if (v.x() >= toward) mm[1] = m;
      if (v.z() <= -toward) mm[2] = m;
      if (v.z() >= toward) mm[3] = m;
    }
    if (r.bodies.empty() || r.bodies.front() < 0) mm[0] = mm[1] = mm[2] = mm[3] = m;  // a planned path's
    const PatchRequest t = terrain_rect(*hf);
    const double past[4] = {a.x0 <= t.x0 + e ? -1.0 : (a.x0 + mm[0]) - (r.x0 + ap), a.x1 >= t.x1 - e ? -1.0 : (r.x1 - ap) - (a.x1 - mm[1]),
                            a.z0 <= t.z0 + e ? -1.0 : (a.z0 + mm[2]) - (r.z0 + ap), a.z1 >= t.z1 - e ? -1.0 : (r.z1 - ap) - (a.z1 - mm[3])};
    // The sides it passes, most first, past a side where the part ahead would lie in another
    // live patch (a car's request, over both its track patches, passes the side each shares
    // with the other by a whole period: looked at alone, that side hid the leading side until
    // the wheels were two frames from it, and the successor's fill fell whole into that frame).
    int sides[4] = {0, 1, 2, 3};
    std::stable_sort(sides, sides + 4, [&](int x, int y) { return past[x] > past[y]; });
    for (int side : sides) {
      if (!(past[side] > 0)) break;  // (another patch it overlaps may be the one it passes)
      if (ask_successor(s, r, side, time)) {
        asked = true;  // (the next patch the request overlaps may need one too: a car's other track)
        break;
      }
      // The part ahead, at least one tile period deep (patch_region rounds it to whole periods,
      // and promote() moves it clear of the patch it abuts).
      const double period = set_for(s.scale).cells * double(hf->spacing());
      PatchRequest u = r;
      switch (side) {
        case 0: u.x1 = a.x0, u.x0 = std::min(r.x0, a.x0 - period); break;
        case 1: u.x0 = a.x1, u.x1 = std::max(r.x1, a.x1 + period); break;
        case 2: u.z1 = a.z0, u.z0 = std::min(r.z0, a.z0 - period); break;
        default: u.z0 = a.z1, u.z1 = std::max(r.z1, a.z1 + period); break;
      }
      clip_to_terrain(*hf, u);
      // (ahead of this patch lies another: the part ahead may be asked for beyond that one, when
      // the request overlaps it too, as where a body turning crosses the corner of two patches)
      if (u.x1 - u.x0 < 1e-6 || u.z1 - u.z0 < 1e-6 || overlaps_patch(u) || !has_soil(u)) continue;  // (the next side it passes)
      // (asked already: the next patch the request overlaps, which may be passed too)
      if (std::any_of(queue.begin(), queue.end(), [&](const PatchRequest& q) { return q.overlaps(u); })) break;
      u.time_to_contact = 0;
      u.abuts = side ^ 1;  // (side 0, x0 of the patch, is its x1; and so on)
      // (ahead of a body the patch carries, moving toward that side faster than sleep_speed: it
      // does not wait for the budget, filling.cpp)
      const Eigen::Vector2d out[4] = {{-1, 0}, {1, 0}, {0, -1}, {0, 1}};
      for (int k : r.bodies) {
        if (k < 0 || k >= int(ids.size())) continue;
        const RigidBodyId b = ids[std::size_t(k)];
        const Eigen::Vector3f v = world->state(b).linear_velocity;
        if (out[side].dot(Eigen::Vector2d(v.x(), v.z())) <= def.sleep_speed) continue;
        for (const Carried& c : s.carried)
          if (c.enabled && c.body.index == b.index && c.body.generation == b.generation) u.ahead_of_carried = true;
      }
      // The budget may trim its apron across the way it extends only (budget.cpp choose).
      u.apron = budget_on() ? r.apron : 0;
      u.particle_scale = budget_on() ? 0.0 : s.scale;  // its scale, or the budget's choice again
      queue.insert(queue.begin(), u);
      events.push_back({PatchEventKind::Requested, -1, time, 0, 0});
      ++extensions;
      return true;
    }
  }
  return asked;
}

// A patch that travels with its bodies (docs/manager.md "A patch that travels with its body"):
// instead of a patch abutting s ahead (two patches stepping while the bodies straddle their
// edge), s itself moved by the fewest whole tile periods toward `side` that cover the request
// r, if every body s carries then lies inside it (4 granule radii from its trailing side), one
// of them heads toward `side`, and it keeps part of s. Its fill is cut from the tile only where
// it reaches past s (whole tile periods: the seam is the tiles' own), it takes s's granules
// over at once when that fill is in (take_over), and s is demoted. Not when s has a successor coming already, carries
// nothing, is being released, or when the moved region has another floor (sloping ground:
// the granules taken over keep their heights) or leaves the terrain. Returns whether one was
// asked (now or before).
bool TerrainManager::Impl::ask_successor(Slot& s, const PatchRequest& r, int side, double time) {
  if (!def.lod.travel) return false;
  if (s.successor >= 0) return true;
  for (const PatchRequest& q : queue)
    if (q.successor_of == s.patch) return true;
  if (s.rebase_from >= 0) return true;  // (its own predecessor's demotion first: asked again next frame)
  if (s.superseded || s.demotion.releasing) return false;
  const int axis = side / 2, dir = side % 2 == 0 ? -1 : 1, c3 = axis == 0 ? 0 : 2;
  const double sp = hf->spacing();
  const int cells = set_for(s.scale).cells;
  const GridRegion& R = s.region;
  const int lo0 = axis == 0 ? R.i0 : R.j0, n = axis == 0 ? R.ni : R.nj;  // samples along the axis
  const int samples = axis == 0 ? hf->samples_x() : hf->samples_z();
  const double o = axis == 0 ? hf->origin_x() : hf->origin_z();
  // (a region cut at the terrain's edge to other than whole tile periods has no tile wall where
  // the successor's own fill would meet the granules it takes over)
  if ((n - 1) % cells != 0) return false;
  // Leading side: the fewest whole periods that reach the request's far edge (at least one).
  const double far = dir > 0 ? (axis == 0 ? r.x1 : r.z1) : (axis == 0 ? r.x0 : r.z0);
  const double reach = dir > 0 ? std::ceil((far - o) / sp) - (lo0 + n - 1) : lo0 - std::floor((far - o) / sp);
  const int k = std::max(1, int(std::ceil(std::max(0.0, reach) / cells)));
  // Trailing side: the most whole periods (at most k) that keep every body s carries on its
  // ground (lowest point within a granule diameter of the surface under it) 4 granule radii
  // inside, and the centre of every other body it carries (a vehicle's chassis, a body falling
  // onto it).
  const GranuleShape& shape = s.sim->granule_shape();  // (sim units)
  const double m = 4.0 * radius_world(s), diameter = 2.0 * double(shape.centre_distance + shape.radius) * s.scale;
  double behind = dir > 0 ? std::numeric_limits<double>::max() : -std::numeric_limits<double>::max();  // trailing-most point (m, along the axis)
  // (a body it carries moving toward the side faster than a body settling creeps, 10
  // sleep_speed as in `lying`: bodies landing on it, or a parked car's wheels jostling as they
  // settle, do not make it travel; a successor grown sideways under a car settling at rest cut
  // room for the wheels where the terrain grid had held them, and they sank a granule deep)
  const double toward = 10.0 * def.sleep_speed;  // m/s
  bool carries_any = false, moving = false;
  for (const Carried& c : s.carried) {
    if (!c.enabled || !world->alive(c.body)) continue;
    carries_any = true;
    // (and heading toward it: at least a quarter as fast toward the side as along it, 14° off
    // its line, so a car driving on while it drifts across its way does not take its track's
    // patch sideways over the other track; a patch abutting beside it takes a wheel that
    // reaches the side. A car turning at the scenes' 0.25 rad keeps travelling with its turn.)
    const Eigen::Vector3f v = world->state(c.body).linear_velocity;
    const double to_side = double(dir) * double(v[c3]), along_side = std::abs(double(v[c3 == 0 ? 2 : 0]));
    moving = moving || (to_side >= toward && to_side >= 0.25 * along_side);
    Eigen::Vector3d blo, bhi;
    world->bounds(c.body, &blo, &bhi);
    const double ground = hf->origin_y() + hf->sample(float(0.5 * (blo.x() + bhi.x()) - hf->origin_x()), float(0.5 * (blo.z() + bhi.z()) - hf->origin_z()));
    const double centre = 0.5 * (blo[c3] + bhi[c3]);
    const bool on_ground = blo.y() <= ground + diameter;
    behind = dir > 0 ? std::min(behind, on_ground ? blo[c3] : centre) : std::max(behind, on_ground ? bhi[c3] : centre);
  }
  if (!carries_any || !moving) return false;
  int t = k;
  auto trailing_edge = [&](int tt) { return o + (dir > 0 ? lo0 + tt * cells : lo0 + n - 1 - tt * cells) * sp; };
  while (t > 0 && (dir > 0 ? behind < trailing_edge(t) + m : behind > trailing_edge(t) - m)) --t;
  if ((n - 1) - t * cells < cells) return false;  // (it keeps at least a tile period of s)
  GridRegion g = R;
  int& g_lo = axis == 0 ? g.i0 : g.j0;
  int& g_n = axis == 0 ? g.ni : g.nj;
  if (dir > 0) g_lo += t * cells, g_n += (k - t) * cells;
  else g_lo -= k * cells, g_n += (k - t) * cells;
  if (g_lo < 0 || g_lo + g_n - 1 > samples - 1) return false;
  float flo = 0, fhi = 0;
  // (ground lower than where s was promoted, a rut its predecessor wrote, is filled from s's
  // floor as well; higher ground, whose floor would be higher, is not travelled onto)
  if (floor_of(g, s.scale, &flo, &fhi) > s.floor_local + 1e-6 || !(s.floor_local < fhi)) return false;
  PatchRequest u = r;
  u.x0 = hf->origin_x() + g.i0 * sp, u.x1 = hf->origin_x() + (g.i0 + g.ni - 1) * sp;
  u.z0 = hf->origin_z() + g.j0 * sp, u.z1 = hf->origin_z() + (g.j0 + g.nj - 1) * sp;
  for (const Slot& o2 : slots)  // (it may overlap s only: another live patch there, and a patch abuts ahead instead)
    if (&o2 != &s && o2.live() && rect(o2).overlaps(u)) return false;
  u.successor_of = s.patch;
  u.region_i0 = g.i0, u.region_j0 = g.j0, u.region_ni = g.ni, u.region_nj = g.nj;
  // (no more granules than a slot holds: else a patch ahead abuts it, as before)
  const TileSet& set = set_for(s.scale);
  const double pf = set.tiles.empty() ? 0.6 : set.tiles.front().packing_fraction;
  if (soil_volume(*hf, g, s.floor_local) * pf / granule_volume(s.scale) > 0.9 * def.granules_per_slot) return false;
  u.particle_scale = s.scale;
  u.steps_per_contact = s.steps_per_contact;
  u.apron = 0;
  u.abuts = -1;
  u.ahead_of_carried = true;
  u.time_to_contact = 0;
  queue.insert(queue.begin(), u);
  events.push_back({PatchEventKind::Requested, -1, time, 0, 0});
  ++extensions;
  return true;
}

// Whether a body is over a patch, or near it (within half lod.apron of its region, below
// engage_height over its surface), or it carries one: such a patch is not released. One that
// never carried a body (released only for a body another patch carries: release_idle) is
// wanted while a body is coming to it (body_coming).
bool TerrainManager::Impl::wanted_for_release(const Slot& s) const {
  if (s.carried.empty()) return body_coming(s);
  for (const Carried& c : s.carried)
    if (c.enabled && world->alive(c.body)) return true;
  const PatchRequest a = rect(s);
  const double pad = double(def.lod.apron) * 0.5;
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    if (lo.x() < a.x1 + pad && hi.x() > a.x0 - pad && lo.z() < a.z1 + pad && hi.z() > a.z0 - pad &&
        lo.y() < hf->origin_y() + s.top_local + engage_height)
      return true;
  }
  return false;
}

// A ready patch no body is over any more (its bodies moved on to a patch ahead, or away)
// starts its demotion to free its slot for a request waiting for one: it is held (not
// stepped) and demoted one part a frame (activate), the first part now. Returns whether one
// started (or one is under way already).
// Its first part: held from now on, demoted one part a frame (activate runs the rest).
Status TerrainManager::Impl::release(Slot& s, double time) {
  s.demotion.releasing = true;
  if (Status st = demote(s, time, false, /*staged=*/true); !st) return st;
  released += s.state == SlotState::Free;
  return Ok{};
}

// Whether a body is coming to s: one no patch carries lies over it (its footprint over s's
// region, at any height: a body falling onto it), or one another patch carries has its
// centre over it (a patch just filled ahead of a wheel that its old patch still carries: the
// wheel is handed over at the next coupling).
bool TerrainManager::Impl::body_coming(const Slot& s) const {
  const PatchRequest a = rect(s);
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    if (!carried_anywhere(b)) {
      if (lo.x() < a.x1 && hi.x() > a.x0 && lo.z() < a.z1 && hi.z() > a.z0) return true;
      continue;
    }
    const double cx = 0.5 * (lo.x() + hi.x()), cz = 0.5 * (lo.z() + hi.z());
    if (cx > a.x0 && cx < a.x1 && cz > a.z0 && cz < a.z1) return true;
  }
  return false;
}

// A patch no body has reached yet is kept for the body it was made for, except from a
// request for a body a patch carries: then one that no body is coming to is released (a car's
// patch asked for beside a wheel that drove on alongside kept one of three slots, asleep or
// held by the budget, and the car's successors waited for it: its wheels ran on the
// heightfield; docs/manager.md "No frame does a whole patch's work", "Release").
Result<bool> TerrainManager::Impl::release_idle(double time, bool for_carried) {
  for (Slot& s : slots)
    if (s.demotion.releasing) return true;
  for (Slot& s : slots) {
    if (!s.ready()) continue;
    if ((s.carried.empty() && !for_carried) || wanted_for_release(s)) continue;
    if (Status st = release(s, time); !st) return st.errors();
    return true;
  }
  return false;
}

// ---- planning geometry (planning.hpp) ----

namespace {
// Trapezoid weights of a sample in a region (½ on edges, ¼ at corners): Σ w h sp² is the
// volume under the bilinear surface.
double trapezoid_weight(int i, int j, const GridRegion& r) {
  const double wi = (i == r.i0 || i == r.i0 + r.ni - 1) ? 0.5 : 1.0;
  const double wj = (j == r.j0 || j == r.j0 + r.nj - 1) ? 0.5 : 1.0;
  return wi * wj;
}
}  // namespace

PatchRequest terrain_rect(const Heightfield& hf) {
  PatchRequest t;
  t.x0 = hf.origin_x();
  t.z0 = hf.origin_z();
  t.x1 = t.x0 + (hf.samples_x() - 1) * double(hf.spacing());
  t.z1 = t.z0 + (hf.samples_z() - 1) * double(hf.spacing());
  return t;
}

void clip_to_terrain(const Heightfield& hf, PatchRequest& r) {
  const PatchRequest t = terrain_rect(hf);
  r.x0 = std::max(r.x0, t.x0), r.z0 = std::max(r.z0, t.z0);
  r.x1 = std::min(r.x1, t.x1), r.z1 = std::min(r.z1, t.z1);
}

Result<GridRegion> patch_region(const Heightfield& hf, const PatchRequest& r, int tile_cells) {
  // The samples around the rectangle: the last at or below its low side, the first at or
  // above its high side (a side on a sample, as a patch asked for ahead of another has, to
  // round-off: that sample; before, one more, and a rectangle of exactly one tile period
  // took two).
  const double tol = 1e-6;
  auto below = [&](double x, double o) { return int(std::floor((x - o) / hf.spacing() + tol)); };
  auto above = [&](double x, double o) { return int(std::ceil((x - o) / hf.spacing() - tol)); };
  int i0 = std::max(0, below(r.x0, hf.origin_x())), j0 = std::max(0, below(r.z0, hf.origin_z()));
  int i1 = std::min(hf.samples_x() - 1, above(r.x1, hf.origin_x())), j1 = std::min(hf.samples_z() - 1, above(r.z1, hf.origin_z()));
  if (i1 - i0 < 2 || j1 - j0 < 2) return Error{"", "patch request", "", "off the terrain"};
  auto align = [&](int& a, int& b, int samples) {
    const int cells = b - a, whole = ((cells + tile_cells - 1) / tile_cells) * tile_cells;
    if (whole > samples - 1) return;  // terrain narrower than the rounded patch: keep the cut sides
    a -= (whole - cells) / 2;
    b = a + whole;
    if (a < 0) b -= a, a = 0;
    if (b > samples - 1) a -= b - (samples - 1), b = samples - 1;
  };
  align(i0, i1, hf.samples_x());
  align(j0, j1, hf.samples_z());
  return GridRegion{i0, j0, i1 - i0 + 1, j1 - j0 + 1};
}

double patch_floor(const Heightfield& hf, const GridRegion& region, double patch_depth, double soil_depth,
                   double bedrock_height, float* lo, float* hi) {
  *lo = std::numeric_limits<float>::max(), *hi = -*lo;
  double bedrock = -std::numeric_limits<double>::infinity();
  for (int j = region.j0; j < region.j0 + region.nj; ++j)
    for (int i = region.i0; i < region.i0 + region.ni; ++i) {
      const float h = hf.height(i, j);
      *lo = std::min(*lo, h);
      *hi = std::max(*hi, h);
      bedrock = std::max({bedrock, double(h) - soil_depth, std::min(double(h), bedrock_height)});
    }
  return std::max(double(*lo) - patch_depth, bedrock);
}

double soil_volume(const Heightfield& hf, const GridRegion& region, double floor_local) {
  const float sp = hf.spacing();
  double v = 0;
  for (int j = region.j0; j < region.j0 + region.nj; ++j)
    for (int i = region.i0; i < region.i0 + region.ni; ++i)
      v += trapezoid_weight(i, j, region) * (hf.height(i, j) - floor_local);
  return v * double(sp) * sp;
}

}  // namespace sandpatch
