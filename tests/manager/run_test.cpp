// tests manager/run.cpp and manager/terrain.cpp: a scene run writes a complete report, is
// deterministic, refuses late bad input before writing anything, and lands bodies where
// the heightfield says.
#include <gtest/gtest.h>

#include <cstdlib>

#include <limits>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "manager/run.hpp"
#include "tests/manager/fresh_dir.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;
using namespace sandpatch;

namespace {

SceneDef scene_from(const std::string& json) {
  auto s = parse_scene(json, "test.json", "");
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  return s.ok() ? *s : SceneDef{};
}

// A sphere over a flat terrain at height 1.5 m, origin far from zero; no granular patches
// (this scene tests the rigid-body path on the heightfield).
const char* kFlatScene = R"({
  "name": "flat",
  "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.5, "samples_x": 65, "samples_z": 65},
              "spacing": 0.5, "origin": [5000.0, 100.0, -3000.0], "soil_depth": 1.0},
  "materials": [{"name": "sand", "restitution": 0.3}],
  "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.5}, "mass": 20.0,
              "pose": {"position": [5016.0, 104.0, -2984.0]}, "restitution": 0.0}],
  "simulation": {"dt": 0.01, "duration": 3.0, "granular_patches": false},
  "outputs": {"heightfields": [{"format": "raw_f32", "at_end": true}]}
})";

}  // namespace

TEST(Run, DefaultSceneWritesCompleteReport) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok()) << scene.message();
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", "default").string();
  opt.seconds = 1.0;
  opt.progress = ProgressStyle::None;
  RunResult r = run_scene(*scene, opt);
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  std::ifstream f(fs::path(opt.out_dir) / "report.json");
  ASSERT_TRUE(f.good());
  const auto rep = nlohmann::json::parse(f);
  for (const char* key : {"sandpatch_version", "scene", "stages", "counts", "warnings", "final_state_hash",
                          "real_time_factor", "frame_count", "bodies", "frames", "ledger", "pool", "conversions", "dem"})
    EXPECT_TRUE(rep.contains(key)) << key;
  // The DEM's cost: the total is the patches' sum, its rate sphere-steps over the step calls' wall time.
  const auto& dem = rep["dem"];
  ASSERT_GE(dem["patches"].size(), 1u);
  std::int64_t sphere_steps = 0, substeps = 0;
  for (const auto& p : dem["patches"]) {
    sphere_steps += p["sphere_steps"].get<std::int64_t>();
    substeps += p["substeps"].get<std::int64_t>();
    EXPECT_EQ(p["spheres"].get<int>(), p["granule_spheres"].get<int>() + p["shell_spheres"].get<int>());
  }
  EXPECT_GT(sphere_steps, 0);
  EXPECT_EQ(dem["total"]["sphere_steps"].get<std::int64_t>(), sphere_steps);
  EXPECT_EQ(dem["total"]["substeps"].get<std::int64_t>(), substeps);
  const double wall_s = 1e-3 * dem["total"]["wall_ms"].get<double>();
  EXPECT_NEAR(dem["total"]["sphere_steps_per_s"].get<double>(), double(sphere_steps) / wall_s, 1e-6 * sphere_steps / wall_s);
  EXPECT_EQ(rep["scene"]["hash"], scene->hash);
  EXPECT_EQ(rep["frame_count"].get<long long>(), std::llround(1.0 / scene->simulation.dt));
  EXPECT_TRUE(rep["stages"].contains("bodies"));
  EXPECT_EQ(rep["final_state_hash"].get<std::string>().size(), 16u);
  EXPECT_TRUE(rep["warnings"].is_array());
}

// Same scene and thread count -> same final state hash; and the thread count does not
// change it (Bullet runs single-threaded; the DEM will be held to the same rule).
TEST(Run, FinalStateHashIsDeterministic) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok());
  std::string hashes[3];
  const int threads[3] = {1, 1, 2};
  for (int k = 0; k < 3; ++k) {
    RunOptions opt;
    opt.out_dir = test::fresh_dir("run_test", "det" + std::to_string(k)).string();
    opt.seconds = 1.0;
    opt.threads = threads[k];
    opt.frame_budget_ms = std::numeric_limits<double>::infinity();  // the budget's choices follow the clock
    opt.progress = ProgressStyle::None;
    RunResult r = run_scene(*scene, opt);
    ASSERT_EQ(r.code, ExitCode::Ok) << r.message;
    hashes[k] = r.report["final_state_hash"];
  }
  EXPECT_EQ(hashes[0], hashes[1]);
  EXPECT_EQ(hashes[0], hashes[2]);
}

// A sphere of radius 0.5 m dropped on a flat terrain at world height 100 + 1.5 m, 5 km from
// the origin, rests with its centre at 102.0 m (tolerance 2 cm, Bullet's contact slop), and
// the exported heightfield exists.
TEST(Run, BodyRestsOnTheHeightfieldFarFromOrigin) {
  SceneDef scene = scene_from(kFlatScene);
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", "flat").string();
  opt.progress = ProgressStyle::None;
  RunResult r = run_scene(scene, opt);
  ASSERT_EQ(r.code, ExitCode::Ok) << r.message;
  const auto& b = r.report["bodies"][0];
  EXPECT_NEAR(b["position_m"][1].get<double>(), 102.0, 0.02);
  EXPECT_NEAR(b["position_m"][0].get<double>(), 5016.0, 0.01);
  EXPECT_TRUE(b["at_rest"].get<bool>());
  ASSERT_EQ(r.report["outputs"].size(), 1u);
  EXPECT_TRUE(fs::exists(r.report["outputs"][0].get<std::string>()));
  EXPECT_EQ(fs::file_size(r.report["outputs"][0].get<std::string>()), 65u * 65u * 4u);
}

// A body that starts below the bedrock (surface 101.5 m - soil 1 m = 100.5 m) is bad input:
// refused before the first frame, the message names the body, and nothing is written.
TEST(Run, BodyBelowBedrockIsRefusedAndNothingWritten) {
  std::string json = kFlatScene;
  json.replace(json.find("[5016.0, 104.0, -2984.0]"), 24, "[5016.0, 99.00, -2984.0]");
  SceneDef scene = scene_from(json);
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", "below").string();
  opt.progress = ProgressStyle::None;
  RunResult r = run_scene(scene, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_NE(r.message.find("bodies[0]"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(opt.out_dir));
}

// The number of steps is checked before anything runs: a non-finite --seconds, or more than
// kMaxRunFrames steps from --seconds, --frames or the scene's duration / dt, is bad input and
// writes nothing (a tiny dt inside its range no longer runs "1 frame, 0 s simulated").
TEST(Run, StepCountIsCheckedBeforeTheFirstFrame) {
  const SceneDef scene = scene_from(kFlatScene);
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", "steps").string();
  opt.progress = ProgressStyle::None;
  opt.seconds = std::numeric_limits<double>::quiet_NaN();
  RunResult r = run_scene(scene, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_NE(r.message.find("--seconds"), std::string::npos) << r.message;
  opt.seconds = 1e308;
  r = run_scene(scene, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  opt.seconds = -1;
  opt.frames = 1000000000000LL;
  r = run_scene(scene, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_NE(r.message.find("--frames"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(opt.out_dir));
  // The scene file's own duration / dt: refused by the parser (so `check` refuses it too).
  std::string json = kFlatScene;
  json.replace(json.find("\"dt\": 0.01"), 10, "\"dt\": 1e-320");
  auto tiny = parse_scene(json, "tiny.json", "");
  ASSERT_FALSE(tiny.ok());
  EXPECT_NE(tiny.message().find("simulation.duration"), std::string::npos) << tiny.message();
}

// The default scene for `seconds` on the GL backend, into a fresh folder `dir` (with a final
// picture, final.png, when `image`).
RunResult default_on_gl(const char* dir, double seconds, bool image, RunOptions* used = nullptr) {
  auto scene = load_default_scene();
  EXPECT_TRUE(scene.ok());
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", dir).string();
  opt.seconds = seconds;
  opt.backend = "gl";
  opt.progress = ProgressStyle::None;
  if (image) opt.final_image = (fs::path(opt.out_dir) / "final.png").string();
  if (used) *used = opt;
  return scene.ok() ? run_scene(*scene, opt) : RunResult{};
}

// A slot too large for the GL backend (4,194,304 granules: a grid of 96 million cells, past
// its 2^26, and 5.4 GB of contact springs, past any driver's storage block: llvmpipe's 128 MiB,
// NVIDIA's 2 GiB) is refused as bad input, before its buffers are allocated, naming the
// scene's pool field that sets the capacity (the GL simulation itself can name only its own
// SimulationDef fields).
TEST(Run, GlPoolTooLargeForTheDriverNamesThePoolField) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok());
  scene->terrain.slots = 1;  // (the pool's whole limit: 4,194,304 granules)
  scene->terrain.granules_per_slot = 4194304;
  RunOptions opt;
  opt.out_dir = test::fresh_dir("run_test", "gl_pool").string();
  opt.seconds = 0.1;
  opt.backend = "gl";
  opt.progress = ProgressStyle::None;
  const RunResult r = run_scene(*scene, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput) << r.stage << ": " << r.message;
  EXPECT_NE(r.message.find("simulation.pool.granules_per_slot = 4194304"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("lower them, or use the CPU backend"), std::string::npos) << r.message;
}

// `run --backend gl`: the terrain manager's pool runs on the GL compute-shader backend
// (llvmpipe in CI); a patch is promoted, simulated and demoted, and the report says so; the
// final picture draws the granules straight from the simulation's buffer (shared context).
TEST(Run, GlBackendDrivesThePatches) {
  RunOptions opt;
  RunResult r = default_on_gl("gl", 0.3, true, &opt);
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  EXPECT_EQ(r.report["backend"], "gl");
  EXPECT_GT(fs::file_size(opt.final_image), 1000u);
  EXPECT_GT(r.report["counts"]["peak_granules"].get<int>(), 100);
  EXPECT_EQ(r.report["ledger"]["patches"].size(), 1u);
  EXPECT_GT(r.report["stages"]["dem"]["total_ms"].get<double>(), 0.0);
  // the GL step's host time is reported: issuing the substeps and the read-back, within the
  // step calls' wall time
  const auto& st = r.report["dem"]["total"]["stage_ms"];
  EXPECT_GT(st["gl_submit"].get<double>(), 0.0);
  EXPECT_GT(st["gl_readback"].get<double>(), 0.0);
  EXPECT_LE(st["gl_submit"].get<double>() + st["gl_readback"].get<double>(),
            r.report["dem"]["total"]["wall_ms"].get<double>());
  EXPECT_FALSE(r.report["dem"]["total"].contains("gl_kernel_ms")) << "only with SANDPATCH_GL_PROFILE";
}

// With SANDPATCH_GL_PROFILE set, every GL dispatch is timed on the GPU and the report sums each
// kernel's time over the run (dem.total.gl_kernel_ms; llvmpipe's timer queries read about 0).
TEST(Run, GlProfileReportsEveryKernel) {
  ::setenv("SANDPATCH_GL_PROFILE", "1", 1);
  RunResult r = default_on_gl("gl_profile", 0.2, false);
  ::unsetenv("SANDPATCH_GL_PROFILE");
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  const auto& t = r.report["dem"]["total"];
  ASSERT_TRUE(t.contains("gl_kernel_ms")) << t.dump();
  for (const char* k : {"dem/force.comp", "dem/bodies.comp", "dem/bodies.comp SP_WIDE_PASS", "dem/grid_count.comp"}) {
    ASSERT_TRUE(t["gl_kernel_ms"].contains(k)) << k << " in " << t["gl_kernel_ms"].dump();
    EXPECT_GE(t["gl_kernel_ms"][k].get<double>(), 0.0);
  }
}
