// tests scene files' joints (scene/scene_joints.cpp, manager/scene_world.cpp, World's joint
// stage): they parse and survive the canonical JSON; bad ones are refused naming the field,
// by the parser and by make_world as `sandpatch check` runs it; motor phases drive a hinge
// while they last and the motor is off outside them; a slider's motor moves a body at its
// speed; a joint between bodies spawned later is made when both are there.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "manager/scene_world.hpp"
#include "manager/world.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;

namespace {

// A flat 16 m terrain at y = 1 m without patches, bodies and joints (JSON arrays' items).
std::string scene_with(const std::string& bodies, const std::string& joints) {
  return R"({"name": "joints",
  "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.0, "samples_x": 33, "samples_z": 33},
              "spacing": 0.5, "soil_depth": 1.0},
  "materials": [{"name": "sand", "restitution": 0.3}],
  "bodies": [)" + bodies + R"(],
  "joints": [)" + joints + R"(],
  "simulation": {"dt": 0.016666666666666666, "duration": 2.0, "granular_patches": false}})";
}

// A wheel (cylinder about z, 10 kg, I = m r² / 2 = 0.45 kg m²) 2 m up, a static post, a
// kinematic carriage and a box.
const char* kBodies = R"(
  {"name": "wheel", "shape": {"type": "cylinder", "radius": 0.3, "height": 0.2}, "mass": 10,
   "pose": {"position": [4, 3, 8], "euler_deg": [90, 0, 0]}},
  {"name": "post", "motion": "static", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
   "pose": {"position": [8, 4, 8]}},
  {"name": "carriage", "motion": "kinematic", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]},
   "keyframes": [{"t": 0, "position": [12, 4, 8]}]},
  {"name": "box", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]}, "mass": 5,
   "pose": {"position": [12, 3, 8]}})";

bool has_field(const std::vector<Error>& es, const std::string& field) {
  for (const Error& e : es)
    if (e.field.starts_with(field)) return true;
  return false;
}

}  // namespace

TEST(SceneJoints, ParseAndSurviveTheCanonicalJson) {
  const std::string joints = R"(
    {"name": "axle", "type": "hinge", "body_a": "wheel", "anchor": [4, 3, 8], "axis": [0, 0, 1],
     "motor": [{"from": 0, "until": 0.5, "target_velocity": 4, "max_torque": 50},
               {"from": 1, "target_position": 0.5, "max_torque": 50, "servo_speed": 2}]},
    {"name": "rail", "type": "slider", "body_a": "carriage", "body_b": "box", "anchor": [12, 3, 8], "axis": [0, 1, 0],
     "limits": [-0.5, 0.5], "spring": {"stiffness": 2000, "damping": 100}},
    {"name": "weld", "type": "fixed", "body_a": "post", "body_b": "wheel", "anchor": [6, 3.5, 8]})";
  auto s = parse_scene(scene_with(kBodies, joints), "j.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(s->joints.size(), 3u);
  EXPECT_EQ(s->joints[0].type, JointType::Hinge);
  ASSERT_EQ(s->joints[0].motor.size(), 2u);
  EXPECT_EQ(s->joints[0].motor[0].target_velocity.value_or(0), 4.0);
  EXPECT_EQ(s->joints[0].motor[1].servo_speed, 2.0);
  EXPECT_EQ(s->joints[1].body_b, "box");
  EXPECT_EQ(s->joints[1].spring_stiffness, 2000.0);
  EXPECT_EQ(s->joints[2].type, JointType::Fixed);
  auto again = parse_scene(scene_to_json(*s).dump(), "j2.json", "");
  ASSERT_TRUE(again.ok()) << again.message();
  EXPECT_EQ(scene_to_json(*again), scene_to_json(*s));
  // make_world as `sandpatch check` runs it accepts them.
  auto w = make_world(*s, 1, "cpu", nullptr, /*patches=*/false);
  ASSERT_TRUE(w.ok()) << w.message();
}

// Each refused by the parser naming the field.
TEST(SceneJoints, BadJointsAreRefusedNamingTheField) {
  auto refused = [](const std::string& joint, const std::string& field) {
    auto s = parse_scene(scene_with(kBodies, joint), "bad.json", "");
    ASSERT_FALSE(s.ok()) << joint;
    EXPECT_TRUE(has_field(s.errors(), field)) << s.message();
    EXPECT_EQ(s.errors().front().file, "bad.json");
  };
  const std::string h = R"({"name": "j", "type": "hinge", "anchor": [4, 3, 8], )";
  refused(h + R"("body_a": "whel"})", "joints[0].body_a");                         // unknown name
  refused(h + R"("body_a": "wheel", "body_b": "nobody"})", "joints[0].body_b");
  refused(h + R"("body_a": "wheel", "body_b": "wheel"})", "joints[0].body_b");     // the same body
  refused(h + R"("body_a": "post", "body_b": "carriage"})", "joints[0].body_b");   // static and kinematic
  refused(h + R"("body_a": "carriage"})", "joints[0].body_a");                     // kinematic and the world
  refused(h + R"("body_a": "wheel", "axis": [0, 0, 0]})", "joints[0].axis");
  refused(h + R"("body_a": "wheel", "axis": [0, "NaN", 1]})", "joints[0].axis");
  refused(h + R"("body_a": "wheel", "limits": [1, -1]})", "joints[0].limits");
  refused(h + R"("body_a": "wheel", "limits": [-4, 1]})", "joints[0].limits");     // beyond pi
  refused(h + R"("body_a": "wheel", "motor": [{"target_velocity": "NaN", "max_torque": 5}]})",
          "joints[0].motor[0].target_velocity");
  refused(h + R"("body_a": "wheel", "motor": [{"target_velocity": 1, "max_torque": -5}]})", "joints[0].motor[0].max_torque");
  refused(h + R"("body_a": "wheel", "motor": [{"target_velocity": 1, "max_force": 5}]})", "joints[0].motor[0].max_force");
  refused(h + R"("body_a": "wheel", "motor": [{"target_velocity": 1, "target_position": 1, "max_torque": 5}]})",
          "joints[0].motor[0].target_position");
  refused(h + R"("body_a": "wheel", "motor": [{"max_torque": 5}]})", "joints[0].motor[0].target_velocity");
  refused(h + R"("body_a": "wheel", "motor": [{"from": 2, "until": 1, "target_velocity": 1, "max_torque": 5}]})",
          "joints[0].motor[0].until");
  refused(h + R"("body_a": "wheel", "spring": {"stiffness": -1}})", "joints[0].spring.stiffness");
  refused(h + R"("body_a": "wheel", "speed": 3})", "joints[0].speed");              // unknown key
  refused(R"({"name": "j", "type": "weld", "body_a": "wheel", "anchor": [4, 3, 8]})", "joints[0].type");
  refused(R"({"name": "j", "type": "fixed", "body_a": "wheel", "anchor": [4, 3, 8], "axis": [0, 1, 0]})", "joints[0].axis");
  refused(R"({"name": "j", "type": "hinge", "body_a": "wheel"})", "joints[0].anchor");
  refused(h + R"("body_a": "wheel"}, )" + h + R"("body_a": "box"})", "joints[1].name");  // not unique
  // A static body on one side is fine.
  auto s = parse_scene(scene_with(kBodies, h + R"("body_a": "post", "body_b": "box"})"), "ok.json", "");
  EXPECT_TRUE(s.ok()) << s.message();
}

// Motor phases: 4 rad/s at up to 50 N m for t in [0, 0.5) (the wheel reaches it in
// I ω / τ = 0.036 s), then no motor (the free wheel keeps turning at 4 rad/s: nothing brakes
// it), then 0 rad/s from t = 1 s (it stops). The hinge holds the wheel 2 m up throughout.
TEST(SceneJoints, MotorPhasesDriveTheHingeWhileTheyLast) {
  const std::string joint = R"({"name": "axle", "type": "hinge", "body_a": "wheel", "anchor": [4, 3, 8], "axis": [0, 0, 1],
     "motor": [{"from": 0, "until": 0.5, "target_velocity": 4, "max_torque": 50},
               {"from": 1, "target_velocity": 0, "max_torque": 50}]})";
  auto s = parse_scene(scene_with(kBodies, joint), "m.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  auto w = make_world(*s, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  const double dt = s->simulation.dt;
  auto rate = [&] {
    const JointId id = world.joint_entries().at(0).id;
    EXPECT_TRUE(world.joint_alive(id));
    return world.bullet().joint_state(id).angular_rate;
  };
  for (int k = 0; k < 24; ++k) ASSERT_TRUE(world.step(dt).ok());  // t = 0.4 s
  EXPECT_NEAR(rate(), 4.0, 0.02);
  for (int k = 24; k < 54; ++k) ASSERT_TRUE(world.step(dt).ok());  // t = 0.9 s: no motor since 0.5 s
  EXPECT_NEAR(rate(), 4.0, 0.05);
  for (int k = 54; k < 72; ++k) ASSERT_TRUE(world.step(dt).ok());  // t = 1.2 s: braked since 1 s
  EXPECT_NEAR(rate(), 0.0, 0.02);
  const BodyState st = world.bullet().state(world.entries().at(0).id);
  EXPECT_NEAR(st.position.y(), 3.0, 1e-3);
  EXPECT_NEAR(st.angular_velocity.z(), 0.0f, 0.02f);
}

// A slider between the kinematic carriage and the box, axis down (-y), its motor moving the
// box at 0.5 m/s for 0.4 s: the box is 0.2 m lower (within 1 cm) and still under the
// carriage; the report names the joint with its travel.
TEST(SceneJoints, SliderMotorMovesTheBodyAtItsSpeed) {
  const std::string joint = R"({"name": "rail", "type": "slider", "body_a": "carriage", "body_b": "box",
     "anchor": [12, 3, 8], "axis": [0, -1, 0],
     "motor": [{"from": 0, "until": 0.4, "target_velocity": 0.5, "max_force": 1000},
               {"from": 0.4, "target_velocity": 0, "max_force": 1000}]})";
  auto s = parse_scene(scene_with(kBodies, joint), "s.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  auto w = make_world(*s, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  for (int k = 0; k < 36; ++k) ASSERT_TRUE(world.step(s->simulation.dt).ok());  // 0.6 s
  const BodyState st = world.bullet().state(world.entries().at(3).id);
  EXPECT_NEAR(st.position.y(), 3.0 - 0.2, 0.01);
  EXPECT_NEAR(st.position.x(), 12.0, 1e-3);
  const auto report = world.report();
  ASSERT_TRUE(report.contains("joints"));
  EXPECT_EQ(report["joints"][0]["name"], "rail");
  EXPECT_NEAR(report["joints"][0]["position_m"].get<double>(), 0.2, 0.01);
}

// A joint to a body that spawns at 0.5 s is made in that frame, at the poses then: the bob,
// let go level with the pivot, swings on its 1 m arm (within 5 mm: one Bullet step per 1/60 s
// frame at up to 4.4 m/s) instead of falling.
TEST(SceneJoints, AJointWaitsForItsBodiesToSpawn) {
  const std::string bodies = R"(
    {"name": "post", "motion": "static", "shape": {"type": "box", "half_extents": [0.1, 0.1, 0.1]}, "pose": {"position": [8, 4, 8]}},
    {"name": "bob", "shape": {"type": "sphere", "radius": 0.1}, "mass": 1, "pose": {"position": [9, 4, 8]}, "spawn_time": 0.5})";
  const std::string joint = R"({"name": "pivot", "type": "hinge", "body_a": "post", "body_b": "bob", "anchor": [8, 4, 8]})";
  auto s = parse_scene(scene_with(bodies, joint), "spawn.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  auto w = make_world(*s, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  for (int k = 0; k < 29; ++k) ASSERT_TRUE(world.step(s->simulation.dt).ok());
  EXPECT_FALSE(world.joint_entries().at(0).id.valid());
  for (int k = 29; k < 120; ++k) ASSERT_TRUE(world.step(s->simulation.dt).ok());
  ASSERT_TRUE(world.joint_entries().at(0).id.valid());
  const BodyState st = world.bullet().state(world.entries().at(1).id);
  EXPECT_NEAR((st.position - Eigen::Vector3d(8, 4, 8)).norm(), 1.0, 5e-3);
  EXPECT_LT(st.position.y(), 4.0);
}

// The shipped excavator arm (scenes/excavator_arm.json): three dynamic bodies on hinges driven
// by position servos dig into the sand, carry what the bucket scooped up and pour it. Frame by
// frame through the World, as `sandpatch run` steps it, on one DEM thread (docs/manager.md "An
// excavator arm on joints"). Asserted, with what this scene measured: the bucket's lowest point
// more than 15 cm below the original surface (24.1 cm); while the stick drags it toward the
// machine (+x, t in [2.5, 4] s) the soil pushes it back (mean x force < -500 N; -2.1 kN);
// lifted 0.55-1 m above the surface, higher than a free body's shell engages, it still carries
// what it scooped (mean weight of the soil on it > 30 kg; 85.5 kg, and 7.4 kg when only
// kinematic tools kept their shells that high); after pouring, held still in the air, it holds
// under 5 kg (0.0 kg; 31.5 kg while the shell of a body at rest was left falling in the DEM);
// the servos end at their targets against the soil (within 0.01 rad); the heightfield holds the
// trench (more than 0.02 m³ below the surface between x = -0.15 and 0.7 m; 0.038) and the pile
// poured behind it (more than 0.005 m³ above it at x < -0.15 m; 0.018); the ledger closes
// within 1 %.
TEST(SceneJoints, ShippedExcavatorArmDigsCarriesAndPours) {
  auto s = load_scene_file(std::string(SANDPATCH_SOURCE_DIR) + "/scenes/excavator_arm.json");
  ASSERT_TRUE(s.ok()) << s.message();
  auto w = make_world(*s, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  const double dt = s->simulation.dt;
  ASSERT_TRUE(world.prepare(dt).ok());
  RigidBodyId bucket;
  for (const auto& e : world.entries())
    if (e.name == "bucket") bucket = e.id;
  ASSERT_TRUE(bucket.valid());
  double deepest = 0, drag = 0, lifted = 0, held_after = 0;
  int n_drag = 0, n_lifted = 0, n_after = 0;
  const int frames = int(std::lround(s->simulation.duration / dt));
  for (int k = 0; k < frames; ++k) {
    ASSERT_TRUE(world.step(dt).ok());
    const double t = (k + 1) * dt;
    const World::Contact c = world.contact(bucket);
    deepest = std::max(deepest, c.sinkage);
    if (t >= 2.5 && t <= 4.0) drag += c.granular.force.x(), ++n_drag;
    if (t <= 9.5 && c.sinkage < -0.55 && c.sinkage > -1.0) lifted += -c.granular.force.y() / 9.81, ++n_lifted;
    if (t >= 11.5) held_after += -c.granular.force.y() / 9.81, ++n_after;
  }
  ASSERT_GT(n_drag, 0);
  ASSERT_GT(n_lifted, 20);
  ASSERT_GT(n_after, 0);
  std::printf("deepest %.3f m, drag force %.0f N, soil carried 0.55-1 m up %.1f kg (%d frames), after pouring %.1f kg\n", deepest,
              drag / n_drag, lifted / n_lifted, n_lifted, held_after / n_after);
  EXPECT_GT(deepest, 0.15);
  EXPECT_LT(drag / n_drag, -500.0);
  EXPECT_GT(lifted / n_lifted, 30.0);
  EXPECT_LT(held_after / n_after, 5.0);
  const auto report = world.report();
  const double targets[3] = {-0.25, -0.1, -0.6};  // the last motor phases' target_position
  for (int j = 0; j < 3; ++j)
    EXPECT_NEAR(report["joints"][std::size_t(j)]["angle_rad"].get<double>(), targets[j], 0.01) << report["joints"][std::size_t(j)].dump();

  ASSERT_TRUE(world.demote_all().ok());
  const Heightfield& hf = world.heightfield();
  double trench = 0, pile = 0;
  const double cell = double(hf.spacing()) * hf.spacing();
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i) {
      const double x = hf.origin_x() + i * hf.spacing(), z = hf.origin_z() + j * hf.spacing();
      const double dh = hf.origin_y() + hf.height(i, j) - world.original_height(x, z);
      if (x >= -0.15 && x <= 0.7 && dh < 0) trench -= dh * cell;
      if (x < -0.15 && dh > 0) pile += dh * cell;
    }
  std::printf("trench %.4f m3, pile %.4f m3\n", trench, pile);
  EXPECT_GT(trench, 0.02);
  EXPECT_GT(pile, 0.005);
  const auto rep = world.report();
  ASSERT_EQ(rep["ledger"]["patches"].size(), 1u);
  EXPECT_LT(std::abs(rep["ledger"]["patches"][0]["error_pct"].get<double>()), 1.0);
}
