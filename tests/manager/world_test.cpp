// The frame owner (manager/world.hpp): one step for every caller, one state hash, the checks.
#include "manager/world.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "manager/run.hpp"
#include "manager/scene_world.hpp"
#include "rig.hpp"
#include "sandpatch/sandpatch.hpp"
#include "scene/scene.hpp"

namespace sandpatch {
namespace {

std::unique_ptr<World> flat_world(bool patches) {
  auto w = World::create(test::terrain_8m("flat"), {0, -9.81f, 0});
  EXPECT_TRUE(w.ok()) << (w.ok() ? "" : w.message());
  if (patches) {
    EXPECT_TRUE((*w)->enable_patches(test::small_manager_def()).ok());
  }
  return std::move(*w);
}

// Time after n steps of one dt is n·dt exactly (not a sum that drifts), and a change of dt
// starts from the time reached.
TEST(World, TimeIsStepsTimesDt) {
  auto w = flat_world(false);
  const double dt = 1.0 / 60.0;
  for (int k = 0; k < 600; ++k) ASSERT_TRUE(w->step(dt).ok());
  EXPECT_EQ(w->time(), 600 * dt);
  EXPECT_EQ(w->steps(), 600);
  ASSERT_TRUE(w->step(0.01).ok());
  EXPECT_EQ(w->time(), 600 * dt + 0.01);
  EXPECT_FALSE(w->step(0.0).ok());
  EXPECT_FALSE(w->step(std::numeric_limits<double>::quiet_NaN()).ok());
  EXPECT_FALSE(w->step(dt, 0).ok());
}

// A scheduled body enters in the spawn stage of the first step starting at or after its time.
TEST(World, ScheduledBodiesSpawnOnTime) {
  auto w = flat_world(false);
  const std::size_t k = w->schedule_body(test::sphere_body(0.1f, 1.0f, {4.0, 2.0, 4.0}), 0.1);
  const double dt = 0.05;
  ASSERT_TRUE(w->step(dt).ok());  // starts at 0
  EXPECT_FALSE(w->entries()[k].spawned());
  ASSERT_TRUE(w->step(dt).ok());  // starts at 0.05
  EXPECT_FALSE(w->entries()[k].spawned());
  ASSERT_TRUE(w->step(dt).ok());  // starts at 0.1
  ASSERT_TRUE(w->entries()[k].spawned());
  EXPECT_TRUE(w->alive(w->entries()[k].id));
  EXPECT_EQ(w->report()["counts"]["bodies_spawned"], 1);
}

// A body whose state becomes non-finite stops the step at the stage that made it, naming it.
TEST(World, NonFiniteBodyStopsTheStepNamingItAndTheStage) {
  auto w = flat_world(false);
  auto def = test::sphere_body(0.1f, 1.0f, {4.0, 2.0, 4.0});
  def.name = "ball";
  auto id = w->add_body(def);
  ASSERT_TRUE(id.ok());
  BodyState st = w->bullet().state(*id);
  st.angular_velocity.x() = std::numeric_limits<float>::quiet_NaN();  // the old CLI loop did not check this one
  w->bullet().set_state(*id, st);
  Status s = w->step(1.0 / 60.0);
  ASSERT_FALSE(s.ok());
  EXPECT_STREQ(w->failed_stage(), "bodies");
  EXPECT_NE(s.message().find("'ball'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("bodies stage"), std::string::npos) << s.message();
}

// A ball rolling on the sand at the start (a body at rest asks for no patch): prepare() makes
// its patch whole before the first frame, so frame 0 does no conversion work (without it,
// frame 0 fills the patch at once), the ball does not move during prepare(), and a later
// prepare() does nothing.
TEST(World, PrepareMakesThePatchesNeededAtOnceBeforeTheFirstFrame) {
  for (const bool prepare : {false, true}) {
    SCOPED_TRACE(prepare ? "prepare" : "no prepare");
    auto w = flat_world(true);
    RigidBodyDef ball = test::sphere_body(0.1f, 1.0f, {4.0, 1.1, 4.0});  // on the ground, y = 1 m
    ball.linear_velocity = {1.0f, 0.0f, 0.0f};                           // m/s, rolling
    auto id = w->add_body(ball);
    ASSERT_TRUE(id.ok());
    const auto before = w->bullet().state(*id).position;
    if (prepare) {
      ASSERT_TRUE(w->prepare(1.0 / 60.0).ok());
      EXPECT_GT(w->manager()->granules(), 0) << "the ball's patch is made before the first frame";
      EXPECT_EQ((w->bullet().state(*id).position - before).norm(), 0.0);
      EXPECT_GT(w->prepare_ms(), 0.0);
      const int granules = w->manager()->granules();
      ASSERT_TRUE(w->prepare(1.0 / 60.0).ok());  // once only
      EXPECT_EQ(w->manager()->granules(), granules);
    }
    ASSERT_TRUE(w->step(1.0 / 60.0).ok());
    const auto& work = w->manager()->last_frame_work();
    if (prepare) {
      EXPECT_EQ(work.conversion_parts, 0);
      EXPECT_EQ(work.urgent_fills, 0);
    } else {
      EXPECT_GT(work.urgent_fills, 0) << "without prepare() the first frame fills the ball's patch";
    }
    EXPECT_GT(work.patches_stepped, 0);
  }
  auto w = flat_world(true);
  EXPECT_FALSE(w->prepare(0.0).ok());
  EXPECT_FALSE(w->prepare(std::numeric_limits<double>::quiet_NaN()).ok());
}

// With patches a removed body is gone at once to callers and leaves the Bullet world in the
// next step; the report and the hash no longer see it.
TEST(World, RemovedBodyLeavesAfterTheNextStep) {
  auto w = flat_world(true);
  auto id = w->add_body(test::sphere_body(0.1f, 1.0f, {4.0, 1.3, 4.0}));
  ASSERT_TRUE(id.ok());
  for (int k = 0; k < 10; ++k) ASSERT_TRUE(w->step(1.0 / 60.0).ok());
  w->remove_body(*id);
  EXPECT_FALSE(w->alive(*id));
  EXPECT_TRUE(w->bodies().empty());
  EXPECT_TRUE(w->bullet().alive(*id)) << "still in Bullet until the dem stage lets go of it";
  ASSERT_TRUE(w->step(1.0 / 60.0).ok());
  EXPECT_FALSE(w->bullet().alive(*id));
  EXPECT_EQ(w->report()["counts"]["bodies"], 0);
}

// The same scene through the public API and through `sandpatch run` gives the same final
// state hash: both step a World made from the same definitions.
TEST(World, ApiAndSceneRunGiveTheSameHash) {
  const char* text = R"({
    "name": "two_doors",
    "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.0, "samples_x": 41, "samples_z": 41},
                "spacing": 0.1, "soil_depth": 1.0, "patch_depth": 0.25},
    "materials": [{"name": "sand", "restitution": 0.3, "granule_radius": 0.025, "stiffness": 2e4}],
    "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.1}, "mass": 5.0,
                "pose": {"position": [2.0, 1.3, 2.0]}}],
    "simulation": {"dt": 0.016666666666666666, "duration": 0.5, "threads": 1,
                   "pool": {"slots": 1, "granules_per_slot": 6000}, "lod": {"apron": 0.3}, "frame_budget_ms": "off"},
    "outputs": {"report": false}
  })";
  auto scene = parse_scene(text, "two_doors.json", "");
  ASSERT_TRUE(scene.ok()) << scene.message();
  RunOptions opt;
  opt.out_dir = (std::filesystem::temp_directory_path() / "sandpatch_world_test").string();
  opt.progress = ProgressStyle::None;
  const RunResult run = run_scene(*scene, opt);
  ASSERT_EQ(run.code, ExitCode::Ok) << run.stage << ": " << run.message;
  ASSERT_GT(run.report["counts"]["peak_granules"].get<int>(), 0)
      << "a patch must have lived for the comparison to mean anything";

  api::TerrainDef t;
  t.procedural = "flat";
  t.base_height = 1.0f;
  t.samples_x = t.samples_z = 41;
  t.spacing = 0.1;
  t.soil_depth = 1.0;
  t.patch_depth = 0.25;
  t.material.restitution = 0.3;
  t.slots = 1;
  t.granules_per_slot = 6000;
  t.lod_apron = 0.3;
  t.threads = 1;
  t.frame_budget_ms = std::numeric_limits<double>::infinity();  // as the scene: no budget (its choices follow the clock)
  t.gl_depth_render = true;  // as a scene run: the GL depth render when a context exists, else the CPU one
  auto terrain = api::Terrain::create(t);
  ASSERT_TRUE(terrain.ok()) << terrain.message();
  api::BodyDef b;
  b.name = "ball";
  b.shape.radius = 0.1;
  b.mass = 5.0;
  b.position = {2.0, 1.3, 2.0};
  ASSERT_TRUE(terrain->add_body(b).ok());
  ASSERT_TRUE(terrain->prepare(scene->simulation.dt).ok());  // as `sandpatch run` does before its first frame
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(terrain->step(scene->simulation.dt).ok());
  ASSERT_TRUE(terrain->demote_all().ok());
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(terrain->state_hash()));
  EXPECT_EQ(run.report["final_state_hash"].get<std::string>(), hex);
}

}  // namespace
}  // namespace sandpatch

namespace sandpatch {
namespace {

// A stiff material at a long frame needs more DEM substeps than the default cap: the step is
// refused naming the knobs that trade it, and raising max_substeps lets it run.
TEST(World, TooManyDemSubstepsNameTheKnobs) {
  for (int max_substeps : {0, 400}) {
    SCOPED_TRACE("max_substeps " + std::to_string(max_substeps));
    auto w = World::create(test::terrain_8m("flat"), {0, -9.81f, 0});
    ASSERT_TRUE(w.ok());
    auto def = test::small_manager_def();
    def.material.stiffness = 1.5e5f;  // k_n: t_c / 20 needs ~ 101 substeps of a 1/60 s frame (default cap 64)
    def.max_substeps = max_substeps;
    ASSERT_TRUE((*w)->enable_patches(def).ok());
    (*w)->manager()->request_patch(3.5, 3.5, 4.0, 4.0, 0.0);
    Status s = Ok{};
    for (int k = 0; k < 10 && s.ok(); ++k) s = (*w)->step(1.0 / 60.0);
    if (max_substeps == 0) {
      ASSERT_FALSE(s.ok()) << "the default cap should refuse this frame";
      EXPECT_STREQ((*w)->failed_stage(), "dem");
      EXPECT_NE(s.message().find("simulation.max_substeps (TerrainDef.max_substeps)"), std::string::npos) << s.message();
    } else {
      EXPECT_TRUE(s.ok()) << s.message();
      EXPECT_GT((*w)->manager()->granules(), 0);
    }
  }
}

}  // namespace
}  // namespace sandpatch

namespace sandpatch {
namespace {

// A scene with one 2 kg ball in the air, no gravity, no patches, and `loads` on the ball.
Result<SceneDef> loaded_scene(const std::string& loads) {
  const std::string text = R"({
    "name": "loads",
    "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 0.0, "samples_x": 21, "samples_z": 21},
                "spacing": 0.5},
    "materials": [{"name": "sand", "restitution": 0.3}],
    "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.5}, "mass": 2.0,
                "pose": {"position": [5.0, 5.0, 5.0], "euler_deg": [0.0, 90.0, 0.0]}, "loads": )" +
                           loads + R"(}],
    "simulation": {"dt": 0.05, "duration": 1.0, "granular_patches": false, "gravity": [0.0, 0.0, 0.0]},
    "outputs": {"report": false}
  })";
  return parse_scene(text, "loads.json", "");
}

// A scene's load acts on the steps that start in [from, until) and on no other: 10 N on a
// 2 kg ball from 0.1 s until 0.3 s at dt = 0.05 s acts on the 4 steps starting at 0.1, 0.15,
// 0.2, 0.25 s: v = F · 0.2 s / m = 1 m/s, reached at 0.3 s and kept.
TEST(WorldLoads, SceneLoadsActOnlyInTheirInterval) {
  auto scene = loaded_scene(R"([{"force": [10.0, 0.0, 0.0], "from": 0.1, "until": 0.3}])");
  ASSERT_TRUE(scene.ok()) << scene.message();
  auto w = make_world(*scene, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  for (int k = 0; k < 12; ++k) {
    ASSERT_TRUE(world.step(0.05).ok());
    const float vx = world.bullet().state(world.entries()[0].id).linear_velocity.x();
    const double t = world.time();  // s, the end of step k
    const float expect = t < 0.1 + 1e-9 ? 0.0f : t < 0.3 + 1e-9 ? float(5.0 * (t - 0.1)) : 1.0f;
    EXPECT_NEAR(vx, expect, 1e-5f) << "at t = " << t;
  }
}

// A body-frame load turns with the body: the ball is turned 90° about y, so its body x is
// world −z; a force at a body point adds (R at) × (R F): 1 N along body x at body (0, 0.5, 0)
// gives the torque (0, 0.5, 0) × (0, 0, −1) = (−0.5, 0, 0) N m. A world-frame load with the
// same `at` keeps its direction: (0, 0.5, 0) × (1, 0, 0) = (0, 0, −0.5) N m.
TEST(WorldLoads, BodyFrameLoadsTurnWithTheBody) {
  for (const char* frame : {"body", "world"}) {
    SCOPED_TRACE(frame);
    auto scene = loaded_scene(std::string(R"([{"force": [1.0, 0.0, 0.0], "at": [0.0, 0.5, 0.0], "frame": ")") + frame +
                              R"("}])");
    ASSERT_TRUE(scene.ok()) << scene.message();
    auto w = make_world(*scene, 1, "cpu");
    ASSERT_TRUE(w.ok()) << w.message();
    ASSERT_TRUE((*w)->step(0.05).ok());
    const BodyState s = (*w)->bullet().state((*w)->entries()[0].id);
    const float a = 0.05f / 2.0f;                 // Δv per N over one step (m/s)
    const float b = 0.05f / (0.4f * 2.0f * 0.25f);  // Δω per N m over one step (I = 0.2 kg m²)
    const bool body = std::string(frame) == "body";
    EXPECT_NEAR(s.linear_velocity.x(), body ? 0.0f : a, 1e-5f);
    EXPECT_NEAR(s.linear_velocity.z(), body ? -a : 0.0f, 1e-5f);
    EXPECT_NEAR(s.angular_velocity.x(), body ? -0.5f * b : 0.0f, 1e-4f);
    EXPECT_NEAR(s.angular_velocity.z(), body ? 0.0f : -0.5f * b, 1e-4f);
  }
}

// A scene's impulse is given once, at the start of the first step that starts at or after
// `from`: 4 N s along x on the 2 kg ball from 0.1 s (dt 0.05 s) gives it 2 m/s in the step
// starting at 0.1 s and nothing more after. With `at` (body frame, the ball turned 90° about y)
// it also spins it: J = 1 N s along body x (world −z) at body (0, 0.5, 0) adds
// Δω = (r × J) / I = ((0, 0.5, 0) × (0, 0, −1)) / 0.2 kg m² = (−2.5, 0, 0) rad/s.
TEST(WorldLoads, ASceneImpulseIsGivenOnceAtItsTime) {
  auto scene = loaded_scene(R"([{"impulse": [4.0, 0.0, 0.0], "from": 0.1}])");
  ASSERT_TRUE(scene.ok()) << scene.message();
  auto w = make_world(*scene, 1, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = **w;
  for (int k = 0; k < 8; ++k) {
    ASSERT_TRUE(world.step(0.05).ok());
    const float vx = world.bullet().state(world.entries()[0].id).linear_velocity.x();
    const double t = world.time();  // s, the end of step k
    EXPECT_NEAR(vx, t < 0.15 - 1e-9 ? 0.0f : 2.0f, 1e-5f) << "at t = " << t;
  }
  auto spun = loaded_scene(R"([{"impulse": [1.0, 0.0, 0.0], "at": [0.0, 0.5, 0.0], "frame": "body"}])");
  ASSERT_TRUE(spun.ok()) << spun.message();
  auto w2 = make_world(*spun, 1, "cpu");
  ASSERT_TRUE(w2.ok()) << w2.message();
  for (int k = 0; k < 3; ++k) ASSERT_TRUE((*w2)->step(0.05).ok());
  const BodyState s = (*w2)->bullet().state((*w2)->entries()[0].id);
  EXPECT_NEAR(s.linear_velocity.z(), -0.5f, 1e-5f);
  EXPECT_NEAR(s.linear_velocity.x(), 0.0f, 1e-5f);
  EXPECT_NEAR(s.angular_velocity.x(), -2.5f, 1e-4f);
  EXPECT_NEAR(s.angular_velocity.z(), 0.0f, 1e-4f);
}

// World::apply_force refuses what the API documents (the API's tests name its fields).
TEST(WorldLoads, BadLoadsAreRefused) {
  auto w = flat_world(false);
  auto id = w->add_body(test::sphere_body(0.1f, 1.0f, {4.0, 2.0, 4.0}));
  ASSERT_TRUE(id.ok());
  EXPECT_EQ(w->apply_force(*id, {std::nanf(""), 0, 0}).errors().front().field, "force");
  EXPECT_EQ(w->apply_torque(*id, {0, 2e9f, 0}).errors().front().field, "torque");
  const Eigen::Vector3d far(4.0, 2.0, 4.0 + 2e4);
  EXPECT_EQ(w->apply_impulse(*id, {1, 0, 0}, &far).errors().front().field, "world_point");
  w->remove_body(*id);
  EXPECT_EQ(w->apply_force(*id, {1, 0, 0}).errors().front().field, "body");
}

// The same push through the public API (apply_force / apply_torque before each step) and as a
// scene load gives the same final state hash, a patch included: both land in World.
TEST(WorldLoads, ApiForcesAndSceneLoadsGiveTheSameHash) {
  const char* text = R"({
    "name": "two_doors_pushed",
    "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.0, "samples_x": 41, "samples_z": 41},
                "spacing": 0.1, "soil_depth": 1.0, "patch_depth": 0.25},
    "materials": [{"name": "sand", "restitution": 0.3, "granule_radius": 0.025, "stiffness": 2e4}],
    "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.1}, "mass": 5.0,
                "pose": {"position": [2.0, 1.3, 2.0]},
                "loads": [{"force": [60.0, 0.0, 5.0], "torque": [0.0, 0.2, 0.0], "from": 0.1, "until": 0.4}]}],
    "simulation": {"dt": 0.016666666666666666, "duration": 0.5, "threads": 1, "frame_budget_ms": "off",
                   "pool": {"slots": 1, "granules_per_slot": 6000}, "lod": {"apron": 0.3}},
    "outputs": {"report": false}
  })";
  // (no frame budget in either door: its choices follow the clock, and this compares states)
  auto scene = parse_scene(text, "two_doors_pushed.json", "");
  ASSERT_TRUE(scene.ok()) << scene.message();
  RunOptions opt;
  opt.out_dir = (std::filesystem::temp_directory_path() / "sandpatch_world_loads_test").string();
  opt.progress = ProgressStyle::None;
  const RunResult run = run_scene(*scene, opt);
  ASSERT_EQ(run.code, ExitCode::Ok) << run.stage << ": " << run.message;
  ASSERT_GT(run.report["counts"]["peak_granules"].get<int>(), 0) << "a patch must have lived";
  const auto& ball = run.report["bodies"][0];
  EXPECT_GT(ball["position_m"][0].get<double>(), 2.05) << "the push moved it";

  api::TerrainDef t;
  t.procedural = "flat";
  t.base_height = 1.0f;
  t.samples_x = t.samples_z = 41;
  t.spacing = 0.1;
  t.soil_depth = 1.0;
  t.patch_depth = 0.25;
  t.material.restitution = 0.3;
  t.slots = 1;
  t.granules_per_slot = 6000;
  t.lod_apron = 0.3;
  t.threads = 1;
  t.gl_depth_render = true;
  t.frame_budget_ms = std::numeric_limits<double>::infinity();
  auto terrain = api::Terrain::create(t);
  ASSERT_TRUE(terrain.ok()) << terrain.message();
  api::BodyDef b;
  b.name = "ball";
  b.shape.radius = 0.1;
  b.mass = 5.0;
  b.position = {2.0, 1.3, 2.0};
  auto h = terrain->add_body(b);
  ASSERT_TRUE(h.ok());
  const double dt = scene->simulation.dt;
  for (int k = 0; k < 30; ++k) {
    const double time = terrain->time();
    if (time + 1e-9 >= 0.1 && time + 1e-9 < 0.4) {
      ASSERT_TRUE(terrain->apply_force(*h, {60.0f, 0.0f, 5.0f}).ok());
      ASSERT_TRUE(terrain->apply_torque(*h, {0.0f, 0.2f, 0.0f}).ok());
    }
    ASSERT_TRUE(terrain->step(dt).ok());
  }
  ASSERT_TRUE(terrain->demote_all().ok());
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(terrain->state_hash()));
  EXPECT_EQ(run.report["final_state_hash"].get<std::string>(), hex);
}

}  // namespace
}  // namespace sandpatch
