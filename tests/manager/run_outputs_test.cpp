// tests manager/run_outputs.cpp's VideoWriter (`sandpatch run --video`): a missing ffmpeg is
// refused naming it, before a run starts; frames of the wrong size are refused; with ffmpeg
// installed the frames become a video file.
#include "manager/run_outputs.hpp"

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "manager/run.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;
namespace fs = std::filesystem;

namespace {

// Sets PATH for the scope, then puts it back.
struct PathOverride {
  std::string old;
  bool had;
  explicit PathOverride(const char* value) {
    const char* p = std::getenv("PATH");
    had = p != nullptr;
    if (had) old = p;
    setenv("PATH", value, 1);
  }
  ~PathOverride() {
    if (had) setenv("PATH", old.c_str(), 1);
    else unsetenv("PATH");
  }
};

render::Image frame(int w, int h, std::uint8_t shade) {
  render::Image img;
  img.width = w;
  img.height = h;
  img.rgba.assign(std::size_t(w) * h * 4, shade);
  return img;
}

}  // namespace

TEST(VideoWriter, MissingFfmpegIsNamed) {
  PathOverride p("/nonexistent-dir");
  auto st = VideoWriter::available();
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("ffmpeg"), std::string::npos) << st.message();
}

TEST(VideoWriter, RunRefusesVideoWithoutFfmpegBeforeRunning) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok()) << scene.message();
  const fs::path dir = fs::temp_directory_path() / ("sandpatch_video_" + std::to_string(getpid()));
  RunOptions opt;
  opt.out_dir = dir.string();
  opt.frames = 1;
  opt.progress = ProgressStyle::None;
  opt.video = (dir / "v.mp4").string();
  RunResult r;
  {
    PathOverride p("/nonexistent-dir");
    r = run_scene(scene.value(), opt);
  }
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_EQ(r.stage, "options");
  EXPECT_NE(r.message.find("--video"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("ffmpeg"), std::string::npos) << r.message;
  EXPECT_FALSE(fs::exists(dir)) << "refused before anything was written";
  opt.video_fps = 1000;  // above 1 / dt = 120
  r = run_scene(scene.value(), opt);
  EXPECT_EQ(r.code, ExitCode::BadInput);
  EXPECT_NE(r.message.find("--video-fps"), std::string::npos) << r.message;
  fs::remove_all(dir);
}

TEST(VideoWriter, FramesBecomeAVideo) {
  if (!VideoWriter::available().ok()) GTEST_SKIP() << "ffmpeg not installed";
  const fs::path path = fs::temp_directory_path() / ("sandpatch_video_" + std::to_string(getpid()) + ".mp4");
  VideoWriter v;
  ASSERT_TRUE(v.open(path.string(), 33, 24, 10).ok());  // odd width: padded to even
  for (int k = 0; k < 5; ++k) ASSERT_TRUE(v.add(frame(33, 24, std::uint8_t(40 * k))).ok());
  auto bad = v.add(frame(32, 24, 0));
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("33 x 24"), std::string::npos) << bad.message();
  ASSERT_TRUE(v.close().ok());
  ASSERT_TRUE(fs::exists(path));
  EXPECT_GT(fs::file_size(path), 100u);
  fs::remove(path);
}
