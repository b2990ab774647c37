// tests the images `sandpatch run` writes (manager/run_outputs.cpp FrameWriter over
// render/): the default scene's bodies show where the report says they are, and the crater
// the ball makes changes the picture where it is.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "manager/run_outputs.hpp"
#include "manager/scene_world.hpp"
#include "render/body_renderer.hpp"
#include "render_test_util.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;
using render::test::output_path;

namespace {

// Rec. 709 luma of a pixel (0..255).
double luma(const std::uint8_t* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

struct WorldRun {
  SceneDef scene;
  std::unique_ptr<World> world;
};

WorldRun default_world(int width, int height) {
  WorldRun r;
  auto scene = load_default_scene();
  EXPECT_TRUE(scene.ok()) << scene.message();
  if (!scene.ok()) return r;
  r.scene = scene.value();
  r.scene.cameras.front().width = width;
  r.scene.cameras.front().height = height;
  auto w = make_world(r.scene, 2, "cpu");
  EXPECT_TRUE(w.ok()) << w.message();
  if (w.ok()) r.world = std::move(w.value());
  return r;
}

Status step_to(World& w, double t, double dt) {
  while (w.time() < t - 1e-9)
    if (Status s = w.step(dt); !s) return s;
  return Ok{};
}

}  // namespace

// Both bodies of the default scene in the air (the crate spawns at 0.5 s): at 0.6 s each body's
// centre, from the report's body list, projects onto a pixel of that body in the ID render and
// onto a pixel that differs from the same frame without bodies in the lit render.
TEST(SceneFrames, DefaultSceneShowsBothBodiesWhereTheReportSaysTheyAre) {
  WorldRun r = default_world(320, 180);
  ASSERT_TRUE(r.world);
  ASSERT_TRUE(step_to(*r.world, 0.6, r.scene.simulation.dt).ok());
  FrameWriter images(*r.world);
  const render::CameraView cam = camera_at(r.scene.cameras.front(), r.world->time());
  render::FrameFlags ids, bare;
  ids.body_ids = true;
  bare.bodies = false;
  auto id_img = images.render(cam, ids);
  ASSERT_TRUE(id_img.ok()) << id_img.message();
  if (images.unavailable()) GTEST_SKIP() << "no GL context: " << images.why();
  auto lit = images.render(cam);
  auto none = images.render(cam, bare);
  ASSERT_TRUE(lit.ok() && none.ok());
  ASSERT_TRUE(render::save_png(output_path("default_bodies.actual.png"), lit.value()).ok());
  const auto report = r.world->report();
  ASSERT_EQ(report["bodies"].size(), 2u);
  for (std::size_t k = 0; k < 2; ++k) {
    const auto& b = report["bodies"][k];
    ASSERT_TRUE(b["spawned"].get<bool>()) << b.dump();
    const Eigen::Vector3d c(b["position_m"][0].get<double>(), b["position_m"][1].get<double>(), b["position_m"][2].get<double>());
    auto p = images.renderer()->project(cam, c);
    ASSERT_TRUE(p.has_value());
    const int x = int(p->pixel.x()), y = int(p->pixel.y());
    ASSERT_TRUE(x >= 0 && x < cam.width && y >= 0 && y < cam.height) << b["name"] << " at " << x << ", " << y;
    const std::uint8_t* px = id_img->pixel(x, y);
    const auto id = render::body_id_color(int(k));
    EXPECT_TRUE(px[0] == id[0] && px[1] == id[1] && px[2] == id[2])
        << b["name"] << ": pixel " << x << ", " << y << " is " << int(px[0]) << " " << int(px[1]) << " " << int(px[2]);
    const std::uint8_t* a = lit->pixel(x, y);
    const std::uint8_t* n = none->pixel(x, y);
    EXPECT_GT(std::abs(a[0] - n[0]) + std::abs(a[1] - n[1]) + std::abs(a[2] - n[2]), 60) << b["name"];
  }
  // The cost of one image of this frame at the scene camera's own 640 x 360 (docs/BENCHMARKS.md
  // "Rendering: images of a run"): median of 5, the whole FrameWriter::render (granules
  // copied from the simulation, bodies, shadow map, frame, ambient occlusion, read-back).
  render::CameraView full = cam;
  full.width = 640;
  full.height = 360;
  auto median_ms = [&](const render::FrameFlags& f) {
    std::vector<double> ms;
    for (int k = 0; k < 5; ++k) {
      const auto t0 = std::chrono::steady_clock::now();
      EXPECT_TRUE(images.render(full, f).ok());
      ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    std::sort(ms.begin(), ms.end());
    return ms[2];
  };
  const double no_bodies = median_ms(bare);
  const double all = median_ms({});
  const auto st = images.renderer()->stats();
  std::printf("image 640x360 on %s: median %.1f ms (%lld granules, %d bodies, shadow map %d); without the bodies and "
              "their shadow map %.1f ms\n",
              images.renderer()->renderer_string().c_str(), all, (long long)st.particles, st.bodies, int(st.shadows), no_bodies);
  EXPECT_GT(st.particles, 0) << "a patch is live at 0.6 s";
}
