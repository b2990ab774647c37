// tests bench/stress.cpp: the stress scene (N copies of the first body, arriving one every
// interval, N pool slots, same height above the ground), its refusals, and the per-frame
// samples it is measured with (run_scene's RunOptions::on_frame).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <set>
#include <vector>

#include "bench/bench.hpp"
#include "manager/run.hpp"
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
  EXPECT_EQ(s->terrain.slots, 5);
  EXPECT_NEAR(s->simulation.duration, 240 * base->simulation.dt, 1e-9);
  EXPECT_FALSE(s->outputs.report);
  std::set<std::pair<long, long>> spots;
  for (std::size_t k = 0; k < s->bodies.size(); ++k) {
    const BodyDef& b = s->bodies[k];
    EXPECT_EQ(b.shape.kind, base->bodies[0].shape.kind);
    EXPECT_DOUBLE_EQ(b.shape.radius, base->bodies[0].shape.radius);
    EXPECT_NEAR(b.spawn_time, base->bodies[0].spawn_time + 1.5 * double(k), 1e-12);
    spots.insert({std::lround(b.position[0] * 100), std::lround(b.position[2] * 100)});
    // Patches (footprint + 1 m apron) of neighbours do not overlap: pitch = 2 R + 4 m.
    for (std::size_t m = 0; m < k; ++m) {
      const double dx = b.position[0] - s->bodies[m].position[0];
      const double dz = b.position[2] - s->bodies[m].position[2];
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
  a.windows = 8;  // deprecated, ignored
  EXPECT_EQ(check_stress_args(a), "");
}

namespace {

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

// The per-frame hook: one sample a frame, in order, at the frame's end time; one Leach
// scenario 3 ball (464 granules a patch) lands, its patch fills, simulates and falls asleep.
// An all-asleep frame's DEM stage does no work: its dem_ms is a small fraction of an active
// frame's (sleeping costs nothing, docs/stress.md).
TEST(Stress, PerFrameSamplesShowSleepingPatchesCostNoDem) {
  auto base = load_scene_file(scene_path("leach_3_ten_bodies.json"));
  ASSERT_TRUE(base.ok()) << base.message();
  const long long frames = 480;  // 4 s at 120 Hz
  auto s = make_stress_scene(*base, 1, 0.0, frames);
  ASSERT_TRUE(s.ok()) << s.message();
  std::vector<FrameSample> samples;
  RunOptions o;
  o.out_dir = (std::filesystem::temp_directory_path() / "sandpatch_stress_per_frame").string();
  o.frames = frames;
  o.threads = 1;
  o.progress = ProgressStyle::None;
  o.on_frame = [&](const FrameSample& f) { samples.push_back(f); };
  RunResult r = run_scene(*s, o);
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  ASSERT_EQ(samples.size(), std::size_t(frames));
  std::vector<double> active_dem, asleep_dem, active_ms, asleep_ms;
  for (std::size_t k = 0; k < samples.size(); ++k) {
    const FrameSample& f = samples[k];
    EXPECT_EQ(f.frame, (long long)k);
    EXPECT_NEAR(f.time_s, double(k + 1) * s->simulation.dt, 1e-9);
    EXPECT_GT(f.frame_ms, 0.0);
    EXPECT_GE(f.dem_ms, 0.0);
    EXPECT_LE(f.dem_ms, f.frame_ms);
    EXPECT_EQ(f.pool_bytes, samples.front().pool_bytes) << "the pool's capacity is fixed";
    EXPECT_LE(f.patches_filling + f.patches_active + f.patches_asleep, 1);
    if (f.patches_active >= 1) active_dem.push_back(f.dem_ms), active_ms.push_back(f.frame_ms);
    if (f.patches_asleep >= 1 && f.patches_active == 0 && f.patches_filling == 0)
      asleep_dem.push_back(f.dem_ms), asleep_ms.push_back(f.frame_ms);
  }
  // 1 slot of 4096 granules: (4 × 4096 + 8192) particles and 4160 bodies of fixed size.
  EXPECT_GT(samples.front().pool_bytes, std::int64_t(24576) * 64);
  ASSERT_GE(active_dem.size(), 10u) << "the patch never simulated";
  ASSERT_GE(asleep_dem.size(), 10u) << "the patch did not fall asleep within " << frames << " frames";
  EXPECT_GT(median(active_dem), 0.0);
  EXPECT_LT(median(asleep_dem), 0.1 * median(active_dem))
      << "asleep " << median(asleep_dem) << " ms vs active " << median(active_dem) << " ms of DEM a frame";
}
