// tests apps/sandpatch/main.cpp end to end: the program as a user runs it, its exit codes
// (0 ok, 1 runtime failure, 2 bad input) and its messages.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include "tests/apps/process.hpp"

namespace fs = std::filesystem;

namespace {

using apps_test::Outcome;
using apps_test::sandpatch;

std::string scene(const std::string& rel) { return std::string(SANDPATCH_SOURCE_DIR) + "/scenes/" + rel; }

}  // namespace

TEST(Cli, RunDefaultSceneWritesValidReport) {
  const fs::path out = fs::temp_directory_path() / "sandpatch_cli_default";
  fs::remove_all(out);
  Outcome o = sandpatch("run --seconds 1 --out " + out.string());
  ASSERT_EQ(o.code, 0) << o.output;
  EXPECT_NE(o.output.find("real-time factor"), std::string::npos) << o.output;
  std::ifstream f(out / "report.json");
  ASSERT_TRUE(f.good());
  const auto rep = nlohmann::json::parse(f);
  EXPECT_EQ(rep["scene"]["name"], "default");
  EXPECT_GT(rep["real_time_factor"].get<double>(), 0.0);
  // The frames alone: within the run's wall, which also writes the outputs between frames (the
  // default scene writes an image at t = 0), and holding at least the DEM's time (it steps only
  // in frames); so at least the whole run's factor.
  const double frames_s = rep["frames_wall_s"].get<double>(), wall_s = rep["wall_s"].get<double>();
  const double dem_s = rep["stages"]["dem"]["total_ms"].get<double>() * 1e-3;
  EXPECT_GT(frames_s, 0.0);
  EXPECT_LE(dem_s, frames_s);
  EXPECT_LT(frames_s, wall_s);
  EXPECT_NEAR(rep["frames_real_time_factor"].get<double>() * frames_s, rep["simulated_s"].get<double>(), 1e-9);
  EXPECT_GE(rep["frames_real_time_factor"].get<double>(), rep["real_time_factor"].get<double>());
  EXPECT_NE(o.output.find("the frames alone"), std::string::npos) << o.output;
  // Not a terminal: progress comes as plain lines.
  EXPECT_NE(o.output.find("progress 100%"), std::string::npos) << o.output;
}

TEST(Cli, RunNamedSceneFile) {
  const fs::path out = fs::temp_directory_path() / "sandpatch_cli_barrel";
  fs::remove_all(out);
  Outcome o = sandpatch("run " + scene("barrel_drop.json") + " --frames 30 --quiet --out " + out.string());
  ASSERT_EQ(o.code, 0) << o.output;
  EXPECT_TRUE(fs::exists(out / "report.json"));
}

TEST(Cli, CheckAcceptsGoodAndRefusesBrokenScenes) {
  EXPECT_EQ(sandpatch("check " + scene("default.json")).code, 0);
  Outcome o = sandpatch("check " + scene("broken/unknown_key.json"));
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("unknown_key.json"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("did you mean"), std::string::npos) << o.output;
}

// check --tiles makes the patch pool as run does: the default scene's tiles (settled by the
// build into the tests' cache, so read from it here) are ready, and a broken scene is still
// refused before anything is settled.
TEST(Cli, CheckTilesReadiesTheScenesTiles) {
  Outcome o = sandpatch("check --tiles " + scene("default.json"));
  ASSERT_EQ(o.code, 0) << o.output;
  EXPECT_NE(o.output.find("granule tiles ready in"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find(" from disk, 0 settled now"), std::string::npos) << "the build settled them: " << o.output;
  Outcome bad = sandpatch("check --tiles " + scene("broken/unknown_key.json"));
  EXPECT_EQ(bad.code, 2) << bad.output;
  EXPECT_EQ(bad.output.find("granule tiles ready"), std::string::npos) << bad.output;
}

TEST(Cli, EveryBrokenSceneExitsWithTwo) {
  int n = 0;
  for (const auto& e : fs::directory_iterator(scene("broken"))) {
    if (e.path().extension() != ".json") continue;
    ++n;
    Outcome o = sandpatch("run " + e.path().string() + " --quiet --out " +
                          (fs::temp_directory_path() / "sandpatch_cli_broken").string());
    EXPECT_EQ(o.code, 2) << e.path() << "\n" << o.output;
    EXPECT_NE(o.output.find(e.path().filename().string()), std::string::npos) << o.output;
  }
  EXPECT_GE(n, 8);
}

TEST(Cli, BadOptionsExitWithTwo) {
  EXPECT_EQ(sandpatch("run --backend vulkan").code, 2);
  EXPECT_EQ(sandpatch("run --seconds 1 --frames 3").code, 2);
  EXPECT_EQ(sandpatch("run --threads -1").code, 2);
  EXPECT_EQ(sandpatch("frobnicate").code, 2);
  EXPECT_EQ(sandpatch("check /nonexistent/scene.json").code, 2);
  EXPECT_EQ(sandpatch("bench dem --granules 10 --idle-sims 2").code, 2);  // a GL backend option
  EXPECT_EQ(sandpatch("bench dem --backend gl --idle-sims 17").code, 2);
  EXPECT_EQ(sandpatch("bench dem --granules 10 --capacity 100").code, 2);  // a GL backend option
  EXPECT_EQ(sandpatch("bench dem --backend gl --granules 200 --capacity 100").code, 2);  // below the bed
  EXPECT_EQ(sandpatch("render --at 0.1 --backend vulkan").code, 2);
  EXPECT_EQ(sandpatch("render --at 0.1 --threads -1").code, 2);
  Outcome o = sandpatch("render --at 0.1 --frame-budget nope");
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("--frame-budget"), std::string::npos) << o.output;
}

TEST(Cli, InfoNamesTheRenderer) {
  Outcome o = sandpatch("info");
  ASSERT_EQ(o.code, 0) << o.output;
  EXPECT_NE(o.output.find("OpenGL: "), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("Bullet"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("threads"), std::string::npos) << o.output;
}

// ---- check runs what run runs before frame 0 (docs/reliability.md) ----

namespace {
std::string data(const std::string& rel) { return std::string(SANDPATCH_SOURCE_DIR) + "/tests/apps/data/" + rel; }
}  // namespace

TEST(CliReliability, CheckLoadsTheHeightmapAsRunDoes) {
  // An ESRI corner of 1e300 m: the scene file is fine, the heightmap's geometry is not.
  for (const std::string& cmd : {"check " + data("esri_corner.json"), "run " + data("esri_corner.json") + " --quiet --out /tmp/sandpatch_cli_rel"}) {
    Outcome o = sandpatch(cmd);
    EXPECT_EQ(o.code, 2) << cmd << o.output;
    EXPECT_NE(o.output.find("corner_1e300.asc"), std::string::npos) << o.output;
    EXPECT_NE(o.output.find("xllcorner"), std::string::npos) << o.output;
  }
  // A NODATA cell: refused naming the file, row and column, by check as by run.
  Outcome o = sandpatch("check " + data("esri_nodata.json"));
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("nodata_cell.asc"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("NODATA"), std::string::npos) << o.output;
}

TEST(CliReliability, CheckRefusesABodyInsideTheTerrain) {
  Outcome o = sandpatch("check " + data("body_inside.json"));
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("inside the terrain"), std::string::npos) << o.output;
}

TEST(CliReliability, EveryShippedSceneChecksValid) {
  for (const auto& e : fs::directory_iterator(scene(""))) {
    if (e.path().extension() != ".json") continue;
    Outcome o = sandpatch("check " + e.path().string());
    EXPECT_EQ(o.code, 0) << e.path() << "\n" << o.output;
  }
}

TEST(CliReliability, RunCreatesTheFoldersOfOutputPatterns) {
  // tests/scene/data/full.json writes heightfields to "hf/{frame}.{ext}" (a folder) at the end.
  const fs::path out = fs::temp_directory_path() / "sandpatch_cli_full";
  fs::remove_all(out);
  Outcome o = sandpatch("run " + std::string(SANDPATCH_SOURCE_DIR) + "/tests/scene/data/full.json --frames 2 --quiet --out " +
                        out.string());
  ASSERT_EQ(o.code, 0) << o.output;
  bool found = false;
  for (const auto& e : fs::directory_iterator(out / "hf")) found = found || e.path().extension() == ".raw";
  EXPECT_TRUE(found);
}

TEST(CliReliability, ABodyFasterThanThePatchesIsAWarning) {
  // 300 m/s a few centimetres above the ground: the run completes and says so in report.json.
  const fs::path out = fs::temp_directory_path() / "sandpatch_cli_skim";
  fs::remove_all(out);
  Outcome o = sandpatch("run " + data("skimming.json") + " --quiet --out " + out.string());
  ASSERT_EQ(o.code, 0) << o.output;
  std::ifstream f(out / "report.json");
  ASSERT_TRUE(f.good());
  const auto rep = nlohmann::json::parse(f);
  std::string warnings = rep["warnings"].dump();
  EXPECT_NE(warnings.find("bodies.bullet: reached"), std::string::npos) << warnings;
  EXPECT_NE(warnings.find("faster than the patches can follow"), std::string::npos) << warnings;
}

TEST(CliReliability, RunStepCountsAreChecked) {
  // Regressions of the step count check: non-finite or huge --seconds, a tiny dt.
  EXPECT_EQ(sandpatch("run --seconds nan --quiet").code, 2);
  EXPECT_EQ(sandpatch("run --seconds 1e308 --quiet").code, 2);
  EXPECT_EQ(sandpatch("check " + scene("broken/deep_nesting.json")).code, 2);
}

// --frame-budget: a number of ms > 0 or off; anything else is bad input (exit 2) naming it.
TEST(Cli, FrameBudgetOption) {
  const fs::path out = fs::temp_directory_path() / "sandpatch_cli_budget";
  fs::remove_all(out);
  for (const char* bad : {"0", "-3", "fast", "nan"}) {
    Outcome o = sandpatch(std::string("run --frames 2 --quiet --frame-budget ") + bad + " --out " + out.string());
    EXPECT_EQ(o.code, 2) << bad << ": " << o.output;
    EXPECT_NE(o.output.find("--frame-budget"), std::string::npos) << o.output;
  }
  Outcome o = sandpatch("run --frames 2 --quiet --frame-budget off --out " + out.string());
  ASSERT_EQ(o.code, 0) << o.output;
  std::ifstream f(out / "report.json");
  const auto rep = nlohmann::json::parse(f);
  EXPECT_EQ(rep["frames"]["budget_ms"], "off");
  EXPECT_FALSE(rep["budget"]["on"].get<bool>());
}
