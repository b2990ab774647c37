// tests render/render.cpp (SceneRenderer): no cracks from any viewpoint, triangle count
// independent of terrain size, reference images, PNG output, refusal of bad cameras.
#include "render/render.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "render/terrain_renderer.hpp"
#include "render_test_util.hpp"

using namespace sandpatch;
using namespace sandpatch::render;
using namespace sandpatch::render::test;

namespace {

// A camera at (x, ground + h, z) looking along yaw (degrees from +x toward +z), pitched down
// by pitch degrees.
CameraView look_down(const Heightfield& hf, double x, double z, double h, double yaw_deg, double pitch_deg) {
  CameraView c;
  const double y = hf.sample(float(x), float(z)) + h;
  const double yaw = yaw_deg * M_PI / 180, pitch = pitch_deg * M_PI / 180;
  c.position = {x, y, z};
  c.target = c.position + Eigen::Vector3d(std::cos(yaw) * std::cos(pitch), -std::sin(pitch), std::sin(yaw) * std::cos(pitch));
  c.fov_deg = 60;
  c.width = 128;
  c.height = 96;
  return c;
}

// Four materials: sand everywhere, a gravel band, a soil square, and grass ramping in
// along x (so the normalised blend of eq. 2 is exercised with unnormalised weights).
void paint_materials(Heightfield& hf) {
  const int n = hf.samples_x();
  hf.fill({0, n / 4, n, n / 8}, 1.0f, Layer::Material1);
  hf.fill({n / 2, n / 2, n / 5, n / 5}, 1.0f, Layer::Material2);
  hf.fill({n / 2, n / 2, n / 5, n / 5}, 0.0f, Layer::Material0);
  std::vector<float> ramp(std::size_t(n) * (n / 6));
  for (int j = 0; j < n / 6; ++j)
    for (int i = 0; i < n; ++i) ramp[std::size_t(j) * n + i] = 2.0f * float(i) / float(n - 1);
  hf.write({0, 3 * n / 4, n, n / 6}, ramp.data(), Layer::Material3);
}

// A 320 x 240 view from `position` toward `target` (m, world) with a vertical field of view
// of `fov` degrees.
CameraView view_320x240(const Eigen::Vector3d& position, const Eigen::Vector3d& target, float fov) {
  CameraView cam;
  cam.position = position;
  cam.target = target;
  cam.fov_deg = fov;
  cam.width = 320;
  cam.height = 240;
  return cam;
}

}  // namespace

// A plane, a slope and hills, each seen from several positions, heights and headings with the
// whole image below the horizon: not one background pixel shows through the terrain (no cracks
// between levels, trims or fix-ups, whatever the trim parity).
TEST(SceneRenderer, NoCracksOnPlaneSlopeAndHills) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  struct Case {
    const char* name;
    ProceduralHeightsDef p;
  };
  const Case cases[] = {{"plane", plane(0, 0, 3)}, {"slope", plane(0.2f, 0.1f)}, {"hills", hills(6, 48)}};
  for (const Case& c : cases) {
    const Heightfield hf = terrain(1025, 1.0f, c.p);
    RendererDef def;
    def.clipmap.n = 31;  // small rings: many level transitions in a 128 x 96 image
    auto r = SceneRenderer::create(*ctx, hf, def);
    ASSERT_TRUE(r.ok()) << r.message();
    int views = 0;
    for (double x : {500.0, 517.3, 530.9}) {
      for (double h : {8.0, 23.5, 40.0}) {
        for (double yaw : {0.0, 37.0, 135.0, 250.0}) {
          const CameraView cam = look_down(hf, x, 1024.0 - x, h, yaw, 55);
          auto img = (*r)->render(cam);
          ASSERT_TRUE(img.ok()) << img.message();
          ASSERT_EQ(background_pixels(img.value(), def.background), 0)
              << c.name << " x " << x << " h " << h << " yaw " << yaw;
          ++views;
        }
      }
    }
    std::printf("%s: %d views, no background pixels; last frame %lld triangles, %d levels, %.1f ms\n", c.name, views,
                (long long)(*r)->stats().terrain_triangles, (*r)->stats().active_levels, (*r)->stats().frame_ms);
  }
}

// No popping: when the camera crosses x = 512 m every level's window moves by two vertices at
// once, yet a 2 mm step across it changes the image by almost nothing, because the transition
// morph (alpha) depends continuously on the viewer. (Without the morph the rings visibly jump.)
TEST(SceneRenderer, NoPoppingWhenLevelsMove) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = terrain(1025, 1.0f, hills(6, 40));
  RendererDef def;
  def.clipmap.n = 31;
  auto r = SceneRenderer::create(*ctx, hf, def);
  ASSERT_TRUE(r.ok()) << r.message();
  for (double yaw : {0.0, 90.0, 200.0}) {
    Image img[2];
    for (int k = 0; k < 2; ++k) {
      CameraView cam = look_down(hf, 512.0, 500.0, 15.0, yaw, 30);
      const Eigen::Vector3d step(k == 0 ? -0.001 : 0.001, 0, 0);
      cam.position += step;
      cam.target += step;
      auto im = (*r)->render(cam);
      ASSERT_TRUE(im.ok()) << im.message();
      img[k] = std::move(im.value());
    }
    const ImageDiff d = compare_images(img[0], img[1]);
    std::printf("yaw %.0f: 2 mm step across a level move: mean %.3f p99 %.1f max %d\n", yaw, d.mean_abs, d.p99, d.max_abs);
    EXPECT_LE(d.mean_abs, 0.3) << "yaw " << yaw;
    EXPECT_LE(d.p99, 4.0) << "yaw " << yaw;
  }
}

// The same view over a 512^2 and an 8192^2 terrain (default renderer settings, levels chosen
// automatically for each size): the same clipmap triangles.
TEST(SceneRenderer, TriangleCountSameFor512And8192Terrains) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  std::int64_t tris[2];
  int k = 0;
  for (int n : {512, 8192}) {
    const Heightfield hf = terrain(n, 1.0f, plane(0, 0, 0));
    auto r = SceneRenderer::create(*ctx, hf);
    ASSERT_TRUE(r.ok()) << r.message();
    CameraView cam;
    cam.position = {256.3, 25.0, 255.7};
    cam.target = {330.0, 0.0, 320.0};
    cam.far_m = 150;  // the whole frustum (corners reach ~205 m) stays inside the 512 m terrain
    auto img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    tris[k++] = (*r)->stats().terrain_triangles;
    std::printf("terrain %d^2: %d levels, %lld triangles, %d pieces\n", n, (*r)->def().clipmap.levels,
                (long long)(*r)->stats().terrain_triangles, (*r)->stats().pieces);
  }
  EXPECT_EQ(tris[0], tris[1]);
}

// Small reference scenes (128 x 96) against tests/render/reference/*.png.
TEST(SceneRenderer, ReferenceImages) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  {
    Heightfield hf = terrain(257, 1.0f, hills(8, 64));
    paint_materials(hf);
    auto r = SceneRenderer::create(*ctx, hf);
    ASSERT_TRUE(r.ok()) << r.message();
    CameraView cam;
    cam.position = {20, 30, 20};
    cam.target = {140, 0, 150};
    auto img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    expect_matches_reference(img.value(), "hills_materials");
    cam.position = {128, 90, -30};
    cam.target = {128, 0, 110};
    img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    expect_matches_reference(img.value(), "hills_overview");
  }
  {
    Heightfield hf = terrain(513, 0.5f, plane(0.15f, -0.05f, 10));
    paint_materials(hf);
    RendererDef def;
    def.clipmap.n = 63;
    auto r = SceneRenderer::create(*ctx, hf, def);
    ASSERT_TRUE(r.ok()) << r.message();
    CameraView cam = look_down(hf, 60, 60, 12, 45, 25);
    auto img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    expect_matches_reference(img.value(), "slope_levels");
  }
  {
    // A mound of splats (3 layers, r = 0.15 m) on hills, half of it sunk into a rise.
    Heightfield hf = terrain(129, 0.5f, hills(1.5f, 24));
    paint_materials(hf);
    auto r = SceneRenderer::create(*ctx, hf);
    ASSERT_TRUE(r.ok()) << r.message();
    std::vector<Eigen::Vector4f> pts;
    for (int k = 0; k < 3; ++k)
      for (float z = 0; z < 4.0f - 0.6f * float(k); z += 0.3f)
        for (float x = 0; x < 4.0f - 0.6f * float(k); x += 0.3f)
          pts.emplace_back(x + 0.3f * float(k), hf.sample(30 + x, 30 + z) + 0.15f + 0.26f * float(k), z + 0.3f * float(k), 0.15f);
    ParticleBuffer buf(pts);
    ASSERT_TRUE((*r)->set_particles({buf.source({30, 0, 30})}).ok());
    CameraView cam;
    cam.position = {27, double(hf.sample(27, 27)) + 4.0, 27};
    cam.target = {32, double(hf.sample(32, 32)), 32};
    auto img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    expect_matches_reference(img.value(), "particles_mound");
  }
}

// render_png writes a PNG that loads back as the rendered image.
TEST(SceneRenderer, RenderPngWritesTheImage) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = terrain(129, 1.0f, hills(4, 32));
  auto r = SceneRenderer::create(*ctx, hf);
  ASSERT_TRUE(r.ok()) << r.message();
  CameraView cam;
  cam.position = {10, 20, 10};
  cam.target = {64, 0, 64};
  const std::string path = output_path("render_png_test.png");
  ASSERT_TRUE((*r)->render_png(cam, path).ok());
  auto back = load_png(path);
  ASSERT_TRUE(back.ok()) << back.message();
  auto img = (*r)->render(cam);
  ASSERT_TRUE(img.ok());
  EXPECT_EQ(back->rgba, img->rgba);
  EXPECT_EQ(back->width, 128);
  EXPECT_EQ(back->height, 96);
  // Unwritable path: an error naming it, no file.
  auto st = (*r)->render_png(cam, "/nonexistent-dir/frame.png");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("/nonexistent-dir/frame.png"), std::string::npos);
}

// A heightfield edit reported through heightfield_changed shows in the next frame exactly as a
// renderer built on the edited heightfield shows it, having rewritten only a few texels.
TEST(SceneRenderer, HeightfieldEditShowsNextFrame) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  Heightfield hf = terrain(257, 1.0f, hills(4, 64));
  auto r = SceneRenderer::create(*ctx, hf);
  ASSERT_TRUE(r.ok());
  CameraView cam;
  cam.position = {100, 25, 100};
  cam.target = {140, 0, 140};
  ASSERT_TRUE((*r)->render(cam).ok());
  const GridRegion pit{125, 125, 12, 12};
  hf.fill(pit, -3.0f);
  (*r)->heightfield_changed(pit);
  auto edited = (*r)->render(cam);
  ASSERT_TRUE(edited.ok());
  EXPECT_GT((*r)->stats().texels_uploaded, 0);
  EXPECT_LT((*r)->stats().texels_uploaded, 400);
  auto fresh_r = SceneRenderer::create(*ctx, hf);
  auto fresh = (*fresh_r)->render(cam);
  ASSERT_TRUE(fresh.ok());
  EXPECT_EQ(compare_images(edited.value(), fresh.value()).max_abs, 0);
}

// set_effects (the viewer's --quality low) gives exactly the frame of a renderer created with
// those settings, and refuses bad values naming the field, changing nothing.
TEST(SceneRenderer, SetEffectsEqualsARendererMadeSo) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = terrain(257, 1.0f, hills(4, 64));
  BodyInstance ball;
  ball.position = {140, 6, 140};
  ball.radius = 1.0f;
  CameraView cam;
  cam.position = {120, 25, 120};
  cam.target = {140, 0, 140};
  auto r = SceneRenderer::create(*ctx, hf);
  ASSERT_TRUE(r.ok());
  ASSERT_TRUE((*r)->set_bodies({ball}).ok());
  auto full = (*r)->render(cam);
  ASSERT_TRUE(full.ok());
  auto st = (*r)->set_effects(5.0f, 100, 100);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("ao_strength"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("shadow_map_size = 100"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("terrain_shadow_steps = 100"), std::string::npos) << st.message();
  auto again = (*r)->render(cam);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(compare_images(full.value(), again.value()).max_abs, 0) << "a refused change changed the frame";
  ASSERT_TRUE((*r)->set_effects(0.0f, 512, 0).ok());
  auto light = (*r)->render(cam);
  ASSERT_TRUE(light.ok());
  RendererDef def;
  def.ao_strength = 0;
  def.shadow_map_size = 512;
  def.terrain_shadow_steps = 0;
  auto made = SceneRenderer::create(*ctx, hf, def);
  ASSERT_TRUE(made.ok());
  ASSERT_TRUE((*made)->set_bodies({ball}).ok());
  auto expected = (*made)->render(cam);
  ASSERT_TRUE(expected.ok());
  EXPECT_EQ(compare_images(light.value(), expected.value()).max_abs, 0);
  EXPECT_GT(compare_images(light.value(), full.value()).max_abs, 0) << "ambient occlusion off changes the frame";
}

// Bad cameras are refused with errors naming the field.
TEST(SceneRenderer, BadCameraIsRefused) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = terrain(65, 1.0f, plane(0, 0));
  auto r = SceneRenderer::create(*ctx, hf);
  ASSERT_TRUE(r.ok());
  CameraView cam;
  cam.fov_deg = 190;
  cam.width = 0;
  auto img = (*r)->render(cam);
  ASSERT_FALSE(img.ok());
  EXPECT_NE(img.message().find("camera.fov_deg = 190"), std::string::npos) << img.message();
  EXPECT_NE(img.message().find("camera.width = 0"), std::string::npos) << img.message();
}

// A crater in the heightfield one granule diameter deep (8 cm, radius 0.5 m, a cosine bowl; a
// demoted patch's crater at 0.125 m spacing), reported through heightfield_changed and seen
// 10 m away at 320 x 240. Metric: the mean over the crater's pixels (the ground disc of 0.6 m
// around its centre) of |luma(after) - luma(before)|, Rec. 709 luma in 0..255: above 9 (its
// walls lit as slopes by the full-resolution normals under a sun 25 degrees high, its floor
// occluded; measured 11.3, and 6.4 with the sun at 37.5 degrees and the weaker sun term).
TEST(SceneRenderer, HeightfieldCraterChangesItsPixels) {
  auto ctx = make_context();
  if (!ctx) GTEST_SKIP() << "no GL context";
  Heightfield hf = terrain(257, 0.125f, plane(0, 0));
  auto r = SceneRenderer::create(*ctx, hf);
  ASSERT_TRUE(r.ok()) << r.message();
  const CameraView cam = view_320x240({22, 4, 24}, {16, 0, 16}, 45);
  std::vector<std::uint8_t> mask(std::size_t(cam.width) * cam.height, 0);
  int n_px = 0;
  for (double z = 15.4; z <= 16.6; z += 0.005)
    for (double x = 15.4; x <= 16.6; x += 0.005) {
      if ((x - 16) * (x - 16) + (z - 16) * (z - 16) > 0.36) continue;
      auto p = (*r)->project(cam, {x, 0.0, z});
      const int px = int(p->pixel.x()), py = int(p->pixel.y());
      if (px < 0 || px >= cam.width || py < 0 || py >= cam.height || mask[std::size_t(py) * cam.width + px]) continue;
      mask[std::size_t(py) * cam.width + px] = 1;
      ++n_px;
    }
  ASSERT_GT(n_px, 300);
  auto before = (*r)->render(cam);
  ASSERT_TRUE(before.ok()) << before.message();
  // Samples within 0.5 m of (16, 16) lowered by 0.08 (1 + cos(pi rho / 0.5)) / 2 m.
  const int i0 = int(15.5 / 0.125), n = int(1.0 / 0.125) + 1;
  for (int j = i0; j < i0 + n; ++j)
    for (int i = i0; i < i0 + n; ++i) {
      const double rho = std::hypot(i * 0.125 - 16, j * 0.125 - 16);
      if (rho < 0.5) hf.set_height(i, j, float(hf.height(i, j) - 0.08 * 0.5 * (1 + std::cos(M_PI * rho / 0.5))));
    }
  (*r)->heightfield_changed({i0, i0, n, n});
  auto after = (*r)->render(cam);
  ASSERT_TRUE(after.ok()) << after.message();
  ASSERT_TRUE(save_png(output_path("heightfield_crater.actual.png"), after.value()).ok());
  auto luma = [](const std::uint8_t* q) { return 0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2]; };
  double sum = 0;
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x)
      if (mask[std::size_t(y) * cam.width + x]) sum += std::fabs(luma(before->pixel(x, y)) - luma(after->pixel(x, y)));
  std::printf("crater pixels %d: mean |luma change| %.1f\n", n_px, sum / n_px);
  EXPECT_GT(sum / n_px, 9.0);
}

// The shadow tests' ground: 32 m of flat ground at 0.125 m, with (`wall`) a wall 1 m high
// across x in [16, 16.5] m, z in [8, 24] m; and the camera that looks across it.
Heightfield wall_terrain(bool wall) {
  Heightfield hf = terrain(257, 0.125f, plane(0, 0));
  if (wall)
    for (int j = 64; j <= 192; ++j)
      for (int i = 128; i <= 132; ++i) hf.set_height(i, j, 1.0f);
  return hf;
}

CameraView wall_camera() {
  return view_320x240({24, 7, 16}, {17.5, 0, 16}, 50);
}

// The terrain shadows itself (terrain.frag terrain_sun_visibility): a wall 1 m high and 0.5 m
// thick across flat ground, the default sun 25 degrees high from -x. Behind the wall, within
// its shadow's length H / tan 25 deg = 2.1 m (1.6 m along x), the ground gets the ambient light
// only: luma 0.3 / (0.3 + 1.2 sin 25 deg) = 0.370 of the lit ground beyond the shadow (common.glsl
// sp_shade; ambient occlusion off), within 0.05. Without the march (terrain_shadow_steps = 0)
// both are lit alike (ratio 1 within 0.05).
TEST(SceneRenderer, TerrainShadowsItselfBehindAWall) {
  auto ctx = make_context();
  if (!ctx) GTEST_SKIP() << "no GL context";
  Heightfield hf = wall_terrain(true);
  const CameraView cam = wall_camera();
  auto mean_luma = [&](SceneRenderer& r, const Image& img, double x0, double x1) {
    double sum = 0;
    int n = 0;
    for (double z = 15.0; z <= 17.0; z += 0.05)
      for (double x = x0; x <= x1; x += 0.05) {
        auto p = r.project(cam, {x, 0.0, z});
        if (!p) continue;
        const int px = int(p->pixel.x()), py = int(p->pixel.y());
        if (px < 0 || px >= img.width || py < 0 || py >= img.height) continue;
        const std::uint8_t* q = img.pixel(px, py);
        sum += 0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2];
        ++n;
      }
    EXPECT_GT(n, 200);
    return sum / std::max(n, 1);
  };
  for (int steps : {32, 0}) {
    RendererDef def;
    def.ao_strength = 0;
    def.terrain_shadow_steps = steps;
    auto r = SceneRenderer::create(*ctx, hf, def);
    ASSERT_TRUE(r.ok()) << r.message();
    auto img = (*r)->render(cam);
    ASSERT_TRUE(img.ok()) << img.message();
    if (steps > 0) ASSERT_TRUE(save_png(output_path("terrain_shadow.actual.png"), img.value()).ok());
    const double shade = mean_luma(**r, *img, 16.9, 17.6), lit = mean_luma(**r, *img, 19.0, 20.0);
    std::printf("terrain_shadow_steps %d: ground behind the wall %.1f, beyond its shadow %.1f: ratio %.3f\n", steps, shade,
                lit, shade / lit);
    EXPECT_NEAR(shade / lit, steps > 0 ? 0.370 : 1.0, 0.05);
  }
  RendererDef bad;
  bad.terrain_shadow_steps = 4;
  auto r = SceneRenderer::create(*ctx, hf, bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("terrain_shadow_steps"), std::string::npos) << r.message();
}

// The terrain's shadow falls on what stands in it: the wall of TerrainShadowsItselfBehindAWall,
// a grey plate (a box 0.6 m square, 0.1 m thick) and a layer of granules (r = 4 cm) on the
// ground in its shadow. The plate's top and the granules (their lighting normal is the bed's,
// up: a granule 1 px in radius shows no sphere shading) face up like the ground, so in the
// shadow they keep the ambient share of the light, 0.3 / (0.3 + 1.2 sin 25°) = 0.372 of their
// luma on the same ground without the wall (the granules' gain 1.12 x 0.9 scales both). With
// terrain_shadow_steps = 0 the wall changes neither (ratio 1).
TEST(SceneRenderer, TerrainShadowFallsOnBodiesAndGranules) {
  auto ctx = make_context();
  if (!ctx) GTEST_SKIP() << "no GL context";
  Heightfield open = wall_terrain(false);
  Heightfield walled = wall_terrain(true);
  const CameraView cam = wall_camera();
  BodyInstance plate;
  plate.kind = BodyShapeKind::Box;
  plate.half_extents = {0.3f, 0.05f, 0.3f};
  plate.position = {17.2, 0.05, 16.0};
  plate.albedo = {0.5f, 0.5f, 0.5f};
  const float r = 0.04f;
  std::vector<Eigen::Vector4f> granules;
  for (float x = 16.75f; x <= 17.65f; x += 2 * r)
    for (float z = 14.0f; z <= 14.8f; z += 2 * r) granules.push_back({x, r, z, r});
  const double kAmbientOnly = 0.3 / (0.3 + 1.2 * 0.38 / std::sqrt(0.6 * 0.6 + 0.38 * 0.38 + 0.55 * 0.55));
  struct Seen {
    double plate = 0, granules = 0;
  };
  auto look = [&](const Heightfield& hf, int steps, const char* png) {
    Seen s;
    RendererDef def;
    def.ao_strength = 0;
    def.terrain_shadow_steps = steps;
    auto r0 = SceneRenderer::create(*ctx, hf, def);
    EXPECT_TRUE(r0.ok()) << r0.message();
    if (!r0.ok()) return s;
    SceneRenderer& rr = **r0;
    ParticleBuffer buf(granules);
    EXPECT_TRUE(rr.set_particles({buf.source({0, 0, 0})}).ok());
    EXPECT_TRUE(rr.set_bodies({plate}).ok());
    FrameFlags ids;
    ids.body_ids = true;
    auto id_img = rr.render(cam, ids);
    auto img = rr.render(cam);
    EXPECT_TRUE(id_img.ok() && img.ok());
    if (!id_img.ok() || !img.ok()) return s;
    EXPECT_TRUE(save_png(output_path(png), *img).ok());
    CameraView close = cam;  // for the eye (docs/rendering.md): 3 m from the plate
    close.position = {19.2, 1.8, 16.6};
    close.target = {17.2, 0.0, 15.2};
    auto near_img = rr.render(close);
    EXPECT_TRUE(near_img.ok() && save_png(output_path(std::string("close_") + png), *near_img).ok());
    // The plate: points of its top face whose pixel the ID render gives to it.
    double sum = 0;
    int n = 0;
    for (double z = 15.8; z <= 16.2; z += 0.02)
      for (double x = 17.0; x <= 17.4; x += 0.02) {
        auto p = rr.project(cam, {x, 0.1, z});
        if (!p) continue;
        const int px = int(p->pixel.x()), py = int(p->pixel.y());
        if (px < 0 || px >= img->width || py < 0 || py >= img->height) continue;
        const std::uint8_t* id = id_img->pixel(px, py);
        if (id[0] != 255 || id[1] != 0 || id[2] != 0) continue;
        const std::uint8_t* q = img->pixel(px, py);
        sum += 0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2];
        ++n;
      }
    EXPECT_GT(n, 100);
    s.plate = sum / std::max(n, 1);
    // The granules: the pixel of each inner granule's top.
    sum = 0;
    n = 0;
    for (const Eigen::Vector4f& g : granules) {
      if (g.x() < 16.85f || g.x() > 17.55f || g.z() < 14.1f || g.z() > 14.7f) continue;
      auto p = rr.project(cam, {g.x(), g.y() + g.w(), g.z()});
      if (!p) continue;
      const int px = int(p->pixel.x()), py = int(p->pixel.y());
      if (px < 0 || px >= img->width || py < 0 || py >= img->height) continue;
      const std::uint8_t* q = img->pixel(px, py);
      sum += 0.2126 * q[0] + 0.7152 * q[1] + 0.0722 * q[2];
      ++n;
    }
    EXPECT_GT(n, 50);
    s.granules = sum / std::max(n, 1);
    return s;
  };
  const Seen lit = look(open, 32, "terrain_shadow_open.actual.png");
  const Seen shade = look(walled, 32, "terrain_shadow_bodies.actual.png");
  const Seen off = look(walled, 0, "terrain_shadow_off.actual.png");
  std::printf("plate luma: open %.1f, behind the wall %.1f (ratio %.3f), march off %.1f (ratio %.3f); granules: open %.1f, "
              "behind the wall %.1f (ratio %.3f), march off %.1f (ratio %.3f); ambient only %.3f\n",
              lit.plate, shade.plate, shade.plate / lit.plate, off.plate, off.plate / lit.plate, lit.granules,
              shade.granules, shade.granules / lit.granules, off.granules, off.granules / lit.granules, kAmbientOnly);
  EXPECT_NEAR(shade.plate / lit.plate, kAmbientOnly, 0.05);
  EXPECT_NEAR(shade.granules / lit.granules, kAmbientOnly, 0.05);
  EXPECT_NEAR(off.plate / lit.plate, 1.0, 0.03);
  EXPECT_NEAR(off.granules / lit.granules, 1.0, 0.03);
}
