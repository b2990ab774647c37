// tests apps/sandpatch/view.cpp end to end: `sandpatch view` refuses bad options and a missing
// display with exit code 2, and under Xvfb (xvfb-run) its screenshot after N frames shows the
// same picture `sandpatch render` writes for the same camera and time, plus the overlay.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include "render/image.hpp"
#include "tests/apps/process.hpp"

namespace fs = std::filesystem;
using sandpatch::render::Image;

namespace {

using apps_test::Outcome;
using apps_test::shell;
Outcome run_exe(const std::string& args) { return apps_test::sandpatch(args); }

bool on_path(const std::string& exe) { return shell("command -v " + exe).code == 0; }

double luma(const Image& img, int x, int y) {
  const std::uint8_t* p = img.pixel(x, y);
  return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];  // Rec. 709 weights on the sRGB bytes
}

}  // namespace

TEST(View, BadOptionsAreRefusedNamingTheOptionAndValue) {
  struct Case {
    std::string args, must_name;
  };
  for (const Case& c : {Case{"view --size 0x0", "--size 0x0"}, Case{"view --size wide", "--size wide"},
                        Case{"view --size 1280x99999", "--size 1280x99999"},
                        Case{"view --screenshot shot.png", "--screenshot shot.png"},
                        Case{"view --frames 3 --frame-budget -5", "--frame-budget -5"},
                        Case{"view --frames 3 --camera nowhere", "--camera nowhere"},
                        Case{"view --frames 0", "--frames"}, Case{"view --backend vulkan", "--backend"},
                        Case{"view --keys space,jump", "'jump'"}, Case{"view --keys rotate:1", "'rotate:1'"},
                        Case{"view --keys zoom:nan", "'zoom:nan'"}, Case{"view --quality ultra", "--quality ultra"}}) {
    Outcome o = run_exe(c.args);
    EXPECT_EQ(o.code, 2) << c.args << "\n" << o.output;
    EXPECT_NE(o.output.find(c.must_name), std::string::npos) << c.args << "\n" << o.output;
  }
  Outcome o = run_exe("view /nonexistent/scene.json");
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("/nonexistent/scene.json"), std::string::npos) << o.output;
}

TEST(View, NoDisplayIsAClearErrorNamingDisplay) {
#ifndef SANDPATCH_HAVE_VIEWER
  GTEST_SKIP() << "sandpatch was built without GLFW (libglfw3-dev): no viewer";
#endif
  Outcome o = shell("env -u DISPLAY -u WAYLAND_DISPLAY " + std::string(SANDPATCH_EXE) + " view --frames 1");
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("DISPLAY"), std::string::npos) << o.output;
  // A display that is not there: the same exit code, the display named.
  o = shell("DISPLAY=:9876 " + std::string(SANDPATCH_EXE) + " view --frames 1");
  EXPECT_EQ(o.code, 2) << o.output;
  EXPECT_NE(o.output.find("DISPLAY=:9876"), std::string::npos) << o.output;
}

// The default scene, 30 frames (t = 0.25 s, one patch live), 640 x 360 in a 1280 x 720 Xvfb
// screen, budget off so the state does not depend on the clock. The screenshot against
// `sandpatch render --at 0.25` (same camera, same time, same renderer): over the pixels outside
// the overlay panel the mean |Δluma| must be < 0.5 (8-bit units) and fewer than 0.5 % of them may
// differ by more than 32 (the patch outline is the only other thing drawn). The panel must hold
// text (white pixels where the picture has none), and the outline a patch state's colour.
TEST(View, ScreenshotUnderXvfbMatchesTheRenderedFrame) {
#ifndef SANDPATCH_HAVE_VIEWER
  GTEST_SKIP() << "sandpatch was built without GLFW (libglfw3-dev): no viewer";
#endif
  if (!on_path("xvfb-run")) GTEST_SKIP() << "xvfb-run is not installed (Debian package xvfb): no X server to test under";
  const fs::path dir = fs::temp_directory_path() / ("sandpatch_view_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path ref = dir / "render.png", shot = dir / "view.png";
  // The reference first: it settles the default scene's granule tile when the cache is cold.
  Outcome r = run_exe("render --at 0.25 --frame-budget off --image " + ref.string() + " --out " + (dir / "run").string());
  ASSERT_EQ(r.code, 0) << r.output;
  Outcome v = shell("xvfb-run -a -s '-screen 0 1280x720x24' " + std::string(SANDPATCH_EXE) +
                    " view --frames 30 --size 640x360 --frame-budget off --screenshot " + shot.string());
  ASSERT_EQ(v.code, 0) << v.output;
  EXPECT_NE(v.output.find("average"), std::string::npos) << v.output;  // the frame rate at exit
  int px = 0, py = 0, pw = 0, ph = 0;
  const std::size_t at = v.output.find("overlay panel at");
  ASSERT_NE(at, std::string::npos) << v.output;
  ASSERT_EQ(std::sscanf(v.output.c_str() + at, "overlay panel at x %d y %d, %d x %d", &px, &py, &pw, &ph), 4) << v.output;

  auto a = sandpatch::render::load_png(shot.string());
  auto b = sandpatch::render::load_png(ref.string());
  ASSERT_TRUE(a) << a.message();
  ASSERT_TRUE(b) << b.message();
  ASSERT_EQ(a->width, 640);
  ASSERT_EQ(a->height, 360);
  ASSERT_EQ(b->width, a->width);
  ASSERT_EQ(b->height, a->height);

  auto in_panel = [&](int x, int y) { return x >= px && x < px + pw && y >= py && y < py + ph; };
  double sum = 0, sum2 = 0, diff = 0;
  long n = 0, big = 0, state_colour = 0, text = 0;
  for (int y = 0; y < a->height; ++y)
    for (int x = 0; x < a->width; ++x) {
      const double la = luma(*a, x, y), lb = luma(*b, x, y);
      const std::uint8_t* p = a->pixel(x, y);
      if (in_panel(x, y)) {
        if (p[0] > 200 && p[1] > 200 && p[2] > 200 && lb < 200) ++text;
        continue;
      }
      ++n;
      sum += la, sum2 += la * la;
      diff += std::fabs(la - lb);
      if (std::fabs(la - lb) > 32) ++big;
      const bool filling = p[0] == 255 && p[1] == 214 && p[2] == 0, active = p[0] == 255 && p[1] == 96 && p[2] == 48,
                 asleep = p[0] == 96 && p[1] == 170 && p[2] == 255;
      if (filling || active || asleep) ++state_colour;
    }
  ASSERT_GT(n, 0);
  const double mean = sum / n, sd = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
  std::printf("outside the panel: mean |dluma| %.3f, %.3f %% over 32, luma sd %.1f; panel text pixels %ld; outline pixels %ld\n",
              diff / n, 100.0 * double(big) / n, sd, text, state_colour);
  EXPECT_GT(sd, 10.0) << "a blank or flat picture";
  EXPECT_LT(diff / n, 0.5) << "mean |dluma| against sandpatch render";
  EXPECT_LT(double(big) / n, 0.005);
  EXPECT_GT(text, 200) << "no overlay text in the panel";
  EXPECT_GT(state_colour, 50) << "no patch outline";
  fs::remove_all(dir);
}

// The keys, through --keys (the same handlers the keyboard and the mouse call), under Xvfb:
// space pauses (no step while paused, the picture still redrawn), n steps exactly one frame,
// + and - double and halve the speed, a drag of (100, 0) px turns the eye about the target by
// -100 x 0.005 rad at the same distance, two wheel notches bring it to 0.85^2 of its distance,
// a pan moves it, r puts the scene camera back (1e-9 m) and space runs again. One line a token
// on stdout gives the state after that token's frame.
TEST(View, ScriptedKeysPauseStepSpeedAndCamera) {
#ifndef SANDPATCH_HAVE_VIEWER
  GTEST_SKIP() << "sandpatch was built without GLFW (libglfw3-dev): no viewer";
#endif
  if (!on_path("xvfb-run")) GTEST_SKIP() << "xvfb-run is not installed (Debian package xvfb): no X server to test under";
  Outcome v = shell("xvfb-run -a -s '-screen 0 1280x720x24' " + std::string(SANDPATCH_EXE) +
                    " view --size 320x180 --frame-budget off --keys space,n,n,+,+,-,rotate:100:0,zoom:2,pan:20:-10,r,space");
  ASSERT_EQ(v.code, 0) << v.output;
  struct State {
    std::string token, mode;
    long long steps = 0;
    double t = 0, speed = 0, x = 0, y = 0, z = 0;
  };
  std::vector<State> s;
  for (std::size_t at = v.output.find("keys: "); at != std::string::npos; at = v.output.find("keys: ", at + 1)) {
    char token[64] = {0}, mode[16] = {0};
    State st;
    ASSERT_EQ(std::sscanf(v.output.c_str() + at, "keys: %63s -> %15[a-z], steps %lld, t = %lf s, speed %lf, eye %lf %lf %lf",
                          token, mode, &st.steps, &st.t, &st.speed, &st.x, &st.y, &st.z),
              8)
        << v.output.substr(at, 200);
    st.token = token, st.mode = mode;
    s.push_back(st);
  }
  ASSERT_EQ(s.size(), 11u) << v.output;
  const long long s0 = s[0].steps;  // the frames drawn before the first token (one)
  EXPECT_EQ(s[0].mode, "paused");
  EXPECT_EQ(s[1].steps, s0 + 1);
  EXPECT_EQ(s[2].steps, s0 + 2);
  for (int k = 3; k <= 9; ++k) {
    EXPECT_EQ(s[k].steps, s0 + 2) << s[k].token << ": no step while paused";
    EXPECT_EQ(s[k].mode, "paused");
  }
  EXPECT_EQ(s[3].speed, 2.0);
  EXPECT_EQ(s[4].speed, 4.0);
  EXPECT_EQ(s[5].speed, 2.0);
  // The default scene's camera: eye (6, 4, 8), target (0, 0, 0).
  const double yaw0 = std::atan2(8.0, 6.0), yaw1 = yaw0 - 100 * 0.005;
  EXPECT_NEAR(s[6].x, 10 * std::cos(yaw1), 1e-6);
  EXPECT_NEAR(s[6].y, 4.0, 1e-6);
  EXPECT_NEAR(s[6].z, 10 * std::sin(yaw1), 1e-6);
  EXPECT_NEAR(s[7].x, 0.85 * 0.85 * s[6].x, 1e-6);
  EXPECT_NEAR(s[7].y, 0.85 * 0.85 * s[6].y, 1e-6);
  EXPECT_NEAR(s[7].z, 0.85 * 0.85 * s[6].z, 1e-6);
  EXPECT_GT(std::hypot(s[8].x - s[7].x, s[8].y - s[7].y, s[8].z - s[7].z), 0.01) << "the pan moved nothing";
  EXPECT_NEAR(s[9].x, 6.0, 1e-9);
  EXPECT_NEAR(s[9].y, 4.0, 1e-9);
  EXPECT_NEAR(s[9].z, 8.0, 1e-9);
  EXPECT_EQ(s[10].mode, "running");
  EXPECT_EQ(s[10].steps, s0 + 3);
  EXPECT_NEAR(s[10].t, double(s0 + 3) / 120.0, 1e-6);  // dt = 1/120 s
}

// --quality low: the window is filled (the half-resolution frame scaled up) with a picture.
TEST(View, LowQualityFillsTheWindow) {
#ifndef SANDPATCH_HAVE_VIEWER
  GTEST_SKIP() << "sandpatch was built without GLFW (libglfw3-dev): no viewer";
#endif
  if (!on_path("xvfb-run")) GTEST_SKIP() << "xvfb-run is not installed (Debian package xvfb): no X server to test under";
  const fs::path shot = fs::temp_directory_path() / ("sandpatch_view_low_" + std::to_string(::getpid()) + ".png");
  Outcome v = shell("xvfb-run -a -s '-screen 0 1280x720x24' " + std::string(SANDPATCH_EXE) +
                    " view --frames 3 --size 320x180 --frame-budget off --quality low --screenshot " + shot.string());
  ASSERT_EQ(v.code, 0) << v.output;
  auto a = sandpatch::render::load_png(shot.string());
  ASSERT_TRUE(a) << a.message();
  ASSERT_EQ(a->width, 320);
  ASSERT_EQ(a->height, 180);
  // Sky at the top, sand at the bottom, in every corner: nothing left black.
  for (int x : {2, a->width - 3}) {
    const std::uint8_t* top = a->pixel(x, 2);
    const std::uint8_t* bottom = a->pixel(x, a->height - 3);
    EXPECT_GT(top[2], top[0]) << "sky at x " << x;
    EXPECT_GT(bottom[0], bottom[2]) << "sand at x " << x;
  }
  fs::remove_all(shot);
}
