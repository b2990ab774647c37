// tests the public API's kinematic and static bodies and its readings of what the ground does
// to a body (Terrain::body_contact), through include/sandpatch/sandpatch.hpp only: keyframes
// reached exactly, a static body unmoved by what hits it, a kinematic plate pressed into a
// patch at the pose prescribed with the soil's force growing with depth, the heightfield's
// force on a resting box against m g, the sinkage against its definition, bad input refused
// naming the field.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>
#include <sandpatch/sandpatch.hpp>

#include "tests/api/terrain_defs.hpp"

namespace sp = sandpatch::api;
using sp::test::flat_def;  // 10 m flat at y = 1 m, no granular patches
using sp::test::sand_def;  // 4 m flat at y = 1 m, coarse granules (5 cm), k_n = 1e5 N/m

namespace {

constexpr double kDt = 1.0 / 60.0;

template <class T>
sp::Error first_error(const sp::Result<T>& r) {
  EXPECT_FALSE(r.ok());
  return r.errors().empty() ? sp::Error{} : r.errors().front();
}

bool has_field(const std::vector<sp::Error>& es, const std::string& field) {
  return std::any_of(es.begin(), es.end(), [&](const sp::Error& e) { return e.field == field; });
}

sp::BodyDef box(const std::string& name, sp::BodyMotion motion, sp::Vec3 half, sp::Vec3 position) {
  sp::BodyDef b;
  b.name = name;
  b.motion = motion;
  b.shape.kind = sp::ShapeKind::Box;
  b.shape.half_extents = half;
  b.position = position;
  return b;
}

// [w, x, y, z] of a rotation by `deg` about y.
sp::Quat about_y(double deg) {
  const double h = 0.5 * deg * M_PI / 180.0;
  return {float(std::cos(h)), 0.0f, float(std::sin(h)), 0.0f};
}

}  // namespace

// A kinematic box on three keyframes: at each keyframe's time (a whole number of steps) it is
// at the keyframe's position within 1e-6 m and orientation within 1e-6; half way between the
// first two it is at their midpoint, moving at their difference / 0.5 s; after the last it
// holds still there.
TEST(ApiKinematic, KeyframesAreHitAtTheirTimes) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  auto h = t->add_body(box("bucket", sp::BodyMotion::Kinematic, {0.2, 0.1, 0.3}, {5, 3, 5}));
  ASSERT_TRUE(h.ok()) << h.message();
  const std::vector<sp::Keyframe> keys = {{0.0, {4.0, 2.5, 5.0}, about_y(0)},
                                          {0.5, {5.0, 2.0, 5.0}, about_y(90)},
                                          {1.0, {5.0, 2.0, 6.0}, about_y(90)}};
  ASSERT_TRUE(t->set_keyframes(*h, keys).ok());
  auto check_at = [&](const sp::Keyframe& k, const char* what) {
    auto s = t->body_state(*h);
    ASSERT_TRUE(s.ok());
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(s->position[i], k.position[i], 1e-6) << what << " axis " << i;
    const double dot = std::abs(s->orientation[0] * k.orientation[0] + s->orientation[1] * k.orientation[1] +
                                s->orientation[2] * k.orientation[2] + s->orientation[3] * k.orientation[3]);
    EXPECT_NEAR(dot, 1.0, 1e-6) << what;
  };
  ASSERT_TRUE(t->step(kDt).ok());  // placed at the first keyframe, then one step along
  for (int n = 1; n < 15; ++n) ASSERT_TRUE(t->step(kDt).ok());
  auto mid = t->body_state(*h);  // t = 0.25 s: half way between the first two
  EXPECT_NEAR(mid->position[0], 4.5, 1e-6);
  EXPECT_NEAR(mid->position[1], 2.25, 1e-6);
  EXPECT_NEAR(mid->linear_velocity[0], 2.0, 1e-3);   // 1 m in 0.5 s
  EXPECT_NEAR(mid->linear_velocity[1], -1.0, 1e-3);
  EXPECT_NEAR(mid->angular_velocity[1], M_PI, 1e-3);  // 90° in 0.5 s
  for (int n = 15; n < 30; ++n) ASSERT_TRUE(t->step(kDt).ok());
  EXPECT_NEAR(t->time(), 0.5, 1e-12);
  check_at(keys[1], "t = 0.5 s");
  for (int n = 30; n < 60; ++n) ASSERT_TRUE(t->step(kDt).ok());
  check_at(keys[2], "t = 1 s");
  for (int n = 60; n < 90; ++n) ASSERT_TRUE(t->step(kDt).ok());
  check_at(keys[2], "held after the last keyframe");
  EXPECT_NEAR(t->body_state(*h)->linear_velocity[2], 0.0, 1e-6);
  EXPECT_NE(t->report_json().find("\"motion\": \"kinematic\""), std::string::npos);
}

// set_kinematic_target: the body is there after the step; set_body_velocity on a kinematic
// body moves it by v dt every step until changed.
TEST(ApiKinematic, TargetAndVelocity) {
  auto t = sp::Terrain::create(flat_def());
  auto h = t->add_body(box("blade", sp::BodyMotion::Kinematic, {0.5, 0.2, 0.05}, {5, 2, 5}));
  ASSERT_TRUE(h.ok()) << h.message();
  ASSERT_TRUE(t->set_kinematic_target(*h, {5.1, 1.9, 5.0}, about_y(10)).ok());
  ASSERT_TRUE(t->step(kDt).ok());
  EXPECT_NEAR(t->body_state(*h)->position[0], 5.1, 1e-6);
  EXPECT_NEAR(t->body_state(*h)->position[1], 1.9, 1e-6);
  ASSERT_TRUE(t->step(kDt).ok());  // no target: it holds
  EXPECT_NEAR(t->body_state(*h)->position[0], 5.1, 1e-6);
  ASSERT_TRUE(t->set_body_velocity(*h, {0.6f, 0.0f, 0.0f}, {0.0f, 0.0f, 0.0f}).ok());
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(t->step(kDt).ok());
  EXPECT_NEAR(t->body_state(*h)->position[0], 5.1 + 0.6 * 30 * kDt, 1e-5);
  EXPECT_NEAR(t->body_state(*h)->linear_velocity[0], 0.6, 1e-4);
}

// A static box on the ground never moves, not by a 5 kg ball dropped on it from 1 m, nor by
// gravity; the ball comes to rest on its top.
TEST(ApiStatic, StaticBodyNeverMovesWhenHit) {
  auto t = sp::Terrain::create(flat_def());
  auto wall = t->add_body(box("block", sp::BodyMotion::Static, {0.5, 0.5, 0.5}, {5, 1.5, 5}));
  ASSERT_TRUE(wall.ok()) << wall.message();
  sp::BodyDef ball;
  ball.name = "ball";
  ball.shape.radius = 0.2;
  ball.mass = 5;
  ball.position = {5.05, 3.2, 5.0};
  auto b = t->add_body(ball);
  ASSERT_TRUE(b.ok()) << b.message();
  const auto before = *t->body_state(*wall);
  bool touched = false;
  for (int k = 0; k < 120; ++k) {
    ASSERT_TRUE(t->step(kDt).ok());
    const auto s = *t->body_state(*wall);
    for (int i = 0; i < 3; ++i) ASSERT_EQ(s.position[i], before.position[i]) << "step " << k;
    for (int i = 0; i < 4; ++i) ASSERT_EQ(s.orientation[i], before.orientation[i]) << "step " << k;
    touched = touched || t->body_state(*b)->position[1] < 2.0 + 0.2 + 0.01;
  }
  EXPECT_TRUE(touched);
  EXPECT_NEAR(t->body_state(*b)->position[1], 2.0 + 0.2, 0.01) << "the ball rests on the block's top";
  // Loads, impulses and teleports do not apply to it.
  EXPECT_EQ(first_error(t->apply_force(*wall, {1.0f, 0.0f, 0.0f})).field, "apply_force.body");
  EXPECT_EQ(first_error(t->apply_impulse(*wall, {1.0f, 0.0f, 0.0f})).field, "apply_impulse.body");
  EXPECT_EQ(first_error(t->set_body_transform(*wall, {1, 2, 3}, {1, 0, 0, 0})).field, "set_body_transform.body");
  EXPECT_EQ(first_error(t->set_body_velocity(*wall, {1, 0, 0}, {0, 0, 0})).field, "set_body_velocity.body");
  EXPECT_EQ(first_error(t->set_kinematic_target(*wall, {5, 2, 5}, {1, 0, 0, 0})).field, "set_kinematic_target.body");
}

// A 10 kg box resting on the heightfield: the heightfield's contact force is its weight,
// (0, m g, 0) within 5 %, and its sinkage (original surface 1 m − box bottom) is within
// Bullet's contact slop of 0; in the air both are 0 and the sinkage is minus its clearance.
TEST(ApiContact, HeightfieldForceOnARestingBoxIsItsWeight) {
  auto t = sp::Terrain::create(flat_def());
  auto bd = box("crate", sp::BodyMotion::Dynamic, {0.3, 0.2, 0.4}, {5, 1.7, 5});
  bd.mass = 10;
  auto h = t->add_body(bd);
  ASSERT_TRUE(h.ok()) << h.message();
  ASSERT_TRUE(t->step(kDt).ok());
  auto c0 = t->body_contact(*h);
  ASSERT_TRUE(c0.ok());
  EXPECT_EQ(c0->heightfield_force[1], 0.0f) << "in the air";
  EXPECT_NEAR(c0->original_surface_y, 1.0, 1e-6);
  EXPECT_NEAR(c0->sinkage, c0->original_surface_y - c0->lowest_y, 1e-12);
  EXPECT_LT(c0->sinkage, -0.4);  // 0.5 m up, less what it fell in one step
  for (int k = 0; k < 90; ++k) ASSERT_TRUE(t->step(kDt).ok());
  const double weight = 10 * 9.81;
  double sum[3] = {0, 0, 0};
  for (int k = 0; k < 30; ++k) {
    ASSERT_TRUE(t->step(kDt).ok());
    auto c = t->body_contact(*h);
    for (int i = 0; i < 3; ++i) sum[i] += c->heightfield_force[i] / 30.0;
  }
  EXPECT_NEAR(sum[1], weight, 0.05 * weight);
  EXPECT_NEAR(sum[0], 0.0, 0.05 * weight);
  EXPECT_NEAR(sum[2], 0.0, 0.05 * weight);
  auto c = t->body_contact(*h);
  EXPECT_FALSE(c->on_particles);
  const auto s = *t->body_state(*h);
  EXPECT_NEAR(c->lowest_y, s.position[1] - 0.2, 1e-6);
  EXPECT_NEAR(c->sinkage, 1.0 - c->lowest_y, 1e-6);
  EXPECT_NEAR(c->sinkage, 0.0, 0.01);
  EXPECT_NE(t->report_json().find("\"heightfield_force_N\""), std::string::npos);
  EXPECT_NE(t->report_json().find("\"sinkage_m\""), std::string::npos);
}

// A 60 kg box (20 cm cube) dropped from 0.5 m onto a patch of softer sand (k_n = 2e4 N/m, the
// API's default) sinks into the granules: the soil holds its weight (mean granular force m g
// within 15 % over the second second, while the patch is awake), and its sinkage is the
// original surface (1 m, the flat terrain before any patch) minus the box's bottom, > 0.
TEST(ApiContact, BoxOnParticlesSinks) {
  auto def = sand_def();
  def.material.stiffness = 2.0e4;
  auto t = sp::Terrain::create(def);
  ASSERT_TRUE(t.ok()) << t.message();
  auto bd = box("crate", sp::BodyMotion::Dynamic, {0.1, 0.1, 0.1}, {2, 1.0 + 0.1 + 0.5, 2});
  bd.mass = 60;
  auto h = t->add_body(bd);
  ASSERT_TRUE(h.ok()) << h.message();
  const double weight = 60 * 9.81;
  double fy = 0;
  int n = 0;
  bool asleep = false;
  for (int k = 0; k < 120; ++k) {
    ASSERT_TRUE(t->step(kDt).ok());
    for (const auto& e : t->poll_events()) asleep = asleep || e.kind == sp::EventKind::Asleep;
    if (k < 60 || asleep) continue;
    auto c = t->body_contact(*h);
    ASSERT_TRUE(c->on_particles) << "step " << k;
    fy += c->granular_force[1];
    ++n;
  }
  ASSERT_GE(n, 10);
  EXPECT_NEAR(fy / n, weight, 0.15 * weight);
  auto c = t->body_contact(*h);
  const auto s = *t->body_state(*h);
  EXPECT_NEAR(c->original_surface_y, 1.0, 1e-6);
  // The lowest corner: y_c − Σ |R_1i| h_i (R_1i: the world-y row of the rotation matrix).
  const double w = s.orientation[0], x = s.orientation[1], y = s.orientation[2], z = s.orientation[3];
  const double r10 = 2 * (x * y + w * z), r11 = 1 - 2 * (x * x + z * z), r12 = 2 * (y * z - w * x);
  EXPECT_NEAR(c->lowest_y, s.position[1] - 0.1 * (std::abs(r10) + std::abs(r11) + std::abs(r12)), 1e-5);
  EXPECT_NEAR(c->sinkage, 1.0 - c->lowest_y, 1e-6);
  EXPECT_GT(c->sinkage, 0.02) << "bottom at y = " << c->lowest_y;
}

// A kinematic 0.5 m square plate pressed down into a patch at 5 cm/s: at every step it is
// where it was sent (the granules do not push it back), and once in the soil the granular
// force on it is upward and larger in the deepest part of the press than in its first part.
TEST(ApiKinematic, PlatePressedIntoSandIsNotPushedBack) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  const double y0 = 1.0 + 0.05 + 0.02;  // plate bottom 2 cm above the surface
  auto h = t->add_body(box("plate", sp::BodyMotion::Kinematic, {0.25, 0.05, 0.25}, {2, y0, 2}));
  ASSERT_TRUE(h.ok()) << h.message();
  const double v = 0.05;  // m/s down
  std::vector<double> force, depth;
  for (int k = 1; k <= 240; ++k) {  // 4 s: 0.2 m down, 0.18 m into the sand
    ASSERT_TRUE(t->set_kinematic_target(*h, {2, y0 - v * k * kDt, 2}, {1, 0, 0, 0}).ok());
    auto st = t->step(kDt);
    ASSERT_TRUE(st.ok()) << st.message();
    const auto s = *t->body_state(*h);
    ASSERT_NEAR(s.position[1], y0 - v * k * kDt, 1e-5) << "step " << k;
    ASSERT_NEAR(s.position[0], 2.0, 1e-6);
    auto c = t->body_contact(*h);
    if (c->on_particles) {
      force.push_back(c->granular_force[1]);
      depth.push_back(c->sinkage);
    }
  }
  ASSERT_GE(force.size(), 120u) << "the plate must be carried by a patch";
  auto mean = [&](std::size_t a, std::size_t b) {
    double m = 0;
    for (std::size_t k = a; k < b; ++k) m += force[k];
    return m / double(b - a);
  };
  const std::size_t n = force.size();
  const double early = mean(n / 4, n / 2), late = mean(3 * n / 4, n);
  EXPECT_GT(late, 0.0);
  EXPECT_GT(late, 1.2 * early) << "early " << early << " N, late " << late << " N at sinkage " << depth.back() << " m";
  EXPECT_GT(depth.back(), 0.15);
  // Turned back into heightfield, the patch leaves the plate's dent; the sinkage is still
  // measured from the surface as it was before (1 m).
  ASSERT_TRUE(t->demote_all().ok());
  EXPECT_LT(t->height_at(2.0, 2.0), 1.0 - 0.1);
  auto c = t->body_contact(*h);
  EXPECT_NEAR(c->original_surface_y, 1.0, 1e-6);
  EXPECT_NEAR(c->sinkage, 1.0 - (y0 - v * 240 * kDt - 0.05), 1e-5);
  EXPECT_EQ(t->report_json().find("tools_too_fast"), std::string::npos);
}

// The same plate pressed with 1 and with 2 DEM threads: the same final state hash (the frame's
// substep-by-substep DEM steps of a kinematic shell keep the DEM's determinism).
TEST(ApiKinematic, PlatePressIsTheSameWhateverTheThreads) {
  auto run = [](int threads) {
    auto def = sand_def();
    def.threads = threads;
    auto t = sp::Terrain::create(def);
    EXPECT_TRUE(t.ok()) << t.message();
    auto h = t->add_body(box("plate", sp::BodyMotion::Kinematic, {0.25, 0.05, 0.25}, {2, 1.07, 2}));
    EXPECT_TRUE(t->set_body_velocity(*h, {0.0f, -0.1f, 0.0f}, {0.0f, 0.0f, 0.0f}).ok());
    for (int k = 0; k < 90; ++k) EXPECT_TRUE(t->step(kDt).ok());
    return t->state_hash();
  };
  EXPECT_EQ(run(1), run(2));
}

// A tool driven into a patch faster than its granules can be stopped within 2 granule radii
// (2 r sqrt(k_n / m_pt) = 19.3 m/s for these 5 cm granules) is reported in the report's
// tools_too_fast and by an event (EventKind::TooFastForGranules) with its speed and the limit,
// not silently let through.
TEST(ApiKinematic, ToolTooFastForThePatchIsReported) {
  auto t = sp::Terrain::create(sand_def());
  auto h = t->add_body(box("rammer", sp::BodyMotion::Kinematic, {0.25, 0.05, 0.25}, {2, 1.2, 2}));
  ASSERT_TRUE(t->set_body_velocity(*h, {0.0f, -25.0f, 0.0f}, {0.0f, 0.0f, 0.0f}).ok());
  for (int k = 0; k < 3; ++k) ASSERT_TRUE(t->step(kDt).ok());
  const std::string r = t->report_json();
  const auto at = r.find("\"tools_too_fast\"");
  ASSERT_NE(at, std::string::npos) << r;
  EXPECT_NE(r.find("\"rammer\"", at), std::string::npos);
  EXPECT_NE(r.find("\"limit_m_s\"", at), std::string::npos);
  // and an event, once as it went over, with its speed and the limit
  int n = 0;
  for (const sp::Event& e : t->poll_events()) {
    if (e.kind != sp::EventKind::TooFastForGranules) continue;
    ++n;
    EXPECT_EQ(e.body, "rammer");
    EXPECT_NEAR(e.value, 25.0, 1e-3);
    EXPECT_NEAR(e.limit, 19.3, 0.1);
  }
  EXPECT_EQ(n, 1);
}

// Bad input is refused naming the field: keyframes with NaN or infinite values, times not
// increasing, a keyframe or target through the bedrock (surface 1 m − soil_depth 2 m), a
// kinematic body's loads; an unknown motion type.
TEST(ApiKinematic, BadKeyframesAndTargetsAreRefused) {
  auto t = sp::Terrain::create(flat_def());
  auto h = t->add_body(box("tool", sp::BodyMotion::Kinematic, {0.2, 0.2, 0.2}, {5, 2, 5}));
  ASSERT_TRUE(h.ok());
  const double nan = std::nan(""), inf = INFINITY;
  auto r1 = t->set_keyframes(*h, {{0.0, {5, 2, 5}, {1, 0, 0, 0}}, {0.5, {nan, 2, 5}, {1, 0, 0, 0}}});
  EXPECT_TRUE(has_field(r1.errors(), "keyframes[1].position")) << r1.message();
  auto r2 = t->set_keyframes(*h, {{0.0, {5, 2, 5}, {1, 0, 0, 0}}, {inf, {5, 2, 5}, {1, 0, 0, 0}}});
  EXPECT_TRUE(has_field(r2.errors(), "keyframes[1].t")) << r2.message();
  auto r3 = t->set_keyframes(*h, {{0.5, {5, 2, 5}, {1, 0, 0, 0}}, {0.5, {5, 2, 5}, {1, 0, 0, 0}}});
  EXPECT_TRUE(has_field(r3.errors(), "keyframes[1].t")) << r3.message();
  auto r4 = t->set_keyframes(*h, {{0.0, {5, 2, 5}, {1, 0, 0, 0}}, {1.0, {5, -1.5, 5}, {1, 0, 0, 0}}});
  EXPECT_TRUE(has_field(r4.errors(), "keyframes[1].position")) << r4.message();
  auto r5 = t->set_keyframes(*h, {{0.0, {5, 2, 5}, {0, 0, 0, 0}}});
  EXPECT_TRUE(has_field(r5.errors(), "keyframes[0].orientation")) << r5.message();
  EXPECT_TRUE(has_field(t->set_keyframes(*h, {}).errors(), "keyframes"));
  EXPECT_EQ(first_error(t->set_kinematic_target(*h, {5, nan, 5}, {1, 0, 0, 0})).field, "set_kinematic_target.position");
  EXPECT_EQ(first_error(t->set_kinematic_target(*h, {5, -1.1, 5}, {1, 0, 0, 0})).field, "set_kinematic_target.position");
  EXPECT_EQ(first_error(t->apply_force(*h, {1.0f, 0.0f, 0.0f})).field, "apply_force.body");
  EXPECT_EQ(first_error(t->apply_torque(*h, {1.0f, 0.0f, 0.0f})).field, "apply_torque.body");
  // Nothing refused was kept: it holds still where it was added.
  ASSERT_TRUE(t->step(kDt).ok());
  EXPECT_NEAR(t->body_state(*h)->position[1], 2.0, 1e-6);
  auto bad = box("odd", static_cast<sp::BodyMotion>(7), {0.2, 0.2, 0.2}, {5, 2, 5});
  EXPECT_EQ(first_error(t->add_body(bad)).field, "BodyDef.motion");
  // A dynamic body cannot take keyframes or targets.
  auto d = t->add_body(box("crate", sp::BodyMotion::Dynamic, {0.2, 0.2, 0.2}, {3, 2, 3}));
  EXPECT_EQ(first_error(t->set_keyframes(*d, {{0.0, {3, 2, 3}, {1, 0, 0, 0}}})).field, "set_keyframes.body");
  EXPECT_EQ(first_error(t->set_kinematic_target(*d, {3, 2, 3}, {1, 0, 0, 0})).field, "set_kinematic_target.body");
}

namespace {

// A kinematic box driven by the game with set_body_velocity along `v` (m/s) from `start` over
// the sand (14 m × 4 m, surface y = 1 m, lod_apron 0.3 m, one slot), one step of kDt at a
// time, the velocity set again every step as a game does.
struct DriveResult {
  int contact_step = -1;        // the first step ending with its lowest point at or below the surface
  int ready_step = -1;          // the step the patch live at contact became ready (-1: none was)
  int promoted_by_contact = 0;  // patches promoted up to the contact step
  bool carried_at_contact = false;  // a patch carried it in the contact step
  std::vector<sp::Event> events;    // every event of the run
  std::string report;
};
DriveResult drive_into_sand(sp::Vec3 start, sp::Vec3f v, int steps, double apron = 0.3) {
  DriveResult out;
  auto def = sand_def();
  def.lod_apron = apron;
  def.samples_x = 141;
  auto t = sp::Terrain::create(def);
  EXPECT_TRUE(t.ok()) << t.message();
  if (!t.ok()) return out;
  auto h = t->add_body(box("bucket", sp::BodyMotion::Kinematic, {0.2, 0.05, 0.2}, start));
  EXPECT_TRUE(h.ok()) << h.message();
  for (int k = 1; k <= steps; ++k) {
    EXPECT_TRUE(t->set_body_velocity(*h, v, {0.0f, 0.0f, 0.0f}).ok());
    auto st = t->step(kDt);
    EXPECT_TRUE(st.ok()) << st.message();
    for (const sp::Event& e : t->poll_events()) {
      if (out.contact_step < 0) {
        if (e.kind == sp::EventKind::Ready) out.ready_step = k;
        if (e.kind == sp::EventKind::Demoted) out.ready_step = -1;
        out.promoted_by_contact += e.kind == sp::EventKind::Promoted;
      }
      out.events.push_back(e);
    }
    const auto c = t->body_contact(*h);
    if (out.contact_step < 0 && c->lowest_y <= 1.0 + 1e-9) {
      out.contact_step = k;
      out.carried_at_contact = c->on_particles;
    }
  }
  out.report = t->report_json();
  return out;
}

}  // namespace

// A tool the game drives (a velocity set every frame, no keyframes) is looked ahead of like a
// keyframed one: its motion held for lod_horizon is its planned path (planning.cpp plan_path).
// The box skims 0.3 m over the sand at 15 m/s, sinking at 0.5 m/s, and meets it after 0.6 s
// (step 36) at x = 10 m. Asserted: one patch, over where it meets the sand, ready before that
// step, carrying it from its first contact. (Followed ballistically, gravity bent its
// predicted path into the ground 2 m ahead of it: three patches one after another on the one
// slot, each demoted for the next, and the one under the contact became ready in the contact
// step itself.)
TEST(ApiKinematic, AGameDrivenToolHasItsPatchReadyBeforeItMeetsTheSand) {
  const DriveResult r = drive_into_sand({1.0, 1.35, 2.0}, {15.0f, -0.5f, 0.0f}, 40);
  std::printf("ready at step %d, contact at step %d, %d patch(es) promoted by then, carried %d\n", r.ready_step,
              r.contact_step, r.promoted_by_contact, int(r.carried_at_contact));
  ASSERT_NEAR(r.contact_step, 36, 1);
  ASSERT_GT(r.ready_step, 0) << "no patch was ready at contact";
  EXPECT_LT(r.ready_step, r.contact_step);
  EXPECT_EQ(r.promoted_by_contact, 1);
  EXPECT_TRUE(r.carried_at_contact);
}

// A game-driven tool faster than the patches can follow (more than lod_apron in one step:
// 0.3 m × 60 = 18 m/s here) is reported, naming it, with its speed and the speed that can be
// followed: an event (EventKind::TooFastToFollow, once as it goes over) and the report's
// warnings; the same tool at 15 m/s is not.
TEST(ApiKinematic, AGameDrivenToolTooFastToFollowIsReported) {
  const DriveResult fast = drive_into_sand({1.0, 1.35, 2.0}, {20.0f, -0.5f, 0.0f}, 30);
  int n = 0;
  for (const sp::Event& e : fast.events) {
    if (e.kind != sp::EventKind::TooFastToFollow) continue;
    ++n;
    EXPECT_EQ(e.body, "bucket");
    EXPECT_NEAR(e.value, std::hypot(20.0, 0.5), 1e-3);  // m/s
    EXPECT_NEAR(e.limit, 0.3 * 60.0, 1e-9);              // m/s: lod_apron / dt
    EXPECT_STREQ(sp::to_string(e.kind), "too_fast_to_follow");
  }
  EXPECT_EQ(n, 1);
  EXPECT_NE(fast.report.find("bodies.bucket: reached 20.0"), std::string::npos) << fast.report.substr(fast.report.find("\"warnings\""), 400);
  const DriveResult ok = drive_into_sand({1.0, 1.35, 2.0}, {15.0f, -0.5f, 0.0f}, 30);
  for (const sp::Event& e : ok.events) EXPECT_NE(e.kind, sp::EventKind::TooFastToFollow);
  EXPECT_EQ(ok.report.find("bodies.bucket: reached"), std::string::npos);
}
