// World's bodies driven by the game or the scene: forces, torques and impulses, the scene's
// load schedules, joints and their motor phases, kinematic bodies (targets, velocities,
// keyframes) and the planned paths of tools (keyframed, or extrapolated from the game's motion). The frame itself is in world.cpp.
#include <algorithm>
#include <cmath>
#include <optional>

#include "manager/world.hpp"

namespace sandpatch {
namespace {

bool same(RigidBodyId a, RigidBodyId b) { return a.index == b.index && a.generation == b.generation; }

}  // namespace

// ---- driving bodies ----

namespace {

std::string vec_str(const Eigen::Vector3d& v) {
  std::string s = "[";
  s += format_number(v.x());
  s += ", ";
  s += format_number(v.y());
  s += ", ";
  s += format_number(v.z());
  s += "]";
  return s;
}
std::string vec_str(const Eigen::Vector3f& v) { return vec_str(Eigen::Vector3d(v.cast<double>())); }

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
    for (Load& l : loads_[k]) {
      if (l.is_impulse) {
        if (l.given || !(t + 1e-9 >= l.from)) continue;
        l.given = true;
        const Eigen::Vector3f j = l.body_frame ? Eigen::Vector3f(R * l.impulse) : l.impulse;
        const Eigen::Vector3d p = st.position + (R * l.at).cast<double>();  // m, world
        // (the scene parser refused what apply_impulse would: J finite and at most kMaxLoad,
        // |at| at most kMaxArm; the body is dynamic and alive)
        (void)apply_impulse(id, j, l.at_centre ? nullptr : &p);
        continue;
      }
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
// A keyframed body where its keyframes have it when it enters (at rest), and its path handed
// to the manager (drive_kinematic in its first frame, or prepare before the first frame).
void World::place_keyframed(std::size_t k, double t) {
  if (kinematic_.size() < entries_.size()) kinematic_.resize(entries_.size());
  const Entry& e = entries_[k];
  Kinematic& kin = kinematic_[k];
  if (kin.placed || kin.keys.empty() || !e.spawned() || !alive(e.id)) return;
  BodyState st = bullet_->state(e.id);
  const Keyframe now = keyframe_at(kin.keys, t);
  st.position = now.position;
  st.orientation = now.orientation.cast<float>();
  st.linear_velocity.setZero();
  st.angular_velocity.setZero();
  bullet_->set_state(e.id, st);
  kin.placed = true;
  if (manager_) manager_->set_planned_path(e.id, planned_path(bullet_->definition(e.id).shape, kin.keys, t));
}

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
      if (!kin.placed) {
        place_keyframed(k, t);
        st = bullet_->state(e.id);
      }
      const Keyframe end = keyframe_at(kin.keys, t + dt);
      p = end.position;
      q = end.orientation.cast<float>();
    } else {
      if (kin.has_target) {
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
      if (manager_) look_ahead(k, st, p, q, t, dt);
    }
    bullet_->set_kinematic_target(e.id, p, q, float(dt));
  }
}

// A kinematic body the game drives (a target pose or a velocity each frame, no keyframes):
// what it does this frame, from its pose `st` at t to (p, q) at t + dt, is taken to go on for
// twice the manager's lod.horizon (at least one frame), and that extrapolated motion is handed
// to the manager as its planned path, sampled like a keyframed one's (planned_path), so the lod
// stage plans its patch by the same code (planning.cpp plan_path: docs/manager.md "Tools on
// a planned path"). The velocity the game set, or the motion to the target it set (the
// step from the last pose it set to the next), is the best guess the game gives of where the
// tool goes. A body holding still has no path: it is planned for like any other body.
void World::look_ahead(std::size_t entry, const BodyState& st, const Eigen::Vector3d& p, const Eigen::Quaternionf& q, double t,
                       double dt) {
  Kinematic& kin = kinematic_[entry];
  const RigidBodyId id = entries_[entry].id;
  const Eigen::Vector3d v = (p - st.position) / dt;  // m/s
  Eigen::Quaterniond turn = (q.cast<double>() * st.orientation.cast<double>().conjugate()).normalized();  // over dt
  if (turn.w() < 0) turn.coeffs() = -turn.coeffs();  // the shorter way round
  const Eigen::AngleAxisd aa(turn);
  const double rate = aa.angle() / dt;  // rad/s
  if (!(v.squaredNorm() > 0) && !(rate > 0)) {
    if (kin.looked_ahead) manager_->set_planned_path(id, {});
    kin.looked_ahead = false;
    return;
  }
  // Contacts are looked for within lod.horizon (plan_path); the second horizon is the stretch
  // after the contact the request covers (a tool grazing the ground at 15 m/s first comes
  // within lod.margin of it 1.5 m before it cuts in: with the path cut at one horizon, the
  // patch asked for ended short of where it cut in). Keyframes every frame (at most 600 of
  // them: a longer horizon is sampled more coarsely) along the straight line and the
  // constant rotation.
  const double horizon = std::max(2.0 * look_ahead_s_, dt);  // s
  const int n = int(std::clamp(std::ceil(horizon / dt - 1e-9), 1.0, 600.0));
  const Eigen::Quaterniond q0 = st.orientation.cast<double>().normalized();
  std::vector<Keyframe> keys(std::size_t(n) + 1);
  for (int k = 0; k <= n; ++k) {
    const double u = horizon * k / n;  // s from now
    Keyframe& f = keys[std::size_t(k)];
    f.t = t + u;
    f.position = st.position + u * v;
    f.orientation = rate > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(rate * u, aa.axis())) * q0 : q0;
    f.orientation.normalize();
  }
  manager_->set_planned_path(id, planned_path(bullet_->definition(id).shape, keys, t), /*extrapolated=*/true);
  kin.looked_ahead = true;
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

}  // namespace sandpatch
