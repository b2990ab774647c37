// tests the images `sandpatch run` writes (manager/run_outputs.cpp FrameWriter over
// render/): the default scene's bodies show where the report says they are, and the crater
// the ball makes changes the picture where it is.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

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

// What a user sees of patch p in the image img of camera cam (scene_frames tests below).
// Regions, from the ground's points projected: 1 the footprint more than 0.5 m inside its
// edge, 3 the band within 0.5 m of the edge, 2 the ring 0.5 to 1.5 m outside; the other
// patches' footprints and 0.5 m around them left out. Metrics (Rec. 709 luma 0..255): the mean
// local contrast |luma - its 5 x 5 mean| per region, the specks (luma more than 40 from its
// 3 x 3 median) per region, and the distance between the mean colours (sRGB bytes) of the
// footprint (inside and band) and of the ring.
// Dark pixels: luma below half the ring's mean (a granule in shadow, or a gap). With `ids` (the
// same camera's body-ID render, FrameFlags::body_ids) the pixels within 2 of a body's are left
// out: the metrics are the sand's, not the bodies' shading and outlines.
struct PatchLook {
  double contrast[4] = {};
  int n[4] = {}, specks[4] = {}, dark[4] = {};
  double colour_distance = 0;
};
PatchLook patch_look(World& world, FrameWriter& images, const render::CameraView& cam, const render::Image& img,
                     const TerrainManager::PatchInfo& p, const std::vector<TerrainManager::PatchInfo>& patches,
                     const render::Image* ids = nullptr) {
  const Heightfield& hf = world.heightfield();
  const double h = hf.spacing();
  const double x0 = hf.origin_x() + h * p.region.i0, z0 = hf.origin_z() + h * p.region.j0;
  const double x1 = hf.origin_x() + h * (p.region.i0 + p.region.ni - 1), z1 = hf.origin_z() + h * (p.region.j0 + p.region.nj - 1);
  auto near_other = [&](double x, double z) {
    for (const auto& q : patches) {
      if (q.patch == p.patch) continue;
      const double a0 = hf.origin_x() + h * q.region.i0 - 0.5, a1 = hf.origin_x() + h * (q.region.i0 + q.region.ni - 1) + 0.5;
      const double b0 = hf.origin_z() + h * q.region.j0 - 0.5, b1 = hf.origin_z() + h * (q.region.j0 + q.region.nj - 1) + 0.5;
      if (x > a0 && x < a1 && z > b0 && z < b1) return true;
    }
    return false;
  };
  const int W = cam.width, H = cam.height;
  std::vector<int> region(std::size_t(W) * H, 0);  // 1 inside, 2 ring, 3 band
  for (double x = x0 - 1.5; x <= x1 + 1.5; x += 0.01)
    for (double z = z0 - 1.5; z <= z1 + 1.5; z += 0.01) {
      if (near_other(x, z)) continue;
      const double out = std::max(std::max(x0 - x, x - x1), std::max(z0 - z, z - z1));  // m outside the footprint
      const double y = hf.sample(float(x - hf.origin_x()), float(z - hf.origin_z())) + hf.origin_y();
      auto q = images.renderer()->project(cam, {x, y, z});
      if (!q) continue;
      const int px = int(q->pixel.x()), py = int(q->pixel.y());
      if (px < 0 || py < 0 || px >= W || py >= H) continue;
      int& r = region[std::size_t(py) * W + px];
      if (std::fabs(out) < 0.5) r = 3;
      else if (out < 0) r = r == 3 ? 3 : 1;
      else if (r == 0) r = 2;
    }
  if (ids) {
    const int bodies = int(world.bodies().size());
    std::vector<char> body(std::size_t(W) * H, 0);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (int k = 0; k < bodies; ++k) {
          const std::uint8_t* c = ids->pixel(x, y);
          const auto id = render::body_id_color(k);
          if (c[0] == id[0] && c[1] == id[1] && c[2] == id[2]) body[std::size_t(y) * W + x] = 1;
        }
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        for (int j = std::max(0, y - 2); j <= std::min(H - 1, y + 2); ++j)
          for (int i = std::max(0, x - 2); i <= std::min(W - 1, x + 2); ++i)
            if (body[std::size_t(j) * W + i]) region[std::size_t(y) * W + x] = 0;
  }
  double sum[4][3] = {}, contrast[4] = {};
  PatchLook o;
  int* n = o.n;
  int* specks = o.specks;
  for (int y = 2; y < H - 2; ++y)
    for (int x = 2; x < W - 2; ++x) {
      const int k = region[std::size_t(y) * W + x];
      if (!k) continue;
      const std::uint8_t* c = img.pixel(x, y);
      for (int i = 0; i < 3; ++i) sum[k][i] += c[i];
      ++n[k];
      double m = 0, v[9];
      for (int j = -2; j <= 2; ++j)
        for (int i = -2; i <= 2; ++i) m += luma(img.pixel(x + i, y + j));
      contrast[k] += std::fabs(luma(c) - m / 25);
      int q = 0;
      for (int j = -1; j <= 1; ++j)
        for (int i = -1; i <= 1; ++i) v[q++] = luma(img.pixel(x + i, y + j));
      std::nth_element(v, v + 4, v + 9);
      specks[k] += std::fabs(luma(c) - v[4]) > 40;
    }
  double d2 = 0;
  for (int i = 0; i < 3; ++i) {
    const double patch = (sum[1][i] + sum[3][i]) / std::max(1, n[1] + n[3]), ring = sum[2][i] / std::max(1, n[2]);
    d2 += (patch - ring) * (patch - ring);
  }
  for (int k = 1; k < 4; ++k) o.contrast[k] = n[k] > 0 ? contrast[k] / n[k] : 0.0;
  o.colour_distance = std::sqrt(d2);
  const double ring_luma = 0.2126 * sum[2][0] + 0.7152 * sum[2][1] + 0.0722 * sum[2][2];
  const double dark_below = 0.5 * ring_luma / std::max(1, n[2]);
  for (int y = 2; y < H - 2; ++y)
    for (int x = 2; x < W - 2; ++x)
      if (const int k = region[std::size_t(y) * W + x]; k && luma(img.pixel(x, y)) < dark_below) ++o.dark[k];
  return o;
}

// The default scene with frame_budget_ms `budget` (ms; infinity: off), two threads, stepped to
// `t` s, for the patch-look tests below.
// `travel` false: the patch a body drives toward the edge of gets a patch abutting it ahead
// (simulation.lod.travel off), the fixture the coarse-patch tests' bounds were measured on.
// The default scene at time t under the frame budget `budget` (ms). former_sand: its sand as
// the looks below were measured with (the linear spring at 2e4 N/m, restitution 0.3), not the
// hysteretic one it has now, whose coarse patch reads 11.5 apart from the ground in mean colour
// (docs/BENCHMARKS.md "The default scene's sand follows the calibration").
void default_scene_at(double budget, double t, SceneDef& s, std::unique_ptr<World>& world, bool travel = true,
                      bool former_sand = false) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok()) << scene.message();
  s = scene.value();
  if (former_sand) {  // (the terrain's material is what the world is made with)
    s.terrain.material.restitution = 0.3;
    s.terrain.material.unloading_stiffness_ratio = 1.0;
    s.terrain.material.stiffness = 2.0e4;
  }
  s.terrain.frame_budget_ms = budget;
  s.terrain.lod_travel = travel;
  auto w = make_world(s, 2, "cpu");
  ASSERT_TRUE(w.ok()) << w.message();
  world = std::move(w.value());
  ASSERT_TRUE(step_to(*world, t, s.simulation.dt).ok());
}

void print_look(const char* what, const TerrainManager::PatchInfo& p, const PatchLook& look) {
  std::printf("%s patch %d (%d granules, scale %.0f): local contrast inside %.2f, band %.2f, ring %.2f; specks inside %d, "
              "band %d, ring %d; dark inside %d, band %d, ring %d (pixels %d, %d, %d); mean colour footprint vs ring %.1f\n",
              what, p.patch, p.granules, p.particle_scale, look.contrast[1], look.contrast[3], look.contrast[2], look.specks[1],
              look.specks[3], look.specks[2], look.dark[1], look.dark[3], look.dark[2], look.n[1], look.n[3], look.n[2],
              look.colour_distance);
}

// One lit frame of `cam`, saved as `png`; nullopt without a GL context (the caller skips) or
// when the render fails (the failure recorded).
std::optional<render::Image> lit_frame(FrameWriter& images, const render::CameraView& cam, const char* png) {
  auto img = images.render(cam);
  EXPECT_TRUE(img.ok()) << img.message();
  if (!img.ok() || images.unavailable()) return std::nullopt;
  EXPECT_TRUE(render::save_png(output_path(png), *img).ok());
  return std::move(*img);
}

// Renders `cam` three ways (body IDs; lit, saved as `png`; without bodies) and checks that each
// body of the world's report, which must have `state` true ("spawned", "carried_by_patch"),
// has its centre on its ID colour in the ID render and changes the lit frame by more than 60
// (RGB summed). false: no GL context (the caller skips).
bool expect_bodies_seen(World& world, FrameWriter& images, const render::CameraView& cam, const char* state, const char* png) {
  render::FrameFlags ids, bare;
  ids.body_ids = true;
  bare.bodies = false;
  auto id_img = images.render(cam, ids);
  EXPECT_TRUE(id_img.ok()) << id_img.message();
  if (!id_img.ok() || images.unavailable()) return false;
  auto lit = images.render(cam);
  auto none = images.render(cam, bare);
  EXPECT_TRUE(lit.ok() && none.ok());
  if (!lit.ok() || !none.ok()) return true;
  EXPECT_TRUE(render::save_png(output_path(png), lit.value()).ok());
  const auto report = world.report();
  EXPECT_EQ(report["bodies"].size(), 2u);
  for (std::size_t k = 0; k < report["bodies"].size(); ++k) {
    const auto& b = report["bodies"][k];
    EXPECT_TRUE(b[state].get<bool>()) << b.dump();
    const Eigen::Vector3d c(b["position_m"][0].get<double>(), b["position_m"][1].get<double>(), b["position_m"][2].get<double>());
    auto p = images.renderer()->project(cam, c);
    EXPECT_TRUE(p.has_value());
    if (!p) continue;
    const int x = int(p->pixel.x()), y = int(p->pixel.y());
    EXPECT_TRUE(x >= 0 && x < cam.width && y >= 0 && y < cam.height) << b["name"] << " at " << x << ", " << y;
    if (x < 0 || x >= cam.width || y < 0 || y >= cam.height) continue;
    const std::uint8_t* px = id_img->pixel(x, y);
    const auto id = render::body_id_color(int(k));
    EXPECT_TRUE(px[0] == id[0] && px[1] == id[1] && px[2] == id[2])
        << b["name"] << ": pixel " << x << ", " << y << " is " << int(px[0]) << " " << int(px[1]) << " " << int(px[2]);
    const std::uint8_t* a = lit->pixel(x, y);
    const std::uint8_t* n = none->pixel(x, y);
    EXPECT_GT(std::abs(a[0] - n[0]) + std::abs(a[1] - n[1]) + std::abs(a[2] - n[2]), 60) << b["name"];
  }
  return true;
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
  if (!expect_bodies_seen(*r.world, images, cam, "spawned", "default_bodies.actual.png"))
    GTEST_SKIP() << "no GL context: " << images.why();
  render::FrameFlags bare;
  bare.bodies = false;
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

// The GL backend's particles are drawn straight from the simulation's buffer, where the bodies'
// shell spheres lie among the granules' (in cell order): only the granules' are drawn (ids
// below 4 x granules), so the bodies show. The default scene on the GL backend at 1.5 s, both
// bodies carried by patches (their shells engaged): each body's centre projects onto that
// body's pixel in the ID render and changes the lit frame. (Drawn as sand, the shells covered
// both bodies: their centres showed granules.)
TEST(SceneFrames, GlBackendShowsTheBodiesNotTheirShells) {
  auto scene = load_default_scene();
  ASSERT_TRUE(scene.ok()) << scene.message();
  SceneDef s = scene.value();
  s.cameras.front().width = 320;
  s.cameras.front().height = 180;
  auto w = make_world(s, 2, "gl");
  if (!w.ok() && w.message().find("OpenGL") != std::string::npos) GTEST_SKIP() << w.message();
  ASSERT_TRUE(w.ok()) << w.message();
  World& world = *w.value();
  ASSERT_TRUE(step_to(world, 1.5, s.simulation.dt).ok());
  ASSERT_NE(world.manager()->gl_context(), nullptr) << "the GL backend's slots";
  FrameWriter images(world);
  const render::CameraView cam = camera_at(s.cameras.front(), world.time());
  if (!expect_bodies_seen(world, images, cam, "carried_by_patch", "gl_bodies.actual.png"))
    GTEST_SKIP() << "no GL context: " << images.why();
}

// The debug overlay of the bodies' particle shells (FrameWriter::set_show_shells, `sandpatch
// run|render --shells`): the default scene at 2 s under a budget no rung fits (0.01 ms: every
// patch at the last rung, particle scale 3, the same on every machine), both bodies carried by
// patches (CPU backend). Counted: pixels of the overlay's magenta hue (red and blue both more
// than 50 above green: no sand, sky or palette colour is) within 20 px of each body's projected
// centre. Off (the default): none in the whole image; on: more than 15 around each body at
// 320 x 180 (measured 33 around the ball, sunk among granules of 12 cm, and 162 around the crate).
TEST(SceneFrames, ShellOverlayDrawsTheCarriedBodiesShells) {
  SceneDef s;
  std::unique_ptr<World> w;
  ASSERT_NO_FATAL_FAILURE(default_scene_at(0.01, 2.0, s, w));
  World& world = *w;
  s.cameras.front().width = 320;
  s.cameras.front().height = 180;
  FrameWriter images(world);
  const render::CameraView cam = camera_at(s.cameras.front(), world.time());
  auto off = images.render(cam);
  ASSERT_TRUE(off.ok()) << off.message();
  if (images.unavailable()) GTEST_SKIP() << "no GL context: " << images.why();
  images.set_show_shells(true);
  auto on = images.render(cam);
  ASSERT_TRUE(on.ok()) << on.message();
  EXPECT_TRUE(render::save_png(output_path("shell_overlay.actual.png"), on.value()).ok());
  auto magenta = [](const std::uint8_t* p) { return p[0] > p[1] + 50 && p[2] > p[1] + 50; };
  int off_count = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) off_count += magenta(off->pixel(x, y));
  EXPECT_EQ(off_count, 0);
  const auto report = world.report();
  ASSERT_EQ(report["bodies"].size(), 2u);
  for (const auto& b : report["bodies"]) {
    EXPECT_TRUE(b["carried_by_patch"].get<bool>()) << b.dump();
    const Eigen::Vector3d c(b["position_m"][0].get<double>(), b["position_m"][1].get<double>(), b["position_m"][2].get<double>());
    auto p = images.renderer()->project(cam, c);
    ASSERT_TRUE(p.has_value());
    int n = 0;
    for (int y = std::max(0, int(p->pixel.y()) - 20); y < std::min(cam.height, int(p->pixel.y()) + 20); ++y)
      for (int x = std::max(0, int(p->pixel.x()) - 20); x < std::min(cam.width, int(p->pixel.x()) + 20); ++x) n += magenta(on->pixel(x, y));
    std::printf("%s: %d overlay pixels within 20 px of its centre\n", b["name"].get<std::string>().c_str(), n);
    EXPECT_GT(n, 15) << b["name"];
  }
}

// What a user sees of a coarse patch: the default scene with a frame budget no rung fits
// (0.01 ms: its patch takes the coarsest scale, 3; granules 12 cm in radius), at 2 s, 640 x 360.
// Regions, from the ground's points projected: the footprint more than 0.5 m inside its edge,
// the band within 0.5 m of the edge, the ring 0.5 to 1.5 m outside. Metrics (Rec. 709 luma
// 0..255): the mean local contrast |luma - its 5 x 5 mean| per region, the specks (luma more
// than 40 from its 3 x 3 median) per region, and the distance between the mean colours (sRGB
// bytes) of the footprint (inside and band) and of the ring. docs/BENCHMARKS.md "What a user
// sees" has the numbers before and after; the bounds here sit between them.
TEST(SceneFrames, CoarsePatchReadsAsSandWithoutSpecks) {
  SceneDef s;
  std::unique_ptr<World> w;
  ASSERT_NO_FATAL_FAILURE(default_scene_at(0.01, 2.0, s, w, /*travel=*/false, /*former_sand=*/true));
  World& world = *w;
  // The first patch, at scale 3 (the budget fits nothing finer). A patch asked for ahead of a
  // body it carries does not wait for the budget, so a second one may abut it: its footprint
  // (and 0.5 m around it) is left out of the regions below.
  const auto patches = world.manager()->patches();
  ASSERT_GE(patches.size(), 1u);
  ASSERT_LE(patches.size(), 2u);
  for (const auto& q : patches) {
    ASSERT_TRUE(q.ready);
    ASSERT_EQ(q.particle_scale, 3.0);
  }
  const auto& p = *std::min_element(patches.begin(), patches.end(), [](const auto& a, const auto& b) { return a.patch < b.patch; });
  FrameWriter images(world);
  const render::CameraView cam = camera_at(s.cameras.front(), world.time());
  auto img = lit_frame(images, cam, "coarse_patch.actual.png");
  if (!img) GTEST_SKIP() << "no GL context: " << images.why();
  const PatchLook look = patch_look(world, images, cam, *img, p, patches);
  print_look("coarse, 2 s,", p, look);
  ASSERT_GT(look.n[1], 2000);
  ASSERT_GT(look.n[2], 5000);
  ASSERT_GT(look.n[3], 5000);
  EXPECT_LT(look.contrast[1], 9.0) << "granules shaded as the sand they stand for (15.2 as balls)";
  EXPECT_LT(look.specks[1] + look.specks[3], 60) << "154 before";
  // (5.8 with the one patch and its whole ring; 8.0 with the ring less the second patch's side)
  EXPECT_LT(look.colour_distance, 9.0);
}

// The trough the crate ploughs through a coarse patch (the default scene at 3 s under a budget
// no rung fits: particle scale 3), 640 x 360: the granules the crate uncovered lie below the
// surface the patch was promoted from, and the terrain's shadow march no longer takes that
// surface for ground above them (terrain_shadow.glsl: no sample inside a live footprint).
// Dark pixels (luma below half the ring's mean) inside the footprints and their bands, summed
// over the patches: docs/BENCHMARKS.md "Shadows inside a live patch" has the count before and
// after; the bound sits between them.
TEST(SceneFrames, TroughInACoarsePatchIsNotShadowedByTheOldSurface) {
  SceneDef s;
  std::unique_ptr<World> w;
  ASSERT_NO_FATAL_FAILURE(default_scene_at(0.01, 3.0, s, w, /*travel=*/false));
  World& world = *w;
  const auto patches = world.manager()->patches();
  ASSERT_GE(patches.size(), 1u);
  FrameWriter images(world);
  const render::CameraView cam = camera_at(s.cameras.front(), world.time());
  auto img = lit_frame(images, cam, "coarse_trough.actual.png");
  if (!img) GTEST_SKIP() << "no GL context: " << images.why();
  int dark = 0, pixels = 0;
  for (const auto& p : patches) {
    ASSERT_EQ(p.particle_scale, 3.0);
    const PatchLook look = patch_look(world, images, cam, *img, p, patches);
    print_look("coarse, 3 s,", p, look);
    dark += look.dark[1] + look.dark[3];
    pixels += look.n[1] + look.n[3];
  }
  std::printf("dark pixels in the footprints and bands: %d of %d\n", dark, pixels);
  ASSERT_GT(pixels, 5000);
  EXPECT_LT(dark, 1100) << "1708 when the march sampled the old surface (655 after)";
}

// What a user sees of a patch at particle scale 1 (granules 2.5 cm in radius, 1.5 px at the
// default camera): the default scene at 3 s with the budget off, 640 x 360, each patch's sand
// (the bodies' pixels and 2 px around them left out: a body-ID render) against the ground
// around it (patch_look). The bed smoothed over two sphere radii before its normal is taken, and
// a fine bed's shadow looked up on that bed rather than on the caps (render.cpp smooth_bed,
// shaders/render/particles.frag): local contrast inside 13.0 and 10.5 -> 10.5 and 5.4 (the
// ground around: 0.55, 0.30; what is left in the ball's patch is mostly its crater and shadow),
// specks inside and in the band 30 and 122 -> 20 and 46 (docs/BENCHMARKS.md "A fine patch
// at the default camera"); the bounds sit between.
TEST(SceneFrames, FinePatchReadsAsSand) {
  SceneDef s;
  std::unique_ptr<World> w;
  ASSERT_NO_FATAL_FAILURE(default_scene_at(std::numeric_limits<double>::infinity(), 3.0, s, w));
  World& world = *w;
  const auto patches = world.manager()->patches();
  ASSERT_GE(patches.size(), 1u);
  FrameWriter images(world);
  const render::CameraView cam = camera_at(s.cameras.front(), world.time());
  auto img = lit_frame(images, cam, "fine_patch.actual.png");
  if (!img) GTEST_SKIP() << "no GL context: " << images.why();
  render::FrameFlags id_flags;
  id_flags.body_ids = true;
  auto ids = images.render(cam, id_flags);
  ASSERT_TRUE(ids.ok()) << ids.message();
  for (const auto& p : patches) {
    ASSERT_EQ(p.particle_scale, 1.0);
    print_look("fine, 3 s, bodies in,", p, patch_look(world, images, cam, *img, p, patches));
    const PatchLook look = patch_look(world, images, cam, *img, p, patches, &ids.value());
    print_look("fine, 3 s, sand only,", p, look);
    ASSERT_GT(look.n[1], 1000);
    ASSERT_GT(look.n[2], 5000);
    EXPECT_LT(look.contrast[1], p.patch == 0 ? 12.0 : 8.0) << "patch " << p.patch << ": 13.0 and 10.5 with the bed unsmoothed";
    EXPECT_LT(look.specks[1] + look.specks[3], p.patch == 0 ? 25 : 90) << "patch " << p.patch << ": 30 and 122 before";
  }
}
