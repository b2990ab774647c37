#include "manager/world.hpp"

#include <algorithm>
#include <cstdio>
#include <chrono>
#include <cmath>
#include <optional>

#include "common/hash.hpp"

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;
using ojson = nlohmann::ordered_json;

ojson vec_json(const Eigen::Vector3d& v) { return ojson::array({v.x(), v.y(), v.z()}); }
ojson vec_json(const Eigen::Vector3f& v) { return ojson::array({v.x(), v.y(), v.z()}); }

bool same(RigidBodyId a, RigidBodyId b) { return a.index == b.index && a.generation == b.generation; }

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

Result<std::unique_ptr<World>> World::create(Heightfield terrain, const Eigen::Vector3f& gravity) {
  std::unique_ptr<World> w(new World());
  w->hf_ = std::make_unique<Heightfield>(std::move(terrain));
  auto bullet = BulletWorld::create(*w->hf_, gravity);
  if (!bullet) return bullet.errors();
  w->bullet_ = std::move(*bullet);
  return w;
}

World::~World() = default;

Status World::enable_patches(const TerrainManagerDef& def) {
  if (manager_) return Error{"", "World.patches", "", "enable_patches may be called once"};
  auto m = TerrainManager::create(def, *hf_, *bullet_);
  if (!m) return m.errors();
  manager_ = std::move(*m);
  follow_apron_ = def.lod.apron;
  look_ahead_s_ = def.lod.horizon;
  return Ok{};
}

// ---- bodies ----

Status World::check_body(const RigidBodyDef& def) const {
  if (!manager_) return Ok{};
  return manager_->check_shell(def.shape);
}

Result<RigidBodyId> World::add_body(const RigidBodyDef& def) {
  if (Status s = check_body(def); !s) return s.errors();
  auto id = bullet_->add_body(def);
  if (id) {
    entries_.push_back({def.name, time(), *id, false});
    enter_kinematic(entries_.size() - 1, def);
  }
  return id;
}

// A kinematic body enters moving at its definition's velocities, held until changed.
void World::enter_kinematic(std::size_t entry, const RigidBodyDef& def) {
  if (def.motion != RigidMotion::Kinematic) return;
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  kinematic_[entry].v = def.linear_velocity;
  kinematic_[entry].w = def.angular_velocity;
}

Result<RigidBodyId> World::adopt_body(btRigidBody* body, const std::string& name) {
  auto id = bullet_->adopt_body(body, name);
  if (id) entries_.push_back({name, time(), *id, false});
  return id;
}

std::size_t World::schedule_body(const RigidBodyDef& def, double spawn_time) {
  entries_.push_back({def.name, spawn_time, RigidBodyId{}, false});
  pending_.emplace_back(entries_.size() - 1, def);
  return entries_.size() - 1;
}

void World::remove_body(RigidBodyId id) {
  if (!alive(id)) return;
  // Its joints go at once (the body itself may stay in Bullet until the next step, far above).
  for (JointEntry& j : joints_) {
    if (j.removed || !j.id.valid() || !bullet_->joint_alive(j.id)) continue;
    const RigidJointDef& d = bullet_->joint_definition(j.id);
    if (same(d.a, id) || (d.b.valid() && same(d.b, id))) {
      bullet_->remove_joint(j.id);
      j.removed = true;
    }
  }
  for (Entry& e : entries_)
    if (same(e.id, id)) e.removed = true;
  if (!manager_ || bullet_->adopted(id)) {
    bullet_->remove_body(id);
    return;
  }
  BodyState st = bullet_->state(id);
  st.position.y() = hf_->origin_y() + double(hf_->max_height()) + 1000.0;  // m, far above any patch
  st.linear_velocity.setZero();
  st.angular_velocity.setZero();
  bullet_->set_state(id, st);
  removing_.push_back(id);
}

void World::discard_body(RigidBodyId id) {
  if (!alive(id)) return;
  for (Entry& e : entries_)
    if (same(e.id, id)) e.removed = true;
  bullet_->remove_body(id);
}

bool World::alive(RigidBodyId id) const {
  if (!bullet_->alive(id)) return false;
  return std::none_of(removing_.begin(), removing_.end(), [&](RigidBodyId r) { return same(r, id); });
}

std::vector<RigidBodyId> World::bodies() const {
  std::vector<RigidBodyId> out;
  for (RigidBodyId id : bullet_->bodies())
    if (alive(id)) out.push_back(id);
  return out;
}

// ---- reading the soil ----

double World::lowest_point(RigidBodyId id) const {
  const BodyState st = bullet_->state(id);
  return st.position.y() - extent_below(bullet_->definition(id).shape, st.orientation);
}

double World::extent_below(const RigidShape& s, const Eigen::Quaternionf& q) {
  return extent_along(s, q, Eigen::Vector3d(0, -1, 0));
}

double World::extent_along(const RigidShape& s, const Eigen::Quaternionf& q, const Eigen::Vector3d& dir) {
  const Eigen::Matrix3d R = q.cast<double>().normalized().toRotationMatrix();
  const Eigen::Vector3d d = R.transpose() * dir;  // body-frame coordinates of dir: dir · (R p) = d · p
  double reach = 0;  // m, from the centre of mass along dir to the farthest point
  switch (s.kind) {
    case RigidShapeKind::Sphere: reach = s.radius * d.norm(); break;
    case RigidShapeKind::Box:
      reach = std::abs(d.x()) * s.half_extents.x() + std::abs(d.y()) * s.half_extents.y() + std::abs(d.z()) * s.half_extents.z();
      break;
    case RigidShapeKind::Cylinder: {  // axis on body y: a rim point
      const double across = std::sqrt(std::max(0.0, d.squaredNorm() - d.y() * d.y()));
      reach = std::abs(d.y()) * 0.5 * s.height + across * s.radius;
      break;
    }
    case RigidShapeKind::Capsule: reach = std::abs(d.y()) * 0.5 * s.height + s.radius * d.norm(); break;
    case RigidShapeKind::Mesh:
      for (const auto& v : s.vertices) reach = std::max(reach, d.dot(v.cast<double>()));
      break;
  }
  return reach;
}

double World::original_height(double x, double z) const {
  const Heightfield& hf = *hf_;
  const float lx = float(x - hf.origin_x()), lz = float(z - hf.origin_z());
  if (original_tiles_.empty()) return hf.origin_y() + hf.sample(lx, lz);
  // Heightfield::sample's cell and weights, read from the kept tile where there is one.
  auto locate = [&](float c, int n, int& i, float& u) {
    float f = c / hf.spacing();
    if (!(f > 0)) f = 0;
    if (f > float(n - 1)) f = float(n - 1);
    i = std::min(static_cast<int>(f), n - 2);
    u = f - float(i);
  };
  int i, j;
  float u, v;
  locate(lx, hf.samples_x(), i, u);
  locate(lz, hf.samples_z(), j, v);
  const int C = hf.tile_cells(), tx = i / C, tz = j / C;
  const auto it = original_tiles_.find(std::size_t(tz) * hf.tiles_x() + tx);
  if (it == original_tiles_.end()) return hf.origin_y() + hf.sample(lx, lz);
  const int nx = hf.tile_samples_x(tx);
  const float* p = it->second.data() + std::size_t(j - tz * C) * nx + (i - tx * C);
  const float h00 = p[0], h10 = p[1], h01 = p[nx], h11 = p[nx + 1];
  return hf.origin_y() + double((1 - u) * (1 - v) * h00 + u * (1 - v) * h10 + (1 - u) * v * h01 + u * v * h11);
}

// Before a demotion may write the heightfield: every tile under a live patch's apron (and the
// sample beyond it the border band reaches) is copied once, as it was.
void World::keep_original_heights() {
  if (!manager_) return;
  const Heightfield& hf = *hf_;
  const int C = hf.tile_cells();
  for (const auto& p : manager_->patches()) {
    const GridRegion& a = p.apron;
    const int i0 = std::max(0, a.i0 - 2), i1 = std::min(hf.samples_x() - 1, a.i0 + a.ni + 1);
    const int j0 = std::max(0, a.j0 - 2), j1 = std::min(hf.samples_z() - 1, a.j0 + a.nj + 1);
    for (int tz = std::max(0, (j0 - 1) / C); tz <= std::min(hf.tiles_z() - 1, j1 / C); ++tz)
      for (int tx = std::max(0, (i0 - 1) / C); tx <= std::min(hf.tiles_x() - 1, i1 / C); ++tx) {
        const std::size_t key = std::size_t(tz) * hf.tiles_x() + tx;
        if (original_tiles_.count(key)) continue;
        const float* d = hf.tile_data(tx, tz);
        original_tiles_[key].assign(d, d + std::size_t(hf.tile_samples_x(tx)) * hf.tile_samples_z(tz));
      }
  }
}

World::Contact World::contact(RigidBodyId id) const {
  Contact c;
  if (!alive(id)) return c;
  c.granular = soil_force(id);
  c.heightfield_force = bullet_->terrain_force(id);
  const BodyState st = bullet_->state(id);
  c.lowest_y = lowest_point(id);
  c.original_surface_y = original_height(st.position.x(), st.position.z());
  c.sinkage = c.original_surface_y - c.lowest_y;
  return c;
}

World::SoilForce World::soil_force(RigidBodyId id) const {
  SoilForce out;
  if (manager_ && alive(id)) out.carried = manager_->soil_force(id, &out.force, &out.torque);
  return out;
}

// ---- the frame ----

void World::set_camera(const Eigen::Vector3d& position) {
  if (manager_) manager_->set_camera(position);
}

Status World::fail(const char* stage, Status s) {
  failed_stage_ = stage;
  std::vector<Error> es = s.errors();
  for (Error& e : es)
    e.detail += std::string(e.detail.empty() ? "" : "; ") + "in the " + stage + " stage at t = " + format_number(time()) + " s";
  return es;
}

// Position, orientation and velocities of every body in the Bullet world finite.
Status World::check_bodies(const char* stage) {
  for (RigidBodyId id : bullet_->bodies()) {
    const BodyState st = bullet_->state(id);
    if (st.position.allFinite() && st.orientation.coeffs().allFinite() && st.linear_velocity.allFinite() &&
        st.angular_velocity.allFinite())
      continue;
    const std::string& name = bullet_->definition(id).name;
    failed_stage_ = stage;
    std::string who = name.empty() ? std::to_string(id.index) + ", " + std::to_string(id.generation) : name;
    who = name.empty() ? std::string(1, '{').append(who).append("}") : std::string(1, '\'').append(who).append("'");
    return Error{"", "body", who,
                 "has a non-finite state after the " + std::string(stage) + " stage at t = " + format_number(time()) + " s"};
  }
  return Ok{};
}

// The spawn stage: bodies scheduled for `t` (s) or before enter the Bullet world.
Status World::spawn_due(double t) {
  if (entries_.empty()) return Ok{};
  auto timer = profile_.time(Stage::Spawn);
  for (auto it = pending_.begin(); it != pending_.end();) {
    Entry& e = entries_[it->first];
    if (e.spawn_time > t + 1e-9) {
      ++it;
      continue;
    }
    auto id = bullet_->add_body(it->second);
    if (!id) return fail("spawn", id.errors());
    e.id = *id;
    enter_kinematic(it->first, it->second);
    it = pending_.erase(it);
  }
  return Ok{};
}

Status World::prepare(double dt) {
  if (!(dt > 0) || !std::isfinite(dt)) return Error{"", "prepare", "dt = " + format_number(dt), "dt must be finite and > 0 (s)"};
  if (prepared_ || steps_ > 0) return Ok{};
  prepared_ = true;
  const auto t0 = Clock::now();
  const double t = time();
  if (Status s = spawn_due(t); !s) return s;
  make_due_joints();
  for (std::size_t k = 0; k < entries_.size(); ++k)
    if (!entries_[k].removed && entries_[k].spawned() && alive(entries_[k].id) &&
        bullet_->motion(entries_[k].id) == RigidMotion::Kinematic)
      place_keyframed(k, t);  // keyframed tools' paths planned as the first frame would
  if (manager_)
    if (Status s = manager_->prepare(t, dt, profile_); !s) return fail("activation", s);
  prepare_ms_ = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  return Ok{};
}

Status World::step(double dt, int substeps) {
  if (!(dt > 0) || !std::isfinite(dt) || substeps < 1)
    return Error{"", "step", "dt = " + format_number(dt) + ", substeps = " + std::to_string(substeps),
                 "dt must be finite and > 0 (s), substeps >= 1"};
  failed_stage_ = "";
  if (dt != dt_) {  // a new step size: the time so far becomes the base
    time_base_ = time();
    dt_ = dt;
    steps_at_dt_ = 0;
  }
  const double t = time();  // s, at the start of this frame
  const auto f0 = Clock::now();
  std::array<double, int(Stage::Count)> stage0{};
  for (int k = 0; k < int(Stage::Count); ++k) stage0[k] = profile_.timer(Stage(k)).total_ms;
  bool conversion = false;

  if (Status s = spawn_due(t); !s) return s;
  make_due_joints();
  drive_motors(t);
  drive_kinematic(t, dt);  // before the lod stage: contact prediction sees the prescribed velocities
  apply_scene_loads(t);  // the body frame's loads turn with the body as it starts the frame
  if (manager_) {
    if (Status s = manager_->before_bodies(t, dt, profile_); !s) return fail("dem", s);
    if (Status s = check_bodies("dem"); !s) return s;
  }
  for (RigidBodyId id : removing_) bullet_->remove_body(id);  // their shells are let go of now
  removing_.clear();
  {
    auto timer = profile_.time(Stage::Bodies);
    // The callers' forces join the patches' (given in the dem stage); both act over every substep.
    for (const Held& h : held_)
      if (alive(h.id)) bullet_->apply_force(h.id, h.force, h.torque);
    held_.clear();
    bullet_->step_frame(float(dt), substeps);
    if (Status s = check_bodies("bodies"); !s) return s;
  }
  if (manager_) {
    keep_original_heights();
    if (Status s = manager_->after_bodies(t, dt, profile_); !s) return fail("demotion", s);
    if (Status s = check_bodies("demotion"); !s) return s;
    for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
    // A body that crosses more than a patch's apron in one frame outruns the patch machinery:
    // no patch can be ready where it lands, and the heightfield takes the contact. Not an
    // error (its speed is allowed); reported once per body with its fastest speed.
    // Also an event (PatchEventKind::TooFastToFollow) each time a body goes over.
    const double follow = follow_apron_ / dt;  // m/s
    std::set<std::pair<int, int>> over;
    for (RigidBodyId id : bullet_->bodies()) {
      const double v = double(bullet_->state(id).linear_velocity.norm());
      if (!(v > follow)) continue;
      const std::string& n = bullet_->definition(id).name;
      const std::string name = n.empty() ? "body " + std::to_string(id.index) : n;
      double& m = too_fast_[name];
      m = std::max(m, v);
      over.insert({id.index, id.generation});
      if (!over_follow_.count({id.index, id.generation}))
        manager_->add_event({PatchEventKind::TooFastToFollow, -1, t, 0, 0, name, v, follow, 0});
    }
    over_follow_.swap(over);
    peak_granules_ = std::max(peak_granules_, manager_->granules());
    // A conversion frame: one in which a part of a promotion or a demotion ran (a slot
    // reset, a fill cut, an upload, a demotion part).
    conversion = manager_->last_frame_work().conversion_parts > 0;
  }
  ++steps_at_dt_;
  ++steps_;
  const bool awake = manager_ && (manager_->active_patches() > manager_->asleep_patches());
  const double budget = manager_ ? manager_->budget_ms(dt) : std::numeric_limits<double>::infinity();
  last_frame_ = {std::chrono::duration<double, std::milli>(Clock::now() - f0).count(), conversion, awake, budget, {}};
  for (int k = 0; k < int(Stage::Count); ++k) last_frame_.stage_ms[k] = profile_.timer(Stage(k)).total_ms - stage0[k];
  if (frame_ms_.size() < kFrameWindow) frame_ms_.push_back(last_frame_.wall_ms);
  else frame_ms_[std::size_t(steps_ - 1) % kFrameWindow] = last_frame_.wall_ms;
  if (awake) {
    if (awake_ms_.size() < kFrameWindow) awake_ms_.push_back(last_frame_.wall_ms);
    else awake_ms_[std::size_t(awake_frames_) % kFrameWindow] = last_frame_.wall_ms;
    ++awake_frames_;
  }
  budget_ms_ = budget;
  if (std::isfinite(budget)) {
    over_budget_ += last_frame_.wall_ms > budget;
    max_over_budget_ = std::max(max_over_budget_, last_frame_.wall_ms / budget);
  }
  if (last_frame_.wall_ms > frame_max_ms_) frame_max_ms_ = last_frame_.wall_ms, frame_max_at_ = t;
  if (worst_.size() < kWorstFrames || last_frame_.wall_ms > worst_.back().total_ms) {
    WorstFrame w;
    w.t = t;
    w.total_ms = last_frame_.wall_ms;
    w.stage_ms = last_frame_.stage_ms;
    if (manager_) w.work = manager_->last_frame_work();
    auto at = std::find_if(worst_.begin(), worst_.end(), [&](const WorstFrame& o) { return o.total_ms < w.total_ms; });
    worst_.insert(at, w);
    if (worst_.size() > kWorstFrames) worst_.pop_back();
  }
  if (conversion) conversion_max_ms_ = std::max(conversion_max_ms_, last_frame_.wall_ms), ++conversion_frames_;
  return Ok{};
}

Status World::demote_all() {
  if (!manager_) return Ok{};
  keep_original_heights();
  if (Status s = manager_->demote_all(time(), profile_); !s) return fail("demotion", s);
  for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
  return Ok{};
}

std::vector<GridRegion> World::take_dirty_regions() {
  if (manager_)
    for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
  std::vector<GridRegion> out;
  out.swap(dirty_);
  return out;
}

// ---- results ----

std::uint64_t World::state_hash() const {
  Hasher h;
  h.pod(time());
  for (RigidBodyId id : bodies()) {
    const BodyState s = bullet_->state(id);
    h.pod(id.index);
    h.pod(s.position);
    h.pod(s.orientation.coeffs());
    h.pod(s.linear_velocity);
    h.pod(s.angular_velocity);
  }
  h.pod(hf_->hash());
  if (manager_) h.pod(manager_->state_hash());
  return h.value();
}

nlohmann::ordered_json World::report() const {
  ojson r;
  r["simulated_s"] = time();
  r["steps"] = steps_;
  r["prepare_ms"] = prepare_ms_;  // start-up before the first frame (prepare), not a frame; its lod and activation time are in `stages`
  r["stages"] = profile_.to_json();

  // Frame times (the step only) and stutter: the longest frame in which a patch was
  // promoted, uploaded or demoted, against the median frame.
  const double med = median(frame_ms_);
  const double mx = frame_max_ms_, conv_max = conversion_max_ms_;
  const long long conv_frames = conversion_frames_;
  r["frames"] = {{"median_ms", med},
                 {"max_ms", mx},
                 {"max_at_s", frame_max_at_},
                 {"max_over_median", med > 0 ? mx / med : 0.0},
                 {"conversion_frames", conv_frames},
                 {"conversion_max_ms", conv_max},
                 {"conversion_max_over_median", med > 0 ? conv_max / med : 0.0}};
  // Frames with a patch simulating, and the frame budget (of the last frame; docs/cli.md).
  const double awake_med = median(awake_ms_);
  r["frames"]["patch_awake_frames"] = awake_frames_;
  r["frames"]["patch_awake_median_ms"] = awake_med;
  r["frames"]["max_over_patch_awake_median"] = awake_med > 0 ? mx / awake_med : 0.0;
  if (std::isfinite(budget_ms_)) r["frames"]["budget_ms"] = budget_ms_;
  else r["frames"]["budget_ms"] = "off";
  r["frames"]["over_budget"] = over_budget_;
  r["frames"]["max_over_budget"] = max_over_budget_;
  // The longest frames: each stage's ms and the work counted in them.
  ojson worst = ojson::array();
  for (const WorstFrame& w : worst_) {
    ojson st = ojson::object();
    for (int k = 0; k < int(Stage::Count); ++k)
      if (Stage(k) != Stage::Outputs) st[kStageNames[k]] = w.stage_ms[k];
    const TerrainManager::FrameWork& k = w.work;
    worst.push_back({{"t", w.t},
                     {"total_ms", w.total_ms},
                     {"stages", st},
                     {"work", {{"conversion_parts", k.conversion_parts},
                               {"urgent_fills", k.urgent_fills},
                               {"promotions", k.promotions},
                               {"granules_filled", k.granules_filled},
                               {"granules_uploaded", k.granules_uploaded},
                               {"ready", k.ready},
                               {"demotion_parts", k.demotion_parts},
                               {"depth_renders", k.depth_renders},
                               {"demotions", k.demotions},
                               {"wakes", k.wakes},
                               {"patches_stepped", k.patches_stepped},
                               {"side_by_side", k.side_by_side},
                               {"substeps", k.substeps},
                               {"sphere_steps", k.sphere_steps}}}});
  }
  r["frames"]["worst"] = worst;

  ojson bodies = ojson::array();
  int live = 0, spawned = 0, resting = 0;
  for (const Entry& e : entries_) {
    if (e.removed) continue;
    ++live;
    ojson b = {{"name", e.name}, {"spawned", e.spawned()}};
    if (e.spawned()) {
      ++spawned;
      const BodyState s = bullet_->state(e.id);
      const bool rest = s.linear_velocity.norm() < 0.05f && s.angular_velocity.norm() < 0.05f;
      resting += rest;
      b["position_m"] = vec_json(s.position);
      b["orientation_wxyz"] = ojson::array({s.orientation.w(), s.orientation.x(), s.orientation.y(), s.orientation.z()});
      b["linear_velocity_m_s"] = vec_json(s.linear_velocity);
      b["angular_velocity_rad_s"] = vec_json(s.angular_velocity);
      b["at_rest"] = rest;
      const Contact c = contact(e.id);
      b["motion"] = to_string(bullet_->motion(e.id));
      b["carried_by_patch"] = c.granular.carried;
      b["granular_force_N"] = vec_json(c.granular.force);
      b["granular_torque_N_m"] = vec_json(c.granular.torque);
      b["heightfield_force_N"] = vec_json(c.heightfield_force);
      b["sinkage_m"] = c.sinkage;
    }
    bodies.push_back(b);
  }
  const Heightfield& hf = *hf_;
  r["counts"] = {{"bodies", live},
                 {"bodies_spawned", spawned},
                 {"bodies_at_rest", resting},
                 {"terrain_samples", std::int64_t(hf.samples_x()) * hf.samples_z()},
                 {"terrain_tiles", bullet_->terrain_tile_count()},
                 {"peak_granules", peak_granules_}};
  if (manager_) {
    r["patches_live"] = manager_->active_patches();
    r["granules_live"] = manager_->granules();
    const ojson m = manager_->report();  // named: iterating a temporary's items() dangles
    for (const auto& [key, value] : m.items()) r[key] = value;
    // The frame's dem stage against the DEM's step calls in it: the rest is the coupling
    // (carriers, shells, forces to and from Bullet).
    if (r.contains("dem")) {
      ojson& t = r["dem"]["total"];
      const double stage_ms = profile_.timer(Stage::Dem).total_ms, step_ms = t["wall_ms"].get<double>();
      t["frame_stage_ms"] = stage_ms;
      t["step_share_of_frame_stage"] = stage_ms > 0 ? step_ms / stage_ms : 0.0;
    }
  }
  r["terrain"] = {{"samples_x", hf.samples_x()},
                  {"samples_z", hf.samples_z()},
                  {"spacing_m", hf.spacing()},
                  {"origin_m", ojson::array({hf.origin_x(), hf.origin_y(), hf.origin_z()})},
                  {"min_height_m", hf.origin_y() + hf.min_height()},
                  {"max_height_m", hf.origin_y() + hf.max_height()},
                  {"hash", Hasher::to_hex(hf.hash())}};
  r["bodies"] = bodies;
  if (!joints_.empty()) {
    ojson js = ojson::array();
    for (const JointEntry& j : joints_) {
      ojson o = {{"name", j.name}, {"type", to_string(j.def.kind)}, {"made", j.id.valid() && !j.removed}};
      if (j.id.valid() && !j.removed && joint_alive(j.id)) {
        const JointState st = bullet_->joint_state(j.id);
        const JointKind k = j.def.kind;
        if (k == JointKind::Wheel) o["steering_rad"] = bullet_->joint_steering(j.id);
        if (k == JointKind::Hinge || k == JointKind::Cylindrical || k == JointKind::Wheel) {
          o["angle_rad"] = st.angle;
          o["angular_rate_rad_s"] = st.angular_rate;
          o["torque_N_m"] = st.torque;
        }
        if (k == JointKind::Slider || k == JointKind::Cylindrical || k == JointKind::Wheel) {
          o["position_m"] = st.position;
          o["rate_m_s"] = st.rate;
          o["force_N"] = st.force;
        }
      }
      js.push_back(o);
    }
    r["joints"] = js;
  }
  {
    std::vector<std::string> w;
    for (const auto& [name, v] : too_fast_)
      w.push_back("bodies." + name + ": reached " + format_number(v) + " m/s, faster than the patches can follow (" +
                  "simulation.lod.apron / dt = " + format_number(follow_apron_ / (dt_ > 0 ? dt_ : 1.0)) +
                  " m/s): where it met the ground the heightfield, not granules, took the contact");
    if (r.contains("soil_dropped"))
      for (const auto& d : r["soil_dropped"])
        w.push_back("bodies." + d["body"].get<std::string>() + ": let go of " + std::to_string(d["granules"].get<int>()) +
                    " granules (" + format_number(d["volume_m3"].get<double>()) + " m³ at the bed's packing) at " +
                    format_number(d["time_s"].get<double>()) + " s, " + format_number(d["height_m"].get<double>()) +
                    " m above its patch's highest surface point: a patch carries a tool's soil up to " +
                    format_number(d["limit_m"].get<double>()) + " m above it and within its sides; the soil fell");
    // The frame budget: patches that did not fit it even at their cheapest rung, with the
    // budget that would have fitted the worst of them (their DEM share is 80 % of the budget,
    // less what Bullet and planning took; docs/manager.md "Frame budget").
    if (r.contains("budget") && r["budget"].value("on", false) && r["budget"].contains("patches")) {
      int over = 0, n = 0;
      double need = 0, worst_pred = 0, worst_avail = 0;
      for (const auto& p : r["budget"]["patches"]) {
        ++n;
        if (p.value("fits", true)) continue;
        ++over;
        const double pred = p.value("predicted_ms", 0.0), avail = p.value("available_ms", 0.0);
        if (pred - avail > need) need = pred - avail, worst_pred = pred, worst_avail = avail;
      }
      const double budget = r.contains("frames") && r["frames"]["budget_ms"].is_number() ? r["frames"]["budget_ms"].get<double>() : 0.0;
      auto ms = [](double v) {
        char b[32];
        std::snprintf(b, sizeof b, "%.2f", v);
        return std::string(b);
      };
      if (over > 0 && budget > 0)
        w.push_back("simulation.frame_budget_ms: " + std::to_string(over) + " of " + std::to_string(n) +
                    " patches did not fit the frame budget of " + ms(budget) +
                    " ms even at their cheapest particle scale, extent and substeps (the worst needed " + ms(worst_pred) +
                    " ms of DEM a frame against " + ms(worst_avail) +
                    " ms left to the DEM); they ran over it. A budget of about " + ms(budget + need / 0.8) +
                    " ms fits them on this machine");
    }
    r["warnings"] = w;
  }
  r["final_state_hash"] = Hasher::to_hex(state_hash());
  return r;
}

}  // namespace sandpatch
