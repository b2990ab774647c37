// tests bench/stress.cpp: the stress scene (N copies of the first body, arriving one every
// interval, N pool slots, same height above the ground), and its refusals.
#include <gtest/gtest.h>

#include <set>

#include "bench/bench.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;

namespace {

std::string scene_path(const std::string& rel) { return std::string(SANDPATCH_SOURCE_DIR) + "/scenes/" + rel; }

}  // namespace

TEST(Stress, SceneCopiesTheFirstBodyOntoAGrid) {
  auto base = load_scene_file(scene_path("default.json"));
  ASSERT_TRUE(base.ok()) << base.message();
  auto s = make_stress_scene(*base, 5, 1.5, 240);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(s->bodies.size(), 5u);
  EXPECT_EQ(s->simulation.pool.slots, 5);
  EXPECT_NEAR(s->simulation.duration, 240 * base->simulation.dt, 1e-9);
  EXPECT_FALSE(s->outputs.report);
  std::set<std::pair<long, long>> spots;
  for (std::size_t k = 0; k < s->bodies.size(); ++k) {
    const BodyDef& b = s->bodies[k];
    EXPECT_EQ(b.shape.kind, base->bodies[0].shape.kind);
    EXPECT_DOUBLE_EQ(b.shape.radius, base->bodies[0].shape.radius);
    EXPECT_NEAR(b.spawn_time, base->bodies[0].spawn_time + 1.5 * double(k), 1e-12);
    spots.insert({std::lround(b.pose.position[0] * 100), std::lround(b.pose.position[2] * 100)});
    // Patches (footprint + 1 m apron) of neighbours do not overlap: pitch = 2 R + 4 m.
    for (std::size_t m = 0; m < k; ++m) {
      const double dx = b.pose.position[0] - s->bodies[m].pose.position[0];
      const double dz = b.pose.position[2] - s->bodies[m].pose.position[2];
      EXPECT_GE(std::max(std::abs(dx), std::abs(dz)), 2 * base->bodies[0].shape.radius + 4.0 - 1e-9);
    }
  }
  EXPECT_EQ(spots.size(), 5u);
}

TEST(Stress, TooManySimulationsForTheTerrainNamesSims) {
  // A 6 m terrain holds one ball (patch 2.5 m) but not a 2 x 2 grid at 4.5 m pitch.
  auto tiny = parse_scene(R"({"terrain": {"source": {"type": "procedural", "samples_x": 13, "samples_z": 13},
      "spacing": 0.5, "origin": [-3, 0, -3]},
    "materials": [{"name": "sand", "restitution": 0.3}],
    "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.25}, "mass": 10, "pose": {"position": [0, 1, 0]}}]})",
                          "tiny.json", "");
  ASSERT_TRUE(tiny.ok()) << tiny.message();
  EXPECT_TRUE(make_stress_scene(*tiny, 1, 1.0, 100).ok());
  auto r = make_stress_scene(*tiny, 4, 1.0, 100);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("--sims = 4"), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("off the terrain"), std::string::npos) << r.message();
}

TEST(Stress, SceneWithoutBodiesIsRefused) {
  auto none = parse_scene(R"({"terrain": {"source": {"type": "procedural"}}, "materials": [{"name": "sand", "restitution": 0.3}]})",
                          "none.json", "");
  ASSERT_TRUE(none.ok()) << none.message();
  auto r = make_stress_scene(*none, 2, 1.0, 100);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("bodies"), std::string::npos) << r.message();
}

TEST(Stress, BadArgumentsNameOptionValueAndAllowed) {
  StressArgs a;
  a.scene = "x.json";
  EXPECT_EQ(check_stress_args(a), "");
  a.sims = 0;
  EXPECT_NE(check_stress_args(a).find("--sims = 0: must be in [1, 64]"), std::string::npos) << check_stress_args(a);
  a = StressArgs{};
  a.scene = "x.json";
  a.frames = 0;
  EXPECT_NE(check_stress_args(a).find("--frames = 0"), std::string::npos);
  a = StressArgs{};
  a.scene = "x.json";
  a.interval = -1;
  EXPECT_NE(check_stress_args(a).find("--interval = -1"), std::string::npos);
  a = StressArgs{};
  a.scene = "x.json";
  a.frames = 4;
  a.windows = 8;
  EXPECT_NE(check_stress_args(a).find("--windows = 8: must be at most --frames (4)"), std::string::npos)
      << check_stress_args(a);
}
