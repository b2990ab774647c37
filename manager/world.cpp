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

Status World::check_dynamic(RigidBodyId id) const {
  const RigidMotion m = bullet_->motion(id);
  if (m == RigidMotion::Dynamic) return Ok{};
  const std::string& name = bullet_->definition(id).name;
  return Error{"", "body", "'" + name + "' (" + to_string(m) + ")",
               "must be a dynamic body: loads and impulses do not move a kinematic or static body",
               m == RigidMotion::Kinematic ? "drive it with set_kinematic_target, set_kinematic_velocity or keyframes" : ""};
}

Status World::check_kinematic(RigidBodyId id, const char* field) const {
  if (Status s = check_body(id); !s) return s;
  const RigidMotion m = bullet_->motion(id);
  if (m == RigidMotion::Kinematic) return Ok{};
  return Error{"", field, "'" + bullet_->definition(id).name + "' (" + to_string(m) + ")", "must be a kinematic body"};
}

std::size_t World::entry_of(RigidBodyId id) const {
  for (std::size_t k = 0; k < entries_.size(); ++k)
    if (!entries_[k].removed && same(entries_[k].id, id)) return k;
  return entries_.size();
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
  if (Status s = check_dynamic(id); !s) return s;
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
  if (Status s = check_dynamic(id); !s) return s;
  if (auto e = check_load("torque", torque, "N m")) return *e;
  accumulate(id, Eigen::Vector3f::Zero(), torque);
  return Ok{};
}

Status World::apply_impulse(RigidBodyId id, const Eigen::Vector3f& impulse, const Eigen::Vector3d* world_point) {
  if (Status s = check_body(id); !s) return s;
  if (Status s = check_dynamic(id); !s) return s;
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

// ---- joints ----

Result<JointId> World::add_joint(const RigidJointDef& def) {
  for (RigidBodyId id : {def.a, def.b})
    if (id.valid() && bullet_->alive(id) && !alive(id))
      return Error{"", same(id, def.a) ? "body_a" : "body_b", "'" + bullet_->definition(id).name + "'",
                   "must be a live body (it was removed)"};
  auto id = bullet_->add_joint(def);
  if (!id) return id;
  JointEntry e;
  e.name = def.name;
  e.id = *id;
  e.def = def;
  joints_.push_back(std::move(e));
  return id;
}

std::size_t World::schedule_joint(const RigidJointDef& def, std::size_t a_entry, std::size_t b_entry) {
  JointEntry e;
  e.name = def.name;
  e.a = a_entry;
  e.b = b_entry;
  e.def = def;
  joints_.push_back(std::move(e));
  return joints_.size() - 1;
}

void World::set_motor_phases(std::size_t joint_entry, std::vector<MotorPhase> phases, const JointMotor& steer_default) {
  if (joint_entry >= joints_.size()) return;
  joints_[joint_entry].phases = std::move(phases);
  joints_[joint_entry].steer_default = steer_default;
  joints_[joint_entry].applied[0] = joints_[joint_entry].applied[1] = joints_[joint_entry].applied[2] = -2;
}

bool World::joint_alive(JointId id) const {
  if (!bullet_->joint_alive(id)) return false;
  const RigidJointDef& d = bullet_->joint_definition(id);
  return alive(d.a) && (!d.b.valid() || alive(d.b));
}

void World::remove_joint(JointId id) {
  if (!bullet_->joint_alive(id)) return;
  for (JointEntry& j : joints_)
    if (!j.removed && j.id.index == id.index && j.id.generation == id.generation) j.removed = true;
  bullet_->remove_joint(id);
}

Status World::set_joint_motor(JointId id, bool turn, const JointMotor& motor) {
  if (!joint_alive(id))
    return Error{"", "joint", "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}",
                 "must be a live joint of this world (removed, or one of its bodies removed)"};
  const JointKind k = bullet_->joint_definition(id).kind;
  const bool has = turn ? (k == JointKind::Hinge || k == JointKind::Cylindrical)
                        : (k == JointKind::Slider || k == JointKind::Cylindrical);
  if (!has)
    return Error{"", "joint", std::string("a ") + to_string(k) + " joint",
                 k == JointKind::Fixed ? "a fixed joint has no motor" : std::string("has no ") + (turn ? "turning" : "sliding") + " motor"};
  if (auto es = BulletWorld::check_motor(motor, turn, "motor"); !es.empty()) return es;
  bullet_->set_joint_motor(id, turn, motor);
  return Ok{};
}

// Scheduled joints whose bodies have both spawned are made now (in entry order).
void World::make_due_joints() {
  for (JointEntry& j : joints_) {
    if (j.id.valid() || j.removed) continue;
    const Entry& a = entries_[j.a];
    if (!a.spawned() || (j.b != kWorld && !entries_[j.b].spawned())) continue;
    RigidJointDef d = j.def;
    d.a = a.id;
    d.b = j.b == kWorld ? RigidBodyId{} : entries_[j.b].id;
    auto id = bullet_->add_joint(d);
    if (!id) {  // checked before the run (make_world); a body removed since: the joint goes too
      j.removed = true;
      continue;
    }
    j.id = *id;
    j.def = d;
    if (d.kind == JointKind::Wheel && j.steer_default.servo_speed > 0)
      bullet_->set_joint_steering(j.id, j.steer_default.target, j.steer_default.servo_speed);
  }
}

// The motor phases due in the frame starting at t (with the spawn stage's 1 ns tolerance).
void World::drive_motors(double t) {
  for (JointEntry& j : joints_) {
    if (j.phases.empty() || !j.id.valid() || j.removed || !joint_alive(j.id)) continue;
    for (int dof = 0; dof < 3; ++dof) {
      const bool turn = dof == 0, steer = dof == 2;
      auto mine = [&](const MotorPhase& p) { return p.steer == steer && (steer || p.turn == turn); };
      int now = -1;
      for (std::size_t k = 0; k < j.phases.size() && now < 0; ++k)
        if (mine(j.phases[k]) && t + 1e-9 >= j.phases[k].from && t + 1e-9 < j.phases[k].until) now = int(k);
      const bool any = std::any_of(j.phases.begin(), j.phases.end(), mine);
      if (!any || now == j.applied[dof]) continue;
      j.applied[dof] = now;
      if (steer) {  // outside every phase: straight ahead
        const JointMotor m = now >= 0 ? j.phases[std::size_t(now)].motor : j.steer_default;
        bullet_->set_joint_steering(j.id, m.target, m.servo_speed);
      } else {
        bullet_->set_joint_motor(j.id, turn, now >= 0 ? j.phases[std::size_t(now)].motor : (turn ? j.def.turn : j.def.slide).motor);
      }
    }
  }
}

// ---- kinematic bodies ----

World::Keyframe World::keyframe_at(const std::vector<Keyframe>& keys, double t) {
  if (t <= keys.front().t) return keys.front();
  for (std::size_t k = 1; k < keys.size(); ++k) {
    const Keyframe& a = keys[k - 1];
    const Keyframe& b = keys[k];
    if (t >= b.t) continue;
    const double u = (t - a.t) / (b.t - a.t);
    Keyframe out;
    out.t = t;
    out.position = a.position + u * (b.position - a.position);
    out.orientation = a.orientation.slerp(u, b.orientation);
    return out;
  }
  return keys.back();
}

std::vector<Error> World::check_keyframes(const std::vector<Keyframe>& keys, const std::string& field) {
  std::vector<Error> es;
  if (keys.empty()) es.push_back({"", field, "[]", "must hold at least one keyframe"});
  for (std::size_t k = 0; k < keys.size(); ++k) {
    const Keyframe& f = keys[k];
    const std::string at = field + "[" + std::to_string(k) + "]";
    if (!std::isfinite(f.t) || f.t < 0)
      es.push_back({"", at + ".t", format_number(f.t), "must be finite and >= 0 (s)"});
    else if (k > 0 && std::isfinite(keys[k - 1].t) && !(f.t > keys[k - 1].t))
      es.push_back({"", at + ".t", format_number(f.t),
                    "must be greater than the keyframe before it (" + format_number(keys[k - 1].t) + " s): times strictly increasing"});
    if (!f.position.allFinite() || f.position.cwiseAbs().maxCoeff() > 1e7)
      es.push_back({"", at + ".position", vec_str(f.position), "must be finite, each coordinate within 1e7 (m, world)"});
    const double n = f.orientation.coeffs().norm();
    if (!f.orientation.coeffs().allFinite() || !(n > 1e-6))
      es.push_back({"", at + ".orientation",
                    "[" + format_number(f.orientation.w()) + ", " + format_number(f.orientation.x()) + ", " +
                        format_number(f.orientation.y()) + ", " + format_number(f.orientation.z()) + "]",
                    "must be a finite quaternion [w, x, y, z] with a norm > 0"});
  }
  return es;
}

Status World::set_keyframes(std::size_t entry, std::vector<Keyframe> keys) {
  if (entry >= entries_.size()) return Error{"", "entry", std::to_string(entry), "must be a body of this world"};
  if (auto es = check_keyframes(keys, "keyframes"); !es.empty()) return es;
  for (Keyframe& k : keys) k.orientation.normalize();
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  kinematic_[entry].keys = std::move(keys);
  kinematic_[entry].placed = false;
  return Ok{};
}

Status World::set_kinematic_target(RigidBodyId id, const Eigen::Vector3d& position, const Eigen::Quaternionf& orientation) {
  if (Status s = check_kinematic(id, "body"); !s) return s;
  std::vector<Error> es;
  if (!position.allFinite() || position.cwiseAbs().maxCoeff() > 1e7)
    es.push_back({"", "position", vec_str(position), "must be finite, each coordinate within 1e7 (m, world)"});
  if (!orientation.coeffs().allFinite() || !(orientation.coeffs().norm() > 1e-6))
    es.push_back({"", "orientation",
                  "[" + format_number(orientation.w()) + ", " + format_number(orientation.x()) + ", " +
                      format_number(orientation.y()) + ", " + format_number(orientation.z()) + "]",
                  "must be a finite quaternion [w, x, y, z] with a norm > 0"});
  if (!es.empty()) return es;
  const std::size_t e = entry_of(id);
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  Kinematic& k = kinematic_[e];
  k.has_target = true;
  k.target = position;
  k.target_q = orientation.normalized();
  return Ok{};
}

Status World::set_kinematic_velocity(RigidBodyId id, const Eigen::Vector3f& linear, const Eigen::Vector3f& angular) {
  if (Status s = check_kinematic(id, "body"); !s) return s;
  std::vector<Error> es;
  if (!linear.allFinite() || linear.norm() > 1000.0f)
    es.push_back({"", "linear", vec_str(linear), "must be finite with |v| <= 1000 (m/s)"});
  if (!angular.allFinite() || angular.norm() > 1e4f)
    es.push_back({"", "angular", vec_str(angular), "must be finite with |w| <= 1e4 (rad/s)"});
  if (!es.empty()) return es;
  const std::size_t e = entry_of(id);
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  kinematic_[e].v = linear;
  kinematic_[e].w = angular;
  return Ok{};
}

// Every kinematic body's pose at the end of the frame [t, t + dt] handed to Bullet (which
// moves it there over the frame's substeps): its keyframes', its target, or its velocity's.
void World::drive_kinematic(double t, double dt) {
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  for (std::size_t k = 0; k < entries_.size(); ++k) {
    const Entry& e = entries_[k];
    if (e.removed || !e.spawned() || !alive(e.id) || bullet_->motion(e.id) != RigidMotion::Kinematic) continue;
    Kinematic& kin = kinematic_[k];
    BodyState st = bullet_->state(e.id);
    Eigen::Vector3d p;
    Eigen::Quaternionf q;
    if (!kin.keys.empty()) {
      if (!kin.placed) {  // where its keyframes have it when it enters
        const Keyframe now = keyframe_at(kin.keys, t);
        st.position = now.position;
        st.orientation = now.orientation.cast<float>();
        st.linear_velocity.setZero();
        st.angular_velocity.setZero();
        bullet_->set_state(e.id, st);
        kin.placed = true;
        if (manager_) manager_->set_planned_path(e.id, planned_path(bullet_->definition(e.id).shape, kin.keys, t));
      }
      const Keyframe end = keyframe_at(kin.keys, t + dt);
      p = end.position;
      q = end.orientation.cast<float>();
    } else if (kin.has_target) {
      p = kin.target;
      q = kin.target_q;
      kin.has_target = false;
    } else {
      p = st.position + dt * kin.v.cast<double>();
      q = st.orientation;
      const float angle = kin.w.norm() * float(dt);
      if (angle > 0) q = Eigen::Quaternionf(Eigen::AngleAxisf(angle, kin.w.normalized())) * q;
      q.normalize();
    }
    bullet_->set_kinematic_target(e.id, p, q, float(dt));
  }
}

// A keyframed body's bounds along its keyframes from t to the last one (the path the manager
// plans its patch over, docs/manager.md "Tools on a planned path"): every keyframe and samples
// at most 1/30 s apart between them (at most 20,000 samples: a path longer than 667 s is
// sampled more coarsely), each the world bounds of the shape at its pose (its support
// function along ±x, ±y, ±z).
std::vector<TerrainManager::PathPose> World::planned_path(const RigidShape& shape, const std::vector<Keyframe>& keys, double t) {
  std::vector<TerrainManager::PathPose> path;
  const double end = std::max(t, keys.back().t);
  const double h = std::max(1.0 / 30.0, (end - t) / 20000.0);  // s
  std::vector<double> times;
  for (double u = t; u < end; u += h) times.push_back(u);
  for (const Keyframe& k : keys)
    if (k.t > t) times.push_back(k.t);
  times.push_back(end);
  std::sort(times.begin(), times.end());
  times.erase(std::unique(times.begin(), times.end()), times.end());
  path.reserve(times.size());
  for (double u : times) {
    const Keyframe k = keyframe_at(keys, u);
    const Eigen::Quaternionf q = k.orientation.cast<float>();
    TerrainManager::PathPose p;
    p.t = u;
    for (int a = 0; a < 3; ++a) {
      Eigen::Vector3d e = Eigen::Vector3d::Zero();
      e[a] = 1;
      p.hi[a] = k.position[a] + extent_along(shape, q, e);
      p.lo[a] = k.position[a] - extent_along(shape, q, -e);
    }
    path.push_back(p);
  }
  return path;
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
      enter_kinematic(it->first, it->second);
      it = pending_.erase(it);
    }
  }
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
    r["warnings"] = w;
  }
  r["final_state_hash"] = Hasher::to_hex(state_hash());
  return r;
}

}  // namespace sandpatch
