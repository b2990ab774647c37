// Extremes of a scene run (docs/extremes.md): a body spawned inside the terrain is
// refused before the first frame, with an error naming the body and its position; a body only
// partly in the ground is pushed out; a scene with a flat bedrock hands it to the patches.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "manager/run.hpp"
#include "tests/manager/fresh_dir.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;
using namespace sandpatch;

namespace {

// A 6.4 m flat terrain at y = 1 m, one sphere of radius 0.2 m at height `y` (its centre), no
// patches unless `patches`.
std::string scene_json(double y, bool patches, const std::string& bedrock = "\"soil_depth\": 2.0") {
  return R"({
  "name": "extremes",
  "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.0, "samples_x": 33, "samples_z": 33},
              "spacing": 0.2, )" + bedrock + R"(},
  "materials": [{"name": "sand", "granule_radius": 0.05, "restitution": 0.3}],
  "bodies": [{"name": "buried_ball", "shape": {"type": "sphere", "radius": 0.2}, "mass": 5.0,
              "pose": {"position": [3.2, )" + std::to_string(y) + R"(, 3.2]}, "restitution": 0.0}],
  "simulation": {"dt": 0.01, "duration": 0.5, "granular_patches": )" + (patches ? "true" : "false") + R"(,
                 "pool": {"slots": 1, "granules_per_slot": 3000}},
  "outputs": {"heightfields": []}
})";
}

RunResult run(const std::string& json, const std::string& dir) {
  auto s = parse_scene(json, "extremes.json", "");
  EXPECT_TRUE(s.ok()) << (s.ok() ? "" : s.message());
  if (!s.ok()) return {};
  RunOptions opt;
  opt.out_dir = test::fresh_dir("extremes_run", dir).string();
  opt.progress = ProgressStyle::None;
  opt.threads = 1;
  return run_scene(*s, opt);
}

}  // namespace

// Centre 0.1 m below the surface (above the bedrock, 2 m down, so the parser's bedrock check
// lets it through): refused before the first frame (BadInput, stage "bodies", no report), the
// message names the body, its field, its position and the surface height there. Before, it
// ran: Bullet's heightfield contact pushed the sphere down and it fell for ever.
TEST(ExtremesRun, BodySpawnedInsideTheTerrainIsRefused) {
  const std::string dir = "inside";
  RunResult r = run(scene_json(0.9, false), dir);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_EQ(r.stage, "bodies");
  for (const char* part : {"extremes.json", "bodies[0].pose.position", "[3.2, 0.9, 3.2]", "'buried_ball'",
                           "starts inside the terrain", "world y = 1 m"})
    EXPECT_NE(r.message.find(part), std::string::npos) << part << " not in: " << r.message;
  EXPECT_TRUE(r.report_path.empty());
  EXPECT_FALSE(fs::exists(test::fresh_dir("extremes_run", dir) / "report.json"));
}

// Centre 5 cm above the surface (the sphere 15 cm into the ground): accepted, pushed out by
// the heightfield contact; after 0.5 s its lowest point is within 2 cm of the surface and it
// is nearly at rest.
TEST(ExtremesRun, BodyPartlyInTheGroundIsPushedOut) {
  RunResult r = run(scene_json(1.05, false), "partly");
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  const auto& b = r.report["bodies"][0];
  ASSERT_TRUE(b.contains("position_m")) << b.dump();
  const double low = b["position_m"][1].get<double>() - 0.2;
  EXPECT_NEAR(low, 1.0, 0.02) << "lowest point (m) against the surface at y = 1 m";
}

// A flat bedrock at the surface (terrain.bedrock_height = 1 m: zero soil everywhere): the run
// hands the bedrock to the terrain manager, which makes no patch (no slot is ever used, the
// ledger is empty) and the sphere dropped from 0.3 m lands on the heightfield, its lowest
// point within 2 cm of the surface. Before, the manager ignored bedrock_height and filled a
// patch 0.4 m below the bedrock.
TEST(ExtremesRun, BedrockAtTheSurfaceMakesNoPatch) {
  RunResult r = run(scene_json(1.5, true, "\"bedrock_height\": 1.0"), "bedrock");
  ASSERT_EQ(r.code, ExitCode::Ok) << r.stage << ": " << r.message;
  EXPECT_EQ(r.report["pool"]["peak_slots_used"].get<int>(), 0) << r.report["pool"].dump();
  EXPECT_TRUE(r.report["ledger"]["patches"].empty());
  const double low = r.report["bodies"][0]["position_m"][1].get<double>() - 0.2;
  EXPECT_NEAR(low, 1.0, 0.02);
}
