// BulletWorld's joints (bullet_world.hpp "joints"): Bullet's btGeneric6DofSpring2Constraint
// for every kind, its motors, springs and limits, and what they did in the last step.
#include "manager/bullet_world_impl.hpp"

namespace sandpatch {

// ---- joints ----

const char* to_string(JointKind k) {
  switch (k) {
    case JointKind::Fixed: return "fixed";
    case JointKind::Hinge: return "hinge";
    case JointKind::Slider: return "slider";
    case JointKind::Cylindrical: return "cylindrical";
    case JointKind::Wheel: return "wheel";
  }
  return "?";
}

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kMaxJointForce = 1e9;   // N or N m: the largest motor force (as the loads' limit)
constexpr double kMaxSpring = 1e12;      // N/m or N m/rad, N s/m or N m s/rad
constexpr double kMaxJointSpeed = 1e4;   // rad/s or m/s: targets of velocity motors, servo speeds

std::string num(double v) { return format_number(v); }

bool turns(JointKind k) { return k == JointKind::Hinge || k == JointKind::Cylindrical || k == JointKind::Wheel; }
bool slides(JointKind k) { return k == JointKind::Slider || k == JointKind::Cylindrical || k == JointKind::Wheel; }

// A frame whose x is `axis` (unit), y and z any perpendicular pair.
btMatrix3x3 basis_along(const btVector3& axis) {
  btVector3 y, z;
  btPlaneSpace1(axis, y, z);
  return btMatrix3x3(axis.x(), y.x(), z.x(), axis.y(), y.y(), z.y(), axis.z(), y.z(), z.z());
}

}  // namespace

std::vector<Error> BulletWorld::check_motor(const JointMotor& m, bool turn, const std::string& field) {
  std::vector<Error> es;
  const char* unit = turn ? "rad" : "m";
  if (m.mode != MotorMode::Off && m.mode != MotorMode::Velocity && m.mode != MotorMode::Position)
    es.push_back({"", field + ".mode", std::to_string(int(m.mode)), "must be off, velocity or position"});
  if (m.mode == MotorMode::Velocity && (!std::isfinite(m.target) || std::abs(m.target) > kMaxJointSpeed))
    es.push_back({"", field + ".target", num(m.target),
                  "must be finite, |target| <= " + num(kMaxJointSpeed) + (turn ? " (rad/s)" : " (m/s)")});
  if (m.mode == MotorMode::Position) {
    const double lim = turn ? kPi : 1e4;
    if (!std::isfinite(m.target) || std::abs(m.target) > lim)
      es.push_back({"", field + ".target", num(m.target),
                    std::string("must be finite and in [-") + num(lim) + ", " + num(lim) + "] " + unit +
                        (turn ? " (a hinge's angle is measured in [-pi, pi])" : "")});
    if (!std::isfinite(m.servo_speed) || !(m.servo_speed > 0) || m.servo_speed > kMaxJointSpeed)
      es.push_back({"", field + ".servo_speed", num(m.servo_speed),
                    "must be in (0, " + num(kMaxJointSpeed) + "]" + (turn ? " rad/s" : " m/s")});
  }
  if (m.mode != MotorMode::Off && (!std::isfinite(m.max_force) || m.max_force < 0 || m.max_force > kMaxJointForce))
    es.push_back({"", field + ".max_force", num(m.max_force),
                  "must be in [0, " + num(kMaxJointForce) + "]" + (turn ? " N m (a torque)" : " N")});
  return es;
}

std::vector<Error> BulletWorld::check_joint(const RigidJointDef& d) const {
  std::vector<Error> es;
  auto who = [&](RigidBodyId id) {
    if (!alive(id)) return "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}";
    const std::string& n = definition(id).name;
    return n.empty() ? "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}" : "'" + n + "'";
  };
  if (!alive(d.a)) es.push_back({"", "body_a", who(d.a), "must be a live body (removed, or never added)"});
  if (d.b.valid() && !alive(d.b)) es.push_back({"", "body_b", who(d.b), "must be a live body, or none (the world)"});
  if (!es.empty()) return es;
  if (d.b.valid() && d.a.index == d.b.index && d.a.generation == d.b.generation)
    es.push_back({"", "body_b", who(d.b), "must not be body_a: a joint connects two bodies (or body_a and the world: no body_b)"});
  else if (motion(d.a) != RigidMotion::Dynamic && (!d.b.valid() || motion(d.b) != RigidMotion::Dynamic))
    es.push_back({"", d.b.valid() ? "body_b" : "body_a",
                  d.b.valid() ? who(d.a) + " (" + to_string(motion(d.a)) + ") and " + who(d.b) + " (" + to_string(motion(d.b)) + ")"
                              : who(d.a) + " (" + to_string(motion(d.a)) + ") and the world",
                  "at least one side of a joint must be a dynamic body: nothing a joint does moves a kinematic or static body"});
  if (!d.anchor.allFinite() || d.anchor.cwiseAbs().maxCoeff() > 1e7)
    es.push_back({"", "anchor", "[" + num(d.anchor.x()) + ", " + num(d.anchor.y()) + ", " + num(d.anchor.z()) + "]",
                  "must be finite, each coordinate within 1e7 (m, world)"});
  const std::string axis = "[" + num(d.axis.x()) + ", " + num(d.axis.y()) + ", " + num(d.axis.z()) + "]";
  if (!d.axis.allFinite() || !(d.axis.cast<double>().norm() > 1e-6))
    es.push_back({"", "axis", axis, "must be a finite, non-zero direction (world)"});
  if (d.kind != JointKind::Fixed && d.kind != JointKind::Hinge && d.kind != JointKind::Slider &&
      d.kind != JointKind::Cylindrical && d.kind != JointKind::Wheel)
    es.push_back({"", "type", std::to_string(int(d.kind)), "must be fixed, hinge or slider"});
  if (d.kind == JointKind::Wheel) {
    const Eigen::Vector3d u = d.up.cast<double>(), x = d.axis.cast<double>();
    if (!d.up.allFinite() || !(u.norm() > 1e-6) || (x.norm() > 1e-6 && std::abs(u.normalized().dot(x.normalized())) > 0.99))
      es.push_back({"", "up", "[" + num(d.up.x()) + ", " + num(d.up.y()) + ", " + num(d.up.z()) + "]",
                    "must be a finite direction across the axis (world)"});
    if (!std::isfinite(d.max_steer) || d.max_steer < 0 || d.max_steer > 1.2f)
      es.push_back({"", "max_steer", num(d.max_steer), "must be in [0, 1.2] rad"});
  }
  const bool two = d.kind == JointKind::Cylindrical || d.kind == JointKind::Wheel;
  auto dof = [&](const JointDof& f, bool turn) {
    const std::string pre = two ? (turn ? "turn." : "slide.") : "";
    const char* unit = turn ? "rad" : "m";
    if (f.limited) {
      const double lim = turn ? kPi : 1e4;
      if (!std::isfinite(f.lower) || !std::isfinite(f.upper) || std::abs(f.lower) > lim || std::abs(f.upper) > lim)
        es.push_back({"", pre + "limits", "[" + num(f.lower) + ", " + num(f.upper) + "]",
                      "must be finite, within [-" + num(lim) + ", " + num(lim) + "] " + unit});
      else if (f.lower > f.upper)
        es.push_back({"", pre + "limits", "[" + num(f.lower) + ", " + num(f.upper) + "]",
                      std::string("the lower limit must not be above the upper (") + unit + ")"});
    }
    for (Error& e : check_motor(f.motor, turn, pre + "motor")) es.push_back(std::move(e));
    if (!std::isfinite(f.stiffness) || f.stiffness < 0 || f.stiffness > kMaxSpring)
      es.push_back({"", pre + "spring.stiffness", num(f.stiffness),
                    "must be in [0, " + num(kMaxSpring) + "]" + (turn ? " N m/rad" : " N/m")});
    if (!std::isfinite(f.damping) || f.damping < 0 || f.damping > kMaxSpring)
      es.push_back({"", pre + "spring.damping", num(f.damping),
                    "must be in [0, " + num(kMaxSpring) + "]" + (turn ? " N m s/rad" : " N s/m")});
  };
  if (turns(d.kind)) dof(d.turn, true);
  if (slides(d.kind)) dof(d.slide, false);
  return es;
}

namespace {

// One degree of freedom of a Spring2 constraint (index 0 = sliding along x, 3 = turning about
// x). Bullet's velocity motors drive A relative to B (its rows' velocity is v_A − v_B: a
// target of +5 rad/s turned B at −5 rad/s about +x, +0.5 m/s moved B at −0.5 m/s), so every
// target velocity is negated. Its angle about x (Euler, RO_XYZ) is of the opposite sense to
// B's right-handed turn relative to A, so angles, servo targets and angular limits are
// negated (kTurnSign); its travel along x is B's relative to A, as the joint's.
constexpr float kTurnSign = -1.0f;
constexpr int kJointIterations = 40;
constexpr float kJointErp = 0.8f;

void apply_motor(btGeneric6DofSpring2Constraint& c, int index, const JointMotor& m) {
  c.enableMotor(index, m.mode != MotorMode::Off);
  c.setServo(index, m.mode == MotorMode::Position);
  c.setMaxMotorForce(index, m.max_force);
  if (m.mode == MotorMode::Velocity) c.setTargetVelocity(index, -m.target);
  if (m.mode == MotorMode::Position) {
    c.setServoTarget(index, (index >= 3 ? kTurnSign : 1.0f) * m.target);
    c.setTargetVelocity(index, m.servo_speed);
  }
}

void apply_dof(btGeneric6DofSpring2Constraint& c, int index, const JointDof& f) {
  apply_motor(c, index, f.motor);
  const bool spring = f.stiffness > 0 || f.damping > 0;
  c.enableSpring(index, spring);
  if (spring) {
    // Bullet softens a spring too stiff to be sampled by the step (its period under 4 steps):
    // the price of not blowing up.
    c.setStiffness(index, f.stiffness, true);
    c.setDamping(index, f.damping, true);
    c.setEquilibriumPoint(index, 0);
  }
}

}  // namespace

Result<JointId> BulletWorld::add_joint(const RigidJointDef& def) {
  if (auto es = check_joint(def); !es.empty()) return es;
  auto& m = *impl_;
  Impl::Joint j;
  j.def = def;
  j.def.axis.normalize();
  // The joint's frame in the world (Bullet-local), then in each body.
  const Eigen::Vector3d local = def.anchor - m.origin;
  btTransform frame(basis_along(bt(j.def.axis)), btVector3(float(local.x()), float(local.y()), float(local.z())));
  if (def.kind == JointKind::Wheel) {
    // x the axle, y the suspension's (and the steering's) axis `up` made square to it.
    const btVector3 x = bt(j.def.axis);
    btVector3 y = bt(def.up) - x * x.dot(bt(def.up));
    y.normalize();
    const btVector3 z = x.cross(y);
    frame.setBasis(btMatrix3x3(x.x(), y.x(), z.x(), x.y(), y.y(), z.y(), x.z(), y.z(), z.z()));
  }
  btRigidBody& a = *m.bodies[def.a.index].rb;
  if (def.b.valid()) {
    btRigidBody& b = *m.bodies[def.b.index].rb;
    j.c = std::make_unique<btGeneric6DofSpring2Constraint>(a, b, a.getCenterOfMassTransform().inverse() * frame,
                                                           b.getCenterOfMassTransform().inverse() * frame, RO_XYZ);
  } else {
    // Bullet's one-body form: the body is its B, the world its (fixed) A.
    j.c = std::make_unique<btGeneric6DofSpring2Constraint>(a, a.getCenterOfMassTransform().inverse() * frame, RO_XYZ);
  }
  btGeneric6DofSpring2Constraint& c = *j.c;
  // Locked: lower = upper = 0; free: lower > upper; limited: [lower, upper].
  c.setLinearLowerLimit(btVector3(0, 0, 0));
  c.setLinearUpperLimit(btVector3(0, 0, 0));
  c.setAngularLowerLimit(btVector3(0, 0, 0));
  c.setAngularUpperLimit(btVector3(0, 0, 0));
  j.frame_a0 = c.getFrameOffsetA();
  auto open = [&](int index, const JointDof& f) {
    if (!f.limited) c.setLimit(index, 1.0f, -1.0f);
    else if (index >= 3) c.setLimit(index, kTurnSign * f.upper, kTurnSign * f.lower);  // kTurnSign = -1
    else c.setLimit(index, f.lower, f.upper);
    apply_dof(c, index, f);
  };
  if (slides(def.kind)) open(def.kind == JointKind::Wheel ? 1 : 0, j.def.slide);  // a wheel slides along y: `up`
  if (turns(def.kind)) open(3, j.def.turn);
  // More solver iterations for joints than Bullet's 10 for contacts: a chain of bodies of very
  // different masses and inertias (a 1 kg bob 1 m from its pivot, a 1500 kg chassis on 30 kg
  // wheels) converges slowly, and the joint opens (5 mm at the pendulum's turning points
  // with 10).
  c.setOverrideNumSolverIterations(kJointIterations);
  for (int axis = 0; axis < 6; ++axis) c.setParam(BT_CONSTRAINT_STOP_ERP, kJointErp, axis);
  j.fb = std::make_unique<btJointFeedback>();
  c.setJointFeedback(j.fb.get());
  m.world->addConstraint(&c, /*disableCollisionsBetweenLinkedBodies=*/true);
  // A jointed body never sleeps in Bullet: a machine at rest must still answer its motors, and
  // a slow pendulum (under Bullet's 0.8 m/s sleeping threshold) must not stop at the top of
  // its swing.
  for (btRigidBody* rb : {&c.getRigidBodyA(), &c.getRigidBodyB()})
    if (!rb->isStaticOrKinematicObject()) rb->forceActivationState(DISABLE_DEACTIVATION);
  int index;
  if (!m.free_joints.empty()) {
    index = m.free_joints.back();
    m.free_joints.pop_back();
    j.generation = m.joints[std::size_t(index)].generation + 1;
    m.joints[std::size_t(index)] = std::move(j);
  } else {
    index = int(m.joints.size());
    m.joints.push_back(std::move(j));
  }
  return JointId{index, m.joints[std::size_t(index)].generation};
}

bool BulletWorld::joint_alive(JointId id) const {
  return id.index >= 0 && id.index < int(impl_->joints.size()) && impl_->joints[std::size_t(id.index)].c &&
         impl_->joints[std::size_t(id.index)].generation == id.generation;
}

void BulletWorld::remove_joint(JointId id) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  j.c->getRigidBodyA().activate(true);
  j.c->getRigidBodyB().activate(true);
  impl_->drop_joint(id.index);
}

void BulletWorld::set_joint_motor(JointId id, bool turn, const JointMotor& motor) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  (turn ? j.def.turn : j.def.slide).motor = motor;
  apply_motor(*j.c, turn ? 3 : (j.def.kind == JointKind::Wheel ? 1 : 0), motor);
  j.c->getRigidBodyA().activate(true);
  j.c->getRigidBodyB().activate(true);
}

void BulletWorld::set_joint_steering(JointId id, float angle, float speed) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  if (j.def.kind != JointKind::Wheel) return;
  j.steer_target = std::clamp(angle, -j.def.max_steer, j.def.max_steer);
  j.steer_speed = speed;
}

float BulletWorld::joint_steering(JointId id) const {
  assert(joint_alive(id));
  return impl_->joints[std::size_t(id.index)].steer;
}

const RigidJointDef& BulletWorld::joint_definition(JointId id) const {
  assert(joint_alive(id));
  return impl_->joints[std::size_t(id.index)].def;
}

JointState BulletWorld::joint_state(JointId id) const {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  btGeneric6DofSpring2Constraint& c = *j.c;
  c.calculateTransforms();
  const btVector3 axis = c.getCalculatedTransformA().getBasis().getColumn(0);
  const btRigidBody& a = c.getRigidBodyA();
  const btRigidBody& b = c.getRigidBodyB();
  // Velocities of the anchor as a point of each body.
  const btVector3 pa = c.getCalculatedTransformA().getOrigin(), pb = c.getCalculatedTransformB().getOrigin();
  const btVector3 va = a.getLinearVelocity() + a.getAngularVelocity().cross(pa - a.getCenterOfMassPosition());
  const btVector3 vb = b.getLinearVelocity() + b.getAngularVelocity().cross(pb - b.getCenterOfMassPosition());
  JointState s;
  s.angle = kTurnSign * c.getAngle(0);
  s.angular_rate = (b.getAngularVelocity() - a.getAngularVelocity()).dot(axis);
  const bool wheel = j.def.kind == JointKind::Wheel;
  s.position = c.getRelativePivotPosition(wheel ? 1 : 0);
  s.rate = (vb - va).dot(wheel ? c.getCalculatedTransformA().getBasis().getColumn(1) : axis);
  s.torque = j.torque;
  s.force = j.force;
  if (!turns(j.def.kind)) s.angle = s.angular_rate = s.torque = 0;
  if (!slides(j.def.kind)) s.position = s.rate = s.force = 0;
  return s;
}

std::vector<std::int32_t> BulletWorld::joint_groups() const {
  // union-find over the slots, each root the lowest slot of its set
  const int n = int(impl_->bodies.size());
  std::vector<int> parent(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) parent[std::size_t(i)] = i;
  auto root = [&](int i) {
    while (parent[std::size_t(i)] != i) i = parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
    return i;
  };
  std::vector<char> jointed(std::size_t(n), 0);
  for (const auto& j : impl_->joints) {
    if (!j.c || !j.def.b.valid()) continue;
    const int a = root(j.def.a.index), b = root(j.def.b.index);
    jointed[std::size_t(j.def.a.index)] = jointed[std::size_t(j.def.b.index)] = 1;
    if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
  }
  std::vector<std::int32_t> g(std::size_t(n), 0);
  for (int i = 0; i < n; ++i)
    if (jointed[std::size_t(i)]) g[std::size_t(i)] = std::int32_t(root(i) + 1);
  return g;
}

std::vector<JointId> BulletWorld::joints() const {
  std::vector<JointId> out;
  for (int i = 0; i < int(impl_->joints.size()); ++i)
    if (impl_->joints[std::size_t(i)].c) out.push_back({i, impl_->joints[std::size_t(i)].generation});
  return out;
}

}  // namespace sandpatch
