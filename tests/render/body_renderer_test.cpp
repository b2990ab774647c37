// tests render/body_renderer.cpp through SceneRenderer: every body shape shows at its
// projected centre (ID colours), lit bodies change the picture where they are and nowhere far
// from them, the terrain hides a body below the ground, bad bodies are refused.
#include "render/body_renderer.hpp"

#include <gtest/gtest.h>

#include "render_test_util.hpp"

using namespace sandpatch;
using namespace sandpatch::render;
using namespace sandpatch::render::test;

namespace {

struct Scene {
  std::unique_ptr<gl::Context> ctx;
  Heightfield hf;
  std::unique_ptr<SceneRenderer> renderer;
  CameraView cam;
};

Scene make_scene(const ProceduralHeightsDef& p) {
  Scene s{make_context(), terrain(129, 0.5f, p), nullptr, {}};
  if (!s.ctx) return s;
  auto r = SceneRenderer::create(*s.ctx, s.hf);
  EXPECT_TRUE(r.ok()) << r.message();
  if (r.ok()) s.renderer = std::move(r.value());
  s.cam.position = {38, 4, 40};
  s.cam.target = {32, 0.5, 32};
  s.cam.fov_deg = 45;
  return s;
}

std::vector<BodyInstance> one_of_each(const Heightfield& hf) {
  std::vector<BodyInstance> bodies;
  const double xs[] = {29.5, 31, 32.5, 34, 35};
  const BodyShapeKind kinds[] = {BodyShapeKind::Sphere, BodyShapeKind::Box, BodyShapeKind::Cylinder,
                                 BodyShapeKind::Capsule, BodyShapeKind::Mesh};
  for (int k = 0; k < 5; ++k) {
    BodyInstance b;
    b.kind = kinds[k];
    b.radius = 0.3f;
    b.height = 0.6f;
    b.half_extents = {0.3f, 0.3f, 0.3f};
    if (b.kind == BodyShapeKind::Mesh) {  // a tetrahedron around its centroid
      b.vertices = {{0.4f, -0.3f, 0.0f}, {-0.4f, -0.3f, 0.3f}, {-0.4f, -0.3f, -0.3f}, {0.0f, 0.5f, 0.0f}};
      for (auto& v : b.vertices) v -= Eigen::Vector3f(-0.1f, -0.1f, 0.0f);
      b.triangles = {{0, 1, 2}, {0, 3, 1}, {1, 3, 2}, {2, 3, 0}};
    }
    b.position = {xs[k], double(hf.sample(float(xs[k]), 32.0f)) + 0.8, 32.0};
    b.orientation = Eigen::Quaternionf(Eigen::AngleAxisf(0.4f * float(k), Eigen::Vector3f(0, 1, 0)));
    b.albedo = body_palette(k);
    bodies.push_back(b);
  }
  return bodies;
}

}  // namespace

TEST(BodyRenderer, EveryShapeShowsAtItsProjectedCentre) {
  Scene s = make_scene(plane(0, 0));
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  const auto bodies = one_of_each(s.hf);
  ASSERT_TRUE(s.renderer->set_bodies(bodies).ok());
  FrameFlags ids;
  ids.body_ids = true;
  auto img = s.renderer->render(s.cam, ids);
  ASSERT_TRUE(img.ok()) << img.message();
  EXPECT_EQ(s.renderer->stats().bodies, 5);
  expect_matches_reference(img.value(), "bodies_ids");
  for (std::size_t k = 0; k < bodies.size(); ++k) {
    auto p = s.renderer->project(s.cam, bodies[k].position);
    ASSERT_TRUE(p.has_value());
    const std::uint8_t* px = img->pixel(int(p->pixel.x()), int(p->pixel.y()));
    const auto id = body_id_color(int(k));
    EXPECT_EQ(px[0], id[0]) << "body " << k;
    EXPECT_EQ(px[1], id[1]) << "body " << k;
    EXPECT_EQ(px[2], id[2]) << "body " << k;
  }
}

TEST(BodyRenderer, LitBodiesChangeThePictureOnlyAroundThem) {
  Scene s = make_scene(hills(0.5f, 16));
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  auto bare = s.renderer->render(s.cam);
  ASSERT_TRUE(bare.ok()) << bare.message();
  const auto bodies = one_of_each(s.hf);
  ASSERT_TRUE(s.renderer->set_bodies(bodies).ok());
  auto with = s.renderer->render(s.cam);
  ASSERT_TRUE(with.ok()) << with.message();
  expect_matches_reference(with.value(), "bodies_lit");
  for (const BodyInstance& b : bodies) {
    auto p = s.renderer->project(s.cam, b.position);
    ASSERT_TRUE(p.has_value());
    const std::uint8_t* a = bare->pixel(int(p->pixel.x()), int(p->pixel.y()));
    const std::uint8_t* c = with->pixel(int(p->pixel.x()), int(p->pixel.y()));
    const int diff = std::abs(a[0] - c[0]) + std::abs(a[1] - c[1]) + std::abs(a[2] - c[2]);
    EXPECT_GT(diff, 60) << "sand and a body's lit albedo differ by more than 60 (sum of R, G, B)";
  }
  // The sky and the far terrain are untouched (ambient occlusion reaches ao_radius around a body).
  for (int x = 0; x < s.cam.width; ++x) {
    const std::uint8_t* a = bare->pixel(x, 2);
    const std::uint8_t* c = with->pixel(x, 2);
    EXPECT_TRUE(a[0] == c[0] && a[1] == c[1] && a[2] == c[2]) << "row 2, x = " << x;
  }
}

TEST(BodyRenderer, TerrainHidesABodyBelowTheGround) {
  // A sphere wholly under flat ground: none of its pixels show (depth test against the terrain).
  Scene s = make_scene(plane(0, 0));
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  BodyInstance b;
  b.kind = BodyShapeKind::Sphere;
  b.radius = 0.3f;
  b.position = {32, -0.5, 32};  // wholly below the flat ground at y = 0
  ASSERT_TRUE(s.renderer->set_bodies({b}).ok());
  FrameFlags ids;
  ids.body_ids = true;
  auto img = s.renderer->render(s.cam, ids);
  ASSERT_TRUE(img.ok()) << img.message();
  const auto id = body_id_color(0);
  int shown = 0;
  for (int y = 0; y < img->height; ++y)
    for (int x = 0; x < img->width; ++x) {
      const std::uint8_t* p = img->pixel(x, y);
      shown += p[0] == id[0] && p[1] == id[1] && p[2] == id[2];
    }
  EXPECT_EQ(shown, 0);
  // Raised half out of the ground it shows.
  b.position.y() = 0.1;
  ASSERT_TRUE(s.renderer->set_bodies({b}).ok());
  img = s.renderer->render(s.cam, ids);
  ASSERT_TRUE(img.ok());
  for (int y = 0; y < img->height; ++y)
    for (int x = 0; x < img->width; ++x) {
      const std::uint8_t* p = img->pixel(x, y);
      shown += p[0] == id[0] && p[1] == id[1] && p[2] == id[2];
    }
  EXPECT_GT(shown, 20);
  // Turned off for a frame, none.
  FrameFlags none = ids;
  none.bodies = false;
  img = s.renderer->render(s.cam, none);
  ASSERT_TRUE(img.ok());
  EXPECT_EQ(s.renderer->stats().bodies, 0);
}

TEST(BodyRenderer, BadBodiesAreRefusedAndNothingChanges) {
  Scene s = make_scene(plane(0, 0));
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  BodyInstance ok;
  ok.position = {32, 0.5, 32};
  ASSERT_TRUE(s.renderer->set_bodies({ok}).ok());
  BodyInstance bad = ok;
  bad.kind = BodyShapeKind::Box;
  bad.half_extents = {0.1f, -0.2f, 0.1f};
  auto st = s.renderer->set_bodies({ok, bad});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("bodies[1].half_extents"), std::string::npos) << st.message();
  auto img = s.renderer->render(s.cam);
  ASSERT_TRUE(img.ok());
  EXPECT_EQ(s.renderer->stats().bodies, 1);
}

// Bodies receive the bodies' shadows: a grey sphere (albedo 0.5) lit at the pixel of its
// projected centre, where the surface's normal points at the eye, then with a plate 1.5 m
// toward the sun from it. Lit, the pixel is 0.5 S(0.3 + 1.2 n.sun) (common.glsl sp_shade, S its
// shoulder above 0.9); in the plate's shadow only the ambient 0.5 x 0.3 is left, so the ratio
// shadowed / lit is 0.3 / S(0.3 + 1.2 n.sun) (within 0.04: 8-bit rounding, ambient occlusion). Alone, the
// sphere does not shadow its own lit side: its pixels equal those of a renderer without a
// shadow map (mean difference below 1, of 0..255).
TEST(BodyRenderer, BodiesReceiveShadowsAndDoNotShadowTheirLitSide) {
  Scene s = make_scene(plane(0, 0));
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  RendererDef no_shadows;
  no_shadows.shadow_map_size = 0;
  auto plain = SceneRenderer::create(*s.ctx, s.hf, no_shadows);
  ASSERT_TRUE(plain.ok()) << plain.message();
  s.cam.position = {30, 2, 38};
  s.cam.target = {32, 0.5, 32};
  BodyInstance ball;
  ball.kind = BodyShapeKind::Sphere;
  ball.radius = 0.3f;
  ball.position = {32, 0.5, 32};
  ball.albedo = {0.5f, 0.5f, 0.5f};
  const Eigen::Vector3d sun = RendererDef{}.sun_direction.cast<double>().normalized();
  BodyInstance plate;
  plate.kind = BodyShapeKind::Box;
  plate.half_extents = {0.5f, 0.05f, 0.5f};
  plate.position = ball.position + 1.5 * sun;
  plate.albedo = {0.2f, 0.6f, 0.2f};

  FrameFlags ids;
  ids.body_ids = true;
  ASSERT_TRUE(s.renderer->set_bodies({ball, plate}).ok());
  auto id_img = s.renderer->render(s.cam, ids);
  ASSERT_TRUE(id_img.ok()) << id_img.message();
  const auto c = s.renderer->project(s.cam, ball.position);
  ASSERT_TRUE(c.has_value());
  const int cx = int(c->pixel.x()), cy = int(c->pixel.y());
  const auto id0 = body_id_color(0);
  ASSERT_EQ(id_img->pixel(cx, cy)[2], id0[2]) << "the plate must not hide the ball's centre";
  auto shadowed = s.renderer->render(s.cam);
  ASSERT_TRUE(shadowed.ok());
  ASSERT_TRUE(save_png(output_path("body_shadowed.actual.png"), shadowed.value()).ok());

  ASSERT_TRUE(s.renderer->set_bodies({ball}).ok());
  id_img = s.renderer->render(s.cam, ids);
  ASSERT_TRUE(id_img.ok());
  auto lit = s.renderer->render(s.cam);
  ASSERT_TRUE(lit.ok());
  ASSERT_TRUE((*plain)->set_bodies({ball}).ok());
  auto lit_plain = (*plain)->render(s.cam);
  ASSERT_TRUE(lit_plain.ok());

  const Eigen::Vector3d n = (s.cam.position - ball.position).normalized();
  const double light = 0.3 + 1.2 * std::max(0.0, n.dot(sun));
  const double shoulder = light <= 0.9 ? light : 0.9 + 0.3 * (1.0 - std::exp(-(light - 0.9) / 0.3));
  const double ratio_expected = 0.3 / shoulder;
  const double g_lit = lit->pixel(cx, cy)[1], g_shadow = shadowed->pixel(cx, cy)[1];
  std::printf("ball centre: lit %.0f, in the plate's shadow %.0f: ratio %.3f (expected %.3f)\n", g_lit, g_shadow,
              g_shadow / g_lit, ratio_expected);
  ASSERT_GT(g_lit, 100.0);
  EXPECT_NEAR(g_shadow / g_lit, ratio_expected, 0.04);

  double sum = 0;
  int count = 0;
  for (int y = 0; y < id_img->height; ++y)
    for (int x = 0; x < id_img->width; ++x) {
      const std::uint8_t* p = id_img->pixel(x, y);
      if (p[0] != id0[0] || p[1] != id0[1] || p[2] != id0[2]) continue;
      const std::uint8_t *a = lit->pixel(x, y), *b = lit_plain->pixel(x, y);
      sum += std::max({std::abs(a[0] - b[0]), std::abs(a[1] - b[1]), std::abs(a[2] - b[2])});
      ++count;
    }
  ASSERT_GT(count, 50);
  std::printf("ball alone, %d pixels: mean difference to no shadow map %.2f\n", count, sum / count);
  EXPECT_LT(sum / count, 1.0);
}
