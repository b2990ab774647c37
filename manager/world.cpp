#include "manager/world.hpp"

#include <algorithm>
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
  return Ok{};
}

// ---- bodies ----

Result<RigidBodyId> World::add_body(const RigidBodyDef& def) {
  auto id = bullet_->add_body(def);
  if (id) entries_.push_back({def.name, time(), *id, false});
  return id;
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

// ---- driving bodies ----

namespace {

std::string vec_str(const Eigen::Vector3f& v) {
  return "[" + format_number(v.x()) + ", " + format_number(v.y()) + ", " + format_number(v.z()) + "]";
}
std::string vec_str(const Eigen::Vector3d& v) {
  return "[" + format_number(v.x()) + ", " + format_number(v.y()) + ", " + format_number(v.z()) + "]";
}

// A load vector: finite, |v| <= World::kMaxLoad.
std::optional<Error> check_load(const char* field, const Eigen::Vector3f& v, const char* unit) {
  if (!v.allFinite()) return Error{"", field, vec_str(v), std::string("must be finite (") + unit + ")"};
  if (double(v.cast<double>().norm()) > World::kMaxLoad)
    return Error{"", field, vec_str(v),
                 "its magnitude must be at most " + format_number(World::kMaxLoad) + " " + unit,
                 "|" + std::string(field) + "| = " + format_number(v.cast<double>().norm())};
  return std::nullopt;
}

}  // namespace

Status World::check_body(RigidBodyId id) const {
  if (alive(id)) return Ok{};
  return Error{"", "body", "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}",
               "must be a live body of this world (removed, or never added)"};
}

void World::accumulate(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3f& torque) {
  for (Held& h : held_)
    if (same(h.id, id)) {
      h.force += force;
      h.torque += torque;
      return;
    }
  held_.push_back({id, force, torque});
}

Status World::apply_force(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3d* world_point) {
  if (Status s = check_body(id); !s) return s;
  std::vector<Error> errs;
  if (auto e = check_load("force", force, "N")) errs.push_back(*e);
  Eigen::Vector3f torque = Eigen::Vector3f::Zero();
  if (world_point) {
    const Eigen::Vector3d arm = *world_point - bullet_->state(id).position;  // m
    if (!world_point->allFinite())
      errs.push_back({"", "world_point", vec_str(*world_point), "must be finite (m, world)"});
    else if (arm.norm() > kMaxArm)
      errs.push_back({"", "world_point", vec_str(*world_point),
                      "must be within " + format_number(kMaxArm) + " m of the body's centre of mass",
                      "it is " + format_number(arm.norm()) + " m away"});
    else
      torque = arm.cast<float>().cross(force);  // N m, about the centre of mass
  }
  if (!errs.empty()) return errs;
  accumulate(id, force, torque);
  return Ok{};
}

Status World::apply_torque(RigidBodyId id, const Eigen::Vector3f& torque) {
  if (Status s = check_body(id); !s) return s;
  if (auto e = check_load("torque", torque, "N m")) return *e;
  accumulate(id, Eigen::Vector3f::Zero(), torque);
  return Ok{};
}

Status World::apply_impulse(RigidBodyId id, const Eigen::Vector3f& impulse, const Eigen::Vector3d* world_point) {
  if (Status s = check_body(id); !s) return s;
  std::vector<Error> errs;
  if (auto e = check_load("impulse", impulse, "N s")) errs.push_back(*e);
  BodyState st = bullet_->state(id);
  Eigen::Vector3d arm = Eigen::Vector3d::Zero();  // m
  if (world_point) {
    if (!world_point->allFinite())
      errs.push_back({"", "world_point", vec_str(*world_point), "must be finite (m, world)"});
    else if ((arm = *world_point - st.position).norm() > kMaxArm)
      errs.push_back({"", "world_point", vec_str(*world_point),
                      "must be within " + format_number(kMaxArm) + " m of the body's centre of mass",
                      "it is " + format_number(arm.norm()) + " m away"});
  }
  if (!errs.empty()) return errs;
  const float m = bullet_->mass(id);  // kg
  if (m > 0) st.linear_velocity += impulse / m;
  if (world_point) {
    // Δω = I⁻¹ (r × J), I⁻¹ = R diag(1 / I_i) Rᵀ (principal moments in the body frame).
    const Eigen::Vector3f I = bullet_->principal_inertia(id);
    const Eigen::Vector3f inv(I.x() > 0 ? 1 / I.x() : 0, I.y() > 0 ? 1 / I.y() : 0, I.z() > 0 ? 1 / I.z() : 0);
    const Eigen::Matrix3f R = st.orientation.toRotationMatrix();
    st.angular_velocity += R * inv.asDiagonal() * R.transpose() * arm.cast<float>().cross(impulse);
  }
  bullet_->set_state(id, st);
  return Ok{};
}

void World::set_loads(std::size_t entry, std::vector<Load> loads) {
  if (entry >= entries_.size()) return;
  if (loads_.size() < entries_.size()) loads_.resize(entries_.size());
  loads_[entry] = std::move(loads);
}

// The scene loads active in the frame starting at t (s): from <= t < until, with the spawn
// stage's 1 ns tolerance on t.
void World::apply_scene_loads(double t) {
  for (std::size_t k = 0; k < loads_.size(); ++k) {
    if (loads_[k].empty() || !entries_[k].spawned() || !alive(entries_[k].id)) continue;
    const RigidBodyId id = entries_[k].id;
    const BodyState st = bullet_->state(id);
    const Eigen::Matrix3f R = st.orientation.toRotationMatrix();
    for (const Load& l : loads_[k]) {
      if (!(t + 1e-9 >= l.from && t + 1e-9 < l.until)) continue;
      const Eigen::Vector3f f = l.body_frame ? Eigen::Vector3f(R * l.force) : l.force;
      Eigen::Vector3f tq = l.body_frame ? Eigen::Vector3f(R * l.torque) : l.torque;
      if (!l.at_centre) tq += (R * l.at).cross(f);  // N m: `at` is a point of the body, wherever it has turned
      accumulate(id, f, tq);
    }
  }
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
  const std::size_t events_before = manager_ ? manager_->events().size() : 0;
  bool conversion = filling_ > 0;

  if (!entries_.empty()) {
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
      it = pending_.erase(it);
    }
  }
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
    if (Status s = manager_->after_bodies(t, dt, profile_); !s) return fail("demotion", s);
    if (Status s = check_bodies("demotion"); !s) return s;
    for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
    // A body that crosses more than a patch's apron in one frame outruns the patch machinery:
    // no patch can be ready where it lands, and the heightfield takes the contact. Not an
    // error (its speed is allowed); reported once per body with its fastest speed.
    const double follow = follow_apron_ / dt;  // m/s
    for (RigidBodyId id : bullet_->bodies()) {
      const double v = double(bullet_->state(id).linear_velocity.norm());
      if (!(v > follow)) continue;
      const std::string& n = bullet_->definition(id).name;
      double& m = too_fast_[n.empty() ? "body " + std::to_string(id.index) : n];
      m = std::max(m, v);
    }
    peak_granules_ = std::max(peak_granules_, manager_->granules());
    const auto& ev = manager_->events();
    for (std::size_t k = events_before; k < ev.size(); ++k) {
      const PatchEventKind kind = ev[k].kind;
      filling_ += kind == PatchEventKind::Promoted;
      filling_ -= kind == PatchEventKind::Ready;
      conversion = conversion || kind == PatchEventKind::Promoted || kind == PatchEventKind::Ready ||
                   kind == PatchEventKind::Demoted;
    }
  }
  ++steps_at_dt_;
  ++steps_;
  const bool awake = manager_ && (manager_->active_patches() > manager_->asleep_patches());
  const double budget = manager_ ? manager_->budget_ms(dt) : std::numeric_limits<double>::infinity();
  last_frame_ = {std::chrono::duration<double, std::milli>(Clock::now() - f0).count(), conversion, awake, budget};
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
  if (conversion) conversion_max_ms_ = std::max(conversion_max_ms_, last_frame_.wall_ms), ++conversion_frames_;
  return Ok{};
}

Status World::demote_all() {
  if (!manager_) return Ok{};
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
      const SoilForce soil = soil_force(e.id);
      b["carried_by_patch"] = soil.carried;
      b["granular_force_N"] = vec_json(soil.force);
      b["granular_torque_N_m"] = vec_json(soil.torque);
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
  {
    std::vector<std::string> w;
    for (const auto& [name, v] : too_fast_)
      w.push_back("bodies." + name + ": reached " + format_number(v) + " m/s, faster than the patches can follow (" +
                  "simulation.lod.apron / dt = " + format_number(follow_apron_ / (dt_ > 0 ? dt_ : 1.0)) +
                  " m/s): where it met the ground the heightfield, not granules, took the contact");
    r["warnings"] = w;
  }
  r["final_state_hash"] = Hasher::to_hex(state_hash());
  return r;
}

}  // namespace sandpatch
