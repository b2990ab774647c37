// tests the public API's joints (Terrain::add_joint, set_joint_motor, joint_state), through
// include/sandpatch/sandpatch.hpp only: a hinge pendulum keeps its pivot and swings with the
// period 2π sqrt(L / g); a velocity motor spins a free wheel to its target at its torque
// limit; a servo reaches its angle; a slider's spring deflects by m g / k; a removed body takes
// its joints along; bad joints refused naming the field.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>
#include <sandpatch/sandpatch.hpp>

#include "tests/api/terrain_defs.hpp"

namespace sp = sandpatch::api;
using sp::test::flat_def;  // 10 m flat at y = 1 m, no granular patches

namespace {

constexpr double kG = 9.81;  // m/s², flat_def's gravity

bool has_field(const std::vector<sp::Error>& es, const std::string& field) {
  return std::any_of(es.begin(), es.end(), [&](const sp::Error& e) { return e.field == field; });
}

sp::BodyDef body(const std::string& name, sp::ShapeKind kind, sp::Vec3 position, double mass = 1.0) {
  sp::BodyDef b;
  b.name = name;
  b.shape.kind = kind;
  b.position = position;
  b.mass = mass;
  return b;
}

// v rotated by the unit quaternion q = [w, x, y, z].
sp::Vec3 rotate(const sp::Quat& q, const sp::Vec3& v) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  // v + 2 w (u × v) + 2 u × (u × v), u = (x, y, z)
  const double cx = y * v[2] - z * v[1], cy = z * v[0] - x * v[2], cz = x * v[1] - y * v[0];
  const double dx = y * cz - z * cy, dy = z * cx - x * cz, dz = x * cy - y * cx;
  return {v[0] + 2 * (w * cx + dx), v[1] + 2 * (w * cy + dy), v[2] + 2 * (w * cz + dz)};
}

}  // namespace

// A 1 m pendulum: a small sphere (r = 5 cm, 1 kg) on a hinge about z to a static post, let go
// at 0.1 rad. The pivot as a point of the bob stays within 1 mm of the anchor, and the period
// (mean of the upward zero crossings over 10 s) is 2π sqrt(L / g) within 1 % (the small-angle
// formula: the amplitude's correction θ0² / 16 and the sphere's own inertia, 2/5 r² / L² / 2,
// are 6e-4 and 5e-4 of it).
TEST(ApiJoints, HingePendulumKeepsItsPivotAndPeriod) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef post = body("post", sp::ShapeKind::Box, {5, 4.2, 5});
  post.motion = sp::BodyMotion::Static;
  post.shape.half_extents = {0.05, 0.05, 0.05};
  auto p = t->add_body(post);
  ASSERT_TRUE(p.ok()) << p.message();
  const double L = 1.0, th0 = 0.1;
  const sp::Vec3 anchor = {5, 4, 5};
  sp::BodyDef bob = body("bob", sp::ShapeKind::Sphere, {5 + L * std::sin(th0), 4 - L * std::cos(th0), 5});
  bob.shape.radius = 0.05;
  auto b = t->add_body(bob);
  ASSERT_TRUE(b.ok()) << b.message();
  sp::JointDef j;
  j.name = "pivot";
  j.kind = sp::JointKind::Hinge;
  j.body_a = *p;
  j.body_b = *b;
  j.anchor = anchor;
  j.axis = {0, 0, 1};
  auto jh = t->add_joint(j);
  ASSERT_TRUE(jh.ok()) << jh.message();
  const sp::Vec3 offset = {anchor[0] - bob.position[0], anchor[1] - bob.position[1], anchor[2] - bob.position[2]};

  const double dt = 1.0 / 240.0;
  double worst = 0, prev_x = std::sin(th0), prev_t = 0;
  std::vector<double> ups;  // s, upward zero crossings of x − 5
  for (int k = 1; k <= 2400; ++k) {
    ASSERT_TRUE(t->step(dt).ok());
    const auto s = t->body_state(*b);
    ASSERT_TRUE(s.ok());
    const sp::Vec3 r = rotate(s->orientation, offset);
    const double dx = s->position[0] + r[0] - anchor[0], dy = s->position[1] + r[1] - anchor[1],
                 dz = s->position[2] + r[2] - anchor[2];
    worst = std::max(worst, std::sqrt(dx * dx + dy * dy + dz * dz));
    const double x = s->position[0] - 5, now = k * dt;
    if (prev_x < 0 && x >= 0) ups.push_back(prev_t + (now - prev_t) * (-prev_x) / (x - prev_x));
    prev_x = x;
    prev_t = now;
  }
  EXPECT_LT(worst, 1e-3) << "m, the pivot drifted from the anchor";
  ASSERT_GE(ups.size(), 4u);
  const double period = (ups.back() - ups.front()) / double(ups.size() - 1);
  const double expected = 2 * M_PI * std::sqrt(L / kG);
  EXPECT_NEAR(period, expected, 0.01 * expected);
  // The joint reads the bob's angle: within the swing's amplitude.
  auto st = t->joint_state(*jh);
  ASSERT_TRUE(st.ok());
  EXPECT_LE(std::abs(st->position), th0 * 1.05);
}

// A wheel (cylinder r = 0.3 m, 0.2 m wide, 10 kg: I = m r² / 2 = 0.45 kg m²) hinged to the
// world at its centre about z, with a velocity motor of 5 rad/s and at most 20 N m: in the
// first step the motor is at its limit (the joint reads 20 N m within 5 %, the wheel gains
// τ dt / I), after 1 s it turns at 5 rad/s within 1 % about +z.
TEST(ApiJoints, VelocityMotorSpinsAWheelToItsTarget) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef w = body("wheel", sp::ShapeKind::Cylinder, {5, 3, 5}, 10.0);
  w.shape.radius = 0.3;
  w.shape.height = 0.2;
  w.orientation = {float(std::cos(M_PI / 4)), float(std::sin(M_PI / 4)), 0, 0};  // axis (local y) onto z
  auto h = t->add_body(w);
  ASSERT_TRUE(h.ok()) << h.message();
  sp::JointDef j;
  j.kind = sp::JointKind::Hinge;
  j.body_a = *h;
  j.anchor = {5, 3, 5};
  j.axis = {0, 0, 1};
  j.motor = {sp::MotorMode::Velocity, 5.0, 20.0, 1.0};
  auto jh = t->add_joint(j);
  ASSERT_TRUE(jh.ok()) << jh.message();
  const double dt = 1.0 / 60.0, I = 0.5 * 10.0 * 0.3 * 0.3;
  ASSERT_TRUE(t->step(dt).ok());
  auto st = t->joint_state(*jh);
  ASSERT_TRUE(st.ok());
  EXPECT_NEAR(st->force, 20.0, 1.0) << "N m at the limit";
  EXPECT_NEAR(st->rate, 20.0 * dt / I, 0.05 * 20.0 * dt / I);
  for (int k = 1; k < 60; ++k) ASSERT_TRUE(t->step(dt).ok());
  st = t->joint_state(*jh);
  EXPECT_NEAR(st->rate, 5.0, 0.05);
  auto s = t->body_state(*h);
  EXPECT_NEAR(s->angular_velocity[2], 5.0f, 0.05f);
  EXPECT_NEAR(s->position[1], 3.0, 1e-3) << "the hinge holds it up";
  // Velocity 0 with the same torque brakes it: back to rest in 0.1 s (I ω / τ = 0.11 s).
  ASSERT_TRUE(t->set_joint_motor(*jh, {sp::MotorMode::Velocity, 0.0, 20.0, 1.0}).ok());
  for (int k = 0; k < 12; ++k) ASSERT_TRUE(t->step(dt).ok());
  EXPECT_NEAR(t->joint_state(*jh)->rate, 0.0, 0.01);
}

// A 1 m rod (2 kg) hanging from a world hinge at its top end, driven by a servo to 0.5 rad at
// 1 rad/s with up to 100 N m (gravity's torque is at most m g L / 2 = 9.8 N m): after 0.25 s
// it has moved about 0.25 rad (the servo's speed), after 2 s it holds 0.5 rad within 0.01 rad.
TEST(ApiJoints, ServoReachesItsAngle) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef rod = body("rod", sp::ShapeKind::Box, {5, 4, 5}, 2.0);
  rod.shape.half_extents = {0.05, 0.5, 0.05};
  auto h = t->add_body(rod);
  ASSERT_TRUE(h.ok());
  sp::JointDef j;
  j.kind = sp::JointKind::Hinge;
  j.body_a = *h;
  j.anchor = {5, 4.5, 5};
  j.axis = {0, 0, 1};
  j.motor = {sp::MotorMode::Position, 0.5, 100.0, 1.0};
  auto jh = t->add_joint(j);
  ASSERT_TRUE(jh.ok()) << jh.message();
  const double dt = 1.0 / 60.0;
  for (int k = 0; k < 15; ++k) ASSERT_TRUE(t->step(dt).ok());
  EXPECT_NEAR(t->joint_state(*jh)->position, 0.25, 0.03);
  for (int k = 15; k < 120; ++k) ASSERT_TRUE(t->step(dt).ok());
  EXPECT_NEAR(t->joint_state(*jh)->position, 0.5, 0.01);
  // The rod turned about +z by that angle: its bottom end swung towards +x.
  EXPECT_GT(t->body_state(*h)->position[0], 5.0 + 0.4 * std::sin(0.5));
}

// A 10 kg box on a vertical slider to the world with a spring of k = 2000 N/m (c = 200 N s/m):
// let go where the spring is slack, it settles at the static deflection m g / k = 4.9 cm
// within 3 %, and the joint reads the spring's force m g within 3 %.
TEST(ApiJoints, SliderSpringDeflectsByWeightOverStiffness) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b = body("mass", sp::ShapeKind::Box, {5, 4, 5}, 10.0);
  b.shape.half_extents = {0.2, 0.2, 0.2};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok());
  sp::JointDef j;
  j.kind = sp::JointKind::Slider;
  j.body_a = *h;
  j.anchor = {5, 4, 5};
  j.axis = {0, 1, 0};
  j.spring = {2000.0, 200.0};
  auto jh = t->add_joint(j);
  ASSERT_TRUE(jh.ok()) << jh.message();
  for (int k = 0; k < 4 * 240; ++k) ASSERT_TRUE(t->step(1.0 / 240.0).ok());
  const double expected = -10.0 * kG / 2000.0;  // m: down the axis
  auto st = t->joint_state(*jh);
  EXPECT_NEAR(st->position, expected, 0.03 * std::abs(expected));
  EXPECT_NEAR(t->body_state(*h)->position[1], 4 + expected, 0.03 * std::abs(expected));
  EXPECT_NEAR(st->force, 10.0 * kG, 0.03 * 10.0 * kG) << "N, up the axis";
  EXPECT_NEAR(t->body_state(*h)->position[0], 5.0, 1e-4) << "no sideways travel";
}

// Removing a body removes its joints; removing a joint frees the body.
TEST(ApiJoints, RemovedBodyTakesItsJoints) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  auto a = t->add_body(body("a", sp::ShapeKind::Sphere, {4, 4, 5}));
  auto b = t->add_body(body("b", sp::ShapeKind::Sphere, {6, 4, 5}));
  ASSERT_TRUE(a.ok() && b.ok());
  sp::JointDef j;
  j.kind = sp::JointKind::Fixed;
  j.body_a = *a;
  j.body_b = *b;
  j.anchor = {5, 4, 5};
  auto jh = t->add_joint(j);
  ASSERT_TRUE(jh.ok()) << jh.message();
  EXPECT_TRUE(t->alive(*jh));
  ASSERT_TRUE(t->remove_body(*a).ok());
  EXPECT_FALSE(t->alive(*jh));
  EXPECT_FALSE(t->joint_state(*jh).ok());
  EXPECT_EQ(t->remove_joint(*jh).errors().front().field, "JointHandle");
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_LT(t->body_state(*b)->position[1], 4.0) << "b falls free";
}

// Each bad joint is refused naming its field.
TEST(ApiJoints, BadJointsAreRefusedNamingTheField) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  auto a = t->add_body(body("a", sp::ShapeKind::Sphere, {4, 4, 5}));
  auto b = t->add_body(body("b", sp::ShapeKind::Sphere, {6, 4, 5}));
  sp::BodyDef s1 = body("s1", sp::ShapeKind::Sphere, {3, 4, 5});
  s1.motion = sp::BodyMotion::Static;
  sp::BodyDef k1 = body("k1", sp::ShapeKind::Sphere, {7, 4, 5});
  k1.motion = sp::BodyMotion::Kinematic;
  auto s = t->add_body(s1);
  auto k = t->add_body(k1);
  ASSERT_TRUE(a.ok() && b.ok() && s.ok() && k.ok());
  auto good = [&] {
    sp::JointDef j;
    j.kind = sp::JointKind::Hinge;
    j.body_a = *a;
    j.body_b = *b;
    j.anchor = {5, 4, 5};
    return j;
  };
  ASSERT_TRUE(t->add_joint(good()).ok());
  auto refused = [&](sp::JointDef j, const std::string& field) {
    auto r = t->add_joint(j);
    ASSERT_FALSE(r.ok()) << field;
    EXPECT_TRUE(has_field(r.errors(), field)) << r.message();
  };
  const double nan = std::nan("");
  {
    auto j = good();
    j.body_b = *a;
    refused(j, "JointDef.body_b");  // the same body on both sides
  }
  {
    auto j = good();
    j.body_a = *s;
    j.body_b = *k;
    refused(j, "JointDef.body_b");  // static and kinematic: nothing to move
  }
  {
    auto j = good();
    j.body_a = *k;
    j.body_b = {};
    refused(j, "JointDef.body_a");  // kinematic to the world
  }
  {
    auto j = good();
    j.body_a = {99, 0};
    refused(j, "JointDef.body_a");  // never added
  }
  {
    auto j = good();
    j.axis = {0, 0, 0};
    refused(j, "JointDef.axis");
  }
  {
    auto j = good();
    j.axis = {nan, 0, 1};
    refused(j, "JointDef.axis");
  }
  {
    auto j = good();
    j.anchor = {5, nan, 5};
    refused(j, "JointDef.anchor");
  }
  {
    auto j = good();
    j.motor = {sp::MotorMode::Velocity, nan, 10, 1};
    refused(j, "JointDef.motor.target");
  }
  {
    auto j = good();
    j.motor = {sp::MotorMode::Velocity, 1, -5, 1};
    refused(j, "JointDef.motor.max_force");
  }
  {
    auto j = good();
    j.motor = {sp::MotorMode::Position, 4.0, 5, 1};  // a hinge's angle is within [-pi, pi]
    refused(j, "JointDef.motor.target");
  }
  {
    auto j = good();
    j.motor = {sp::MotorMode::Position, 1.0, 5, 0};
    refused(j, "JointDef.motor.servo_speed");
  }
  {
    auto j = good();
    j.limits = std::array<double, 2>{0.5, -0.5};
    refused(j, "JointDef.limits");
  }
  {
    auto j = good();
    j.limits = std::array<double, 2>{-4.0, 0.5};
    refused(j, "JointDef.limits");
  }
  {
    auto j = good();
    j.spring.stiffness = -1;
    refused(j, "JointDef.spring.stiffness");
  }
  // A static body on one side is fine.
  {
    auto j = good();
    j.body_a = *s;
    EXPECT_TRUE(t->add_joint(j).ok());
  }
  // A fixed joint has no motor; a bad motor is refused by set_joint_motor too.
  auto j = good();
  j.kind = sp::JointKind::Fixed;
  auto fixed = t->add_joint(j);
  ASSERT_TRUE(fixed.ok()) << fixed.message();
  auto r = t->set_joint_motor(*fixed, {sp::MotorMode::Velocity, 1, 1, 1});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors().front().field, "set_joint_motor.joint");
  auto hinge = t->add_joint(good());
  r = t->set_joint_motor(*hinge, {sp::MotorMode::Velocity, 1, nan, 1});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(has_field(r.errors(), "set_joint_motor.motor.max_force")) << r.message();
}
