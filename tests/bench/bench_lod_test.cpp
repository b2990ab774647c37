// tests bench/bench_lod.cpp: the generated scenes are valid and keep the bodies where they are
// while the terrain grows; bad arguments are refused with the option, value and what is allowed.
// (The timings themselves are a program, `sandpatch bench lod`, never a test.)
#include <gtest/gtest.h>

#include "bench/bench.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;

namespace {

SceneDef parse(const nlohmann::json& j) {
  auto s = parse_scene(j.dump(), "<test>", "");
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  return s.ok() ? *s : SceneDef{};
}

}  // namespace

TEST(BenchLod, ScenesValidateForEverySize) {
  for (int n : {64, 512, 8192})
    for (auto kind : {LodBenchScene::Drop, LodBenchScene::Idle, LodBenchScene::Asleep}) {
      const SceneDef s = parse(lod_bench_scene(kind, n, 2));
      EXPECT_EQ(s.terrain.source.procedural.samples_x, n + 1);
      EXPECT_EQ(s.terrain.source.procedural.samples_z, n + 1);
      EXPECT_DOUBLE_EQ(s.terrain.spacing, 0.5);
      EXPECT_FALSE(s.outputs.report);  // the bench writes nothing
    }
  EXPECT_EQ(parse(lod_bench_scene(LodBenchScene::Drop, 512, 0)).bodies.size(), 3u);
  EXPECT_EQ(parse(lod_bench_scene(LodBenchScene::Idle, 512, 0)).bodies.size(), 0u);
  EXPECT_EQ(parse(lod_bench_scene(LodBenchScene::Asleep, 512, 0)).bodies.size(), 1u);
}

TEST(BenchLod, BodiesStayPutWhileTheTerrainGrows) {
  const auto small = lod_bench_scene(LodBenchScene::Drop, 512, 2);
  const auto large = lod_bench_scene(LodBenchScene::Drop, 8192, 2);
  EXPECT_EQ(small["bodies"], large["bodies"]);
  EXPECT_EQ(small["terrain"]["origin"], large["terrain"]["origin"]);
  EXPECT_EQ(small["materials"], large["materials"]);
  EXPECT_EQ(small["simulation"], large["simulation"]);
  // Bodies sit well inside the smallest terrain (64 cells = 32 m) and far from each other's patches.
  const SceneDef s = parse(lod_bench_scene(LodBenchScene::Drop, 64, 2));
  for (const auto& b : s.bodies) {
    EXPECT_GT(b.pose.position[0], 2.0);
    EXPECT_LT(b.pose.position[0], 30.0);
    EXPECT_GT(b.pose.position[2], 2.0);
    EXPECT_LT(b.pose.position[2], 30.0);
  }
}

TEST(BenchLod, FullTerrainBodyCoversTheTerrain) {
  // The ball's patch is its footprint (0.5 m) plus a 1 m apron each side: 2.5 m > the 2 m terrain.
  const SceneDef s = parse(lod_bench_scene(LodBenchScene::Full, 4, 2));
  ASSERT_EQ(s.bodies.size(), 1u);
  EXPECT_DOUBLE_EQ(s.bodies[0].pose.position[0], 1.0);
  EXPECT_DOUBLE_EQ(s.bodies[0].pose.position[2], 1.0);
  EXPECT_LE(4 * 0.5, 2 * s.bodies[0].shape.radius + 2.0);
  const SceneDef slab = parse(lod_bench_scene(LodBenchScene::FullSlab, 8, 2));
  ASSERT_EQ(slab.bodies.size(), 1u);
  EXPECT_DOUBLE_EQ(slab.bodies[0].shape.half_extents[0], 1.0);  // 2 m slab + 2 m apron = the 4 m terrain
}

TEST(BenchLod, BadArgumentsNameOptionValueAndAllowed) {
  BenchLodArgs a;
  EXPECT_EQ(check_bench_lod_args(a), "");
  a.sizes = {512, 32};
  std::string e = check_bench_lod_args(a);
  EXPECT_NE(e.find("--sizes = 32"), std::string::npos) << e;
  EXPECT_NE(e.find("[64, 16384]"), std::string::npos) << e;
  a.sizes = {1024, 512};
  e = check_bench_lod_args(a);
  EXPECT_NE(e.find("ascending"), std::string::npos) << e;
  a.sizes = {};
  EXPECT_NE(check_bench_lod_args(a).find("--sizes"), std::string::npos);
  a = BenchLodArgs{};
  a.seconds = 0;
  e = check_bench_lod_args(a);
  EXPECT_NE(e.find("--seconds = 0"), std::string::npos) << e;
  EXPECT_NE(e.find("(0, 60]"), std::string::npos) << e;
  a = BenchLodArgs{};
  a.threads = -1;
  EXPECT_NE(check_bench_lod_args(a).find("--threads = -1"), std::string::npos);
}
