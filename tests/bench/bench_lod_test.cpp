// tests bench/bench_lod.cpp: the generated scenes are valid and keep the bodies where they are
// while the terrain grows; bad arguments are refused with the option, value and what is allowed;
// a two-frame --quick run interleaves the sizes and reports the issue's JSON shape. (The
// timings themselves are a program, `sandpatch bench lod`, never asserted by a test.)
#include <gtest/gtest.h>

#include <cmath>

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
      EXPECT_EQ(s.terrain.samples_x, n + 1);
      EXPECT_EQ(s.terrain.samples_z, n + 1);
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
    EXPECT_GT(b.position[0], 2.0);
    EXPECT_LT(b.position[0], 30.0);
    EXPECT_GT(b.position[2], 2.0);
    EXPECT_LT(b.position[2], 30.0);
  }
}

TEST(BenchLod, FullTerrainBodyCoversTheTerrain) {
  // The ball's patch is its footprint (0.5 m) plus a 1 m apron each side: 2.5 m > the 2 m terrain.
  const SceneDef s = parse(lod_bench_scene(LodBenchScene::Full, 4, 2));
  ASSERT_EQ(s.bodies.size(), 1u);
  EXPECT_DOUBLE_EQ(s.bodies[0].position[0], 1.0);
  EXPECT_DOUBLE_EQ(s.bodies[0].position[2], 1.0);
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
  a = BenchLodArgs{};
  a.window = 2.0;  // longer than --seconds (1)
  e = check_bench_lod_args(a);
  EXPECT_NE(e.find("--window = 2"), std::string::npos) << e;
  EXPECT_NE(e.find("--seconds]"), std::string::npos) << e;
  a.window = 0.001;  // less than one frame
  EXPECT_NE(check_bench_lod_args(a).find("--window = 0.001"), std::string::npos);
}

// Two sizes set up in one process and advanced one frame each in turn, twice: the JSON line
// has the issue's shape ({"results": [{"terrain", "wall_s_per_sim_s"}], "lod_off"}); both
// sizes simulated the same 2 frames with the same DEM state (the same work: the bodies and
// patches sit in the same place), Bullet updated the same bounds a step at both sizes and none
// on the idle terrain; the LOD-off granule count follows G = (N·s)² d φ / (16/3 π r³)
// (relative 1e-9).
TEST(BenchLod, QuickRunInterleavesSizesAndReportsTheIssueShape) {
  BenchLodArgs a;
  a.sizes = {64, 128};
  a.seconds = 2.0 / 120.0;
  a.window = 1.0 / 120.0;
  a.threads = 2;
  a.quick = true;
  a.json = true;
  testing::internal::CaptureStdout();
  const int code = run_bench_lod(a);
  const std::string out = testing::internal::GetCapturedStdout();
  ASSERT_EQ(code, 0) << out;
  const std::string last = out.substr(out.rfind('\n', out.size() - 2) + 1);
  const auto j = nlohmann::json::parse(last);
  ASSERT_EQ(j["results"].size(), 2u);
  EXPECT_TRUE(j["method"]["interleaved"].get<bool>());
  EXPECT_EQ(j["method"]["rounds"], 2);
  for (int k = 0; k < 2; ++k) {
    const auto& r = j["results"][k];
    EXPECT_EQ(r["terrain"], a.sizes[k]);
    EXPECT_GT(r["wall_s_per_sim_s"].get<double>(), 0.0);
    EXPECT_GT(r["cpu_s_per_sim_s"].get<double>(), 0.0);
    EXPECT_NEAR(r["simulated_s"].get<double>(), 2.0 / 120.0, 1e-12);
    EXPECT_EQ(r["window_wall_over_smallest"]["windows"], 2);
    EXPECT_TRUE(r["stage_ms_per_sim_s"].contains("dem"));
    EXPECT_TRUE(r["stage_ms_per_sim_s"].contains("bodies"));
    EXPECT_EQ(r["bullet"]["aabb_updates_per_step"], j["results"][0]["bullet"]["aabb_updates_per_step"]);
  }
  EXPECT_TRUE(j["same_dem_state_every_size"].get<bool>());
  EXPECT_EQ(j["idle"]["bullet"]["aabb_updates_per_step"], 0);
  const auto& lod_off = j["lod_off"];
  const double phi = lod_off["phi"].get<double>(), r = lod_off["granule_radius_m"].get<double>();
  const double g64 = std::pow(64 * 0.5, 2) * lod_off["depth_m"].get<double>() * phi / (16.0 / 3.0 * M_PI * r * r * r);
  EXPECT_NEAR(lod_off["estimates"][0]["granules"].get<double>() / g64, 1.0, 1e-9);
}
