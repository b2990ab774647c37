// tests scene files' kinematic and static bodies (scene/scene.cpp, manager/scene_world.cpp)
// and the run's time series (manager/run_outputs.cpp RunCsv, manager/run.cpp): bad motion,
// mass and keyframes refused naming the field; a run's CSV has its header, one row per frame
// per body, a last row equal to report.json's final pose; a refused run leaves no CSV; the
// shipped scenes/plate_press.json parses.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "manager/run.hpp"
#include "tests/manager/fresh_dir.hpp"
#include "manager/run_outputs.hpp"
#include "scene/scene.hpp"

namespace fs = std::filesystem;
using namespace sandpatch;

namespace {

// A flat 16 m terrain at y = 1 m without patches, and `bodies` (a JSON array's items).
std::string scene_with(const std::string& bodies, const std::string& outputs = R"({"report": true})") {
  return R"({"name": "machines",
  "terrain": {"source": {"type": "procedural", "kind": "flat", "height": 1.0, "samples_x": 33, "samples_z": 33},
              "spacing": 0.5, "soil_depth": 1.0},
  "materials": [{"name": "sand", "restitution": 0.3}],
  "bodies": [)" + bodies + R"(],
  "simulation": {"dt": 0.016666666666666666, "duration": 1.0, "granular_patches": false},
  "outputs": )" + outputs + "}";
}

const char* kBodies = R"(
  {"name": "bucket", "motion": "kinematic", "shape": {"type": "box", "half_extents": [0.3, 0.2, 0.3]},
   "keyframes": [{"t": 0.0, "position": [4.0, 2.0, 8.0]},
                 {"t": 0.5, "position": [6.0, 1.5, 8.0], "euler_deg": [0, 45, 0]},
                 {"t": 1.0, "position": [6.0, 1.5, 9.0], "euler_deg": [0, 90, 0]}]},
  {"name": "block", "motion": "static", "shape": {"type": "box", "half_extents": [0.5, 0.5, 0.5]},
   "pose": {"position": [10.0, 1.5, 8.0]}},
  {"name": "ball, red", "shape": {"type": "sphere", "radius": 0.2}, "mass": 3.0,
   "pose": {"position": [10.0, 3.0, 8.0]}})";

bool has_field(const std::vector<Error>& es, const std::string& field) {
  for (const Error& e : es)
    if (e.field.find(field) != std::string::npos) return true;
  return false;
}

std::vector<std::string> lines_of(const fs::path& p) {
  std::ifstream in(p);
  std::vector<std::string> out;
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

std::vector<std::string> split_csv(const std::string& line) {  // (quoted fields hold no quotes here)
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (char c : line) {
    if (c == '"') quoted = !quoted;
    else if (c == ',' && !quoted) out.push_back(cur), cur.clear();
    else cur += c;
  }
  out.push_back(cur);
  return out;
}

}  // namespace

// The fields parse into the scene and survive its canonical JSON.
TEST(SceneMotion, MotionAndKeyframesParse) {
  auto s = parse_scene(scene_with(kBodies), "m.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(s->bodies.size(), 3u);
  EXPECT_EQ(s->bodies[0].motion, MotionKind::Kinematic);
  ASSERT_EQ(s->bodies[0].keyframes.size(), 3u);
  EXPECT_NEAR(s->bodies[0].keyframes[2].orientation[2], std::sin(M_PI / 4), 1e-12);  // 90° about y
  EXPECT_EQ(s->bodies[0].position[0], 4.0) << "the pose at spawn_time is the first keyframe's";
  EXPECT_EQ(s->bodies[1].motion, MotionKind::Static);
  EXPECT_EQ(s->bodies[2].motion, MotionKind::Dynamic);
  auto again = parse_scene(scene_to_json(*s).dump(), "m2.json", "");
  ASSERT_TRUE(again.ok()) << again.message();
  EXPECT_EQ(scene_to_json(*again), scene_to_json(*s));
}

// Each refused naming the field: an unknown motion, a mass or loads for a body that is not
// dynamic, keyframes on a dynamic body, keyframe times not increasing, a non-finite or
// missing keyframe value, a pose beside keyframes, a keyframe through the bedrock (run).
TEST(SceneMotion, BadMotionAndKeyframesAreRefusedNamingTheField) {
  auto refused = [](const std::string& body, const std::string& field) {
    auto s = parse_scene(scene_with(body), "bad.json", "");
    ASSERT_FALSE(s.ok()) << body;
    EXPECT_TRUE(has_field(s.errors(), field)) << s.message();
    EXPECT_EQ(s.errors().front().file, "bad.json");
  };
  const std::string box = R"("shape": {"type": "box", "half_extents": [0.2, 0.2, 0.2]})";
  refused(R"({"name": "a", "motion": "flying", )" + box + R"(, "mass": 1})", "bodies[0].motion");
  refused(R"({"name": "a", "motion": "static", )" + box + R"(, "mass": 1})", "bodies[0].mass");
  refused(R"({"name": "a", "motion": "kinematic", )" + box + R"(, "density": 1000})", "bodies[0].density");
  refused(R"({"name": "a", "motion": "kinematic", )" + box + R"(, "loads": [{"force": [1, 0, 0]}]})", "bodies[0].loads");
  refused(R"({"name": "a", "motion": "static", )" + box + R"(, "linear_velocity": [1, 0, 0]})", "bodies[0].linear_velocity");
  refused(R"({"name": "a", )" + box + R"(, "mass": 1, "keyframes": [{"t": 0, "position": [1, 2, 1]}]})", "bodies[0].keyframes");
  refused(R"({"name": "a", "motion": "kinematic", )" + box +
              R"(, "keyframes": [{"t": 1, "position": [1, 2, 1]}, {"t": 1, "position": [1, 2, 2]}]})",
          "bodies[0].keyframes[1].t");
  refused(R"({"name": "a", "motion": "kinematic", )" + box +
              R"(, "keyframes": [{"t": 0, "position": [1, 2, 1]}, {"t": 1e999, "position": [1, 2, 2]}]})",
          "bodies[0].keyframes[1].t");
  refused(R"({"name": "a", "motion": "kinematic", )" + box +
              R"(, "keyframes": [{"t": 0, "position": [1, "NaN", 1]}]})",
          "bodies[0].keyframes[0].position");
  refused(R"({"name": "a", "motion": "kinematic", )" + box + R"(, "keyframes": [{"t": 0}]})", "bodies[0].keyframes[0].position");
  refused(R"({"name": "a", "motion": "kinematic", )" + box +
              R"(, "pose": {"position": [1, 2, 1]}, "keyframes": [{"t": 0, "position": [1, 2, 1]}]})",
          "bodies[0].pose");
  refused(R"({"name": "a", "motion": "kinematic", )" + box + R"(, "keyframes": []})", "bodies[0].keyframes");

  // Through the bedrock (surface 1 m − soil_depth 1 m = 0): refused before the first frame,
  // and nothing written (no CSV, no .part file).
  auto s = parse_scene(scene_with(R"({"name": "blade", "motion": "kinematic", )" + box +
                                      R"(, "keyframes": [{"t": 0, "position": [5, 1.5, 5]}, {"t": 1, "position": [5, -0.1, 5]}]})",
                                  R"({"report": true, "csv": "series.csv"})"),
                        "deep.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  const fs::path dir = test::fresh_dir("machines_test", "bedrock");
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.progress = ProgressStyle::None;
  RunResult r = run_scene(*s, opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_NE(r.message.find("bodies[0].keyframes[1].position"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(dir / "series.csv"));
  EXPECT_FALSE(fs::exists(dir / "series.csv.part"));
  EXPECT_FALSE(fs::exists(dir / "report.json"));
}

// A run of one second (60 frames) with the kinematic bucket, the static block and a ball that
// falls onto the block: the CSV has the documented header, 60 × 3 body rows in time order
// (the name with a comma quoted), the bucket at its keyframes at t = 0.5 s and 1 s within
// 1e-6 m, the block unmoved, and the last row of each body equal to report.json's final pose.
TEST(RunCsv, OneRowPerFramePerBodyAndTheLastMatchesTheReport) {
  auto s = parse_scene(scene_with(kBodies, R"({"report": true, "csv": "series/bodies.csv"})"), "m.json", "");
  ASSERT_TRUE(s.ok()) << s.message();
  const fs::path dir = test::fresh_dir("machines_test", "csv");
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.progress = ProgressStyle::None;
  RunResult r = run_scene(*s, opt);
  ASSERT_EQ(r.code, ExitCode::Ok) << r.message;
  const auto rows = lines_of(dir / "series" / "bodies.csv");
  ASSERT_EQ(rows.size(), 1u + 60u * 3u);
  EXPECT_EQ(rows[0], RunCsv::body_header());
  EXPECT_EQ(split_csv(rows[0]).size(), 26u);
  EXPECT_TRUE(fs::exists(dir / "series" / "bodies_patches.csv"));
  EXPECT_EQ(lines_of(dir / "series" / "bodies_patches.csv").front(), RunCsv::patch_header());
  EXPECT_FALSE(fs::exists(dir / "series" / "bodies.csv.part"));
  std::map<std::string, std::vector<std::string>> last;
  double t_prev = 0;
  for (std::size_t k = 1; k < rows.size(); ++k) {
    const auto f = split_csv(rows[k]);
    ASSERT_EQ(f.size(), 26u) << rows[k];
    const double t = std::stod(f[0]);
    EXPECT_GE(t, t_prev);
    t_prev = t;
    last[f[1]] = f;
    if (f[1] == "bucket" && (std::abs(t - 0.5) < 1e-9 || std::abs(t - 1.0) < 1e-9)) {
      const double x = t < 0.75 ? 6.0 : 6.0, z = t < 0.75 ? 8.0 : 9.0;
      EXPECT_NEAR(std::stod(f[2]), x, 1e-6) << rows[k];
      EXPECT_NEAR(std::stod(f[3]), 1.5, 1e-6) << rows[k];
      EXPECT_NEAR(std::stod(f[4]), z, 1e-6) << rows[k];
    }
    if (f[1] == "block") {
      EXPECT_EQ(std::stod(f[2]), 10.0);
      EXPECT_EQ(std::stod(f[3]), 1.5);
    }
  }
  ASSERT_EQ(last.size(), 3u);
  EXPECT_TRUE(last.count("ball, red"));
  std::ifstream in(dir / "report.json");
  const auto report = nlohmann::json::parse(in);
  for (const auto& b : report["bodies"]) {
    const auto& f = last.at(b["name"].get<std::string>());
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(std::stod(f[2 + i]), b["position_m"][i].get<double>(), 1e-6) << b["name"];
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(std::stod(f[5 + i]), b["orientation_wxyz"][i].get<double>(), 1e-6) << b["name"];
  }
  // The ball came to rest on the static block: the heightfield holds nothing of it, its
  // sinkage is minus its clearance over the original surface (1 m): 2 m − 0.2 m.
  const auto& ball = last.at("ball, red");
  EXPECT_NEAR(std::stod(ball[3]), 2.2, 0.01);
  EXPECT_NEAR(std::stod(ball[24]), -(2.2 - 0.2 - 1.0), 0.01);
  EXPECT_EQ(ball[25], "0");
  // The frame file: one row per frame, in time order; the longest frame is the report's, and
  // each frame's stages add up to no more than it.
  const auto frames = lines_of(dir / "series" / "bodies_frames.csv");
  ASSERT_EQ(frames.size(), 1u + 60u);
  EXPECT_EQ(frames[0], RunCsv::frame_header());
  const std::size_t columns = split_csv(frames[0]).size();
  double longest = 0, t_before = 0;
  for (std::size_t k = 1; k < frames.size(); ++k) {
    const auto f = split_csv(frames[k]);
    ASSERT_EQ(f.size(), columns) << frames[k];
    EXPECT_GT(std::stod(f[0]), t_before);
    t_before = std::stod(f[0]);
    const double ms = std::stod(f[1]);
    double stages = 0;
    for (std::size_t c = 3; c <= 9; ++c) stages += std::stod(f[c]);
    EXPECT_LE(stages, ms * (1 + 1e-5) + 1e-6) << frames[k];
    longest = std::max(longest, ms);
  }
  EXPECT_NEAR(longest, report["frames"]["max_ms"].get<double>(), 1e-5 * longest);
  EXPECT_FALSE(fs::exists(dir / "series" / "bodies_frames.csv.part"));
}

// The shipped plate press parses: a kinematic plate on keyframes, a CSV output.
TEST(SceneMotion, ShippedPlatePressParses) {
  auto s = load_scene_file(std::string(SANDPATCH_SOURCE_DIR) + "/scenes/plate_press.json");
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(s->bodies.size(), 1u);
  EXPECT_EQ(s->bodies[0].motion, MotionKind::Kinematic);
  EXPECT_EQ(s->bodies[0].keyframes.size(), 3u);
  EXPECT_EQ(s->outputs.csv, "plate.csv");
}
