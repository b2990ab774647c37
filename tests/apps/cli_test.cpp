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

namespace fs = std::filesystem;

namespace {

struct Outcome {
  int code = -1;
  std::string output;  // stdout and stderr together
};

Outcome sandpatch(const std::string& args) {
  const std::string cmd = std::string(SANDPATCH_EXE) + " " + args + " 2>&1";
  Outcome o;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return o;
  std::array<char, 4096> buf;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), p)) o.output.append(buf.data(), n);
  const int status = pclose(p);
  o.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return o;
}

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
}

TEST(Cli, InfoNamesTheRenderer) {
  Outcome o = sandpatch("info");
  ASSERT_EQ(o.code, 0) << o.output;
  EXPECT_NE(o.output.find("OpenGL: "), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("Bullet"), std::string::npos) << o.output;
  EXPECT_NE(o.output.find("threads"), std::string::npos) << o.output;
}
