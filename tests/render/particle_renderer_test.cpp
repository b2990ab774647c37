// tests render/particle_renderer.cpp through SceneRenderer: Leach's draw order hides particles
// under the surface, a fully faded-in patch stacked at the surface looks like the heightfield,
// fade 0 shows nothing, buffer layouts (stride/offset) and bad sources.
#include "render/particle_renderer.hpp"

#include <gtest/gtest.h>

#include <GL/glcorearb.h>

#include <algorithm>
#include <cmath>

#include "render/camera.hpp"
#include "render_test_util.hpp"

using namespace sandpatch;
using namespace sandpatch::render;
using namespace sandpatch::render::test;

namespace {

constexpr float kR = 0.125f;  // particle radius (m)

// Columns of particles on a 2r grid over [x0, x0+w] x [z0, z0+w], `layers` deep, the top
// layer's centres at the surface + lift (m). Positions are relative to `origin` (the patch frame).
std::vector<Eigen::Vector4f> stacked_patch(const Heightfield& hf, float x0, float z0, float w, int layers, float lift,
                                           const Eigen::Vector3f& origin) {
  std::vector<Eigen::Vector4f> p;
  for (float z = z0 + kR; z < z0 + w; z += 2 * kR)
    for (float x = x0 + kR; x < x0 + w; x += 2 * kR) {
      const float top = hf.sample(x, z) + lift;
      for (int k = 0; k < layers; ++k)
        p.emplace_back(x - origin.x(), top - 2 * kR * float(k) - origin.y(), z - origin.z(), kR);
    }
  return p;
}

struct Scene {
  std::unique_ptr<gl::Context> ctx;
  Heightfield hf;
  std::unique_ptr<SceneRenderer> renderer;
  CameraView cam;
};

Scene make_scene() {
  Scene s{make_context(), terrain(129, 0.5f, hills(1.5f, 24)), nullptr, {}};
  if (!s.ctx) return s;
  auto r = SceneRenderer::create(*s.ctx, s.hf);
  EXPECT_TRUE(r.ok()) << r.message();
  if (r.ok()) s.renderer = std::move(r.value());
  s.cam.position = {32, double(s.hf.sample(32, 26)) + 7.0, 26};
  s.cam.target = {32, double(s.hf.sample(32, 32)), 32};
  return s;
}

// Flat ground (129 samples at 0.5 m, y = 0) seen from about 10 m at 45 degrees, 320 x 240,
// looking at (32, 0, 32), as the default scene's camera sees its patches.
Scene make_flat_scene() {
  Scene s = make_scene();
  if (!s.renderer) return s;
  s.hf = terrain(129, 0.5f, plane(0, 0));
  auto r = SceneRenderer::create(*s.ctx, s.hf);
  EXPECT_TRUE(r.ok()) << r.message();
  s.renderer = r.ok() ? std::move(r.value()) : nullptr;
  s.cam.position = {38, 4, 40};
  s.cam.target = {32, 0, 32};
  s.cam.fov_deg = 45;
  s.cam.width = 320;
  s.cam.height = 240;
  return s;
}

// Pixels whose view ray falls inside the patch square (shrunk by `margin` pixels).
std::vector<std::uint8_t> patch_mask(const Scene& s, float x0, float z0, float w, int margin) {
  const Eigen::Vector3f eye = s.cam.position.cast<float>(), target = s.cam.target.cast<float>();
  const Eigen::Matrix4f vp = perspective(s.cam.fov_deg, float(s.cam.width) / float(s.cam.height), 0.1f, 100.0f) * look_at(eye, target);
  int px0 = s.cam.width, px1 = 0, py0 = s.cam.height, py1 = 0;
  for (float x : {x0, x0 + w})
    for (float z : {z0, z0 + w}) {
      Eigen::Vector4f c = vp * Eigen::Vector4f(x, s.hf.sample(x, z), z, 1);
      const int px = int((c.x() / c.w() * 0.5f + 0.5f) * float(s.cam.width));
      const int py = int((0.5f - c.y() / c.w() * 0.5f) * float(s.cam.height));
      px0 = std::min(px0, px);
      px1 = std::max(px1, px);
      py0 = std::min(py0, py);
      py1 = std::max(py1, py);
    }
  std::vector<std::uint8_t> mask(std::size_t(s.cam.width) * s.cam.height, 0);
  for (int y = std::max(0, py0 + margin); y <= std::min(s.cam.height - 1, py1 - margin); ++y)
    for (int x = std::max(0, px0 + margin); x <= std::min(s.cam.width - 1, px1 - margin); ++x) mask[std::size_t(y) * s.cam.width + x] = 1;
  return mask;
}

int masked(const std::vector<std::uint8_t>& m) {
  int c = 0;
  for (auto v : m) c += v;
  return c;
}

}  // namespace

// Leach's order (terrain, clear depth, particles, terrain again): particles whose tops are
// below the surface leave the image exactly as the terrain alone; lifted above it they show.
TEST(ParticleRenderer, ParticlesUnderTheSurfaceAreInvisible) {
  Scene s = make_scene();
  ASSERT_TRUE(s.renderer);
  auto alone = s.renderer->render(s.cam);
  ASSERT_TRUE(alone.ok()) << alone.message();
  const Eigen::Vector3f origin(29, 0, 29);
  ParticleBuffer under(stacked_patch(s.hf, 29, 29, 6, 3, -1.5f * kR, origin));
  ASSERT_TRUE(s.renderer->set_particles({under.source(origin.cast<double>())}).ok());
  auto with_under = s.renderer->render(s.cam);
  ASSERT_TRUE(with_under.ok()) << with_under.message();
  EXPECT_EQ(s.renderer->stats().terrain_passes, 2);
  EXPECT_EQ(s.renderer->stats().particles, under.count());
  EXPECT_EQ(compare_images(alone.value(), with_under.value()).max_abs, 0);

  ParticleBuffer above(stacked_patch(s.hf, 29, 29, 6, 1, 3 * kR, origin));
  ASSERT_TRUE(s.renderer->set_particles({above.source(origin.cast<double>())}).ok());
  auto with_above = s.renderer->render(s.cam);
  ASSERT_TRUE(with_above.ok());
  const auto mask = patch_mask(s, 29, 29, 6, 2);
  EXPECT_GT(compare_images(alone.value(), with_above.value(), &mask).mean_abs, 5.0);
}

// A fully faded-in patch stacked to the surface (top centres on it, as Leach §5.1 fills a patch)
// and the heightfield it came from look alike inside the patch; with fade 0 the image is the
// terrain's exactly, and half faded lies in between. Every frame is opaque (alpha 255 in every
// pixel): a half-faded patch left alpha below 1 in the frame, and a PNG viewer showed it pale
// over its own background (11,825 of 36,000 pixels of the default scene's patches at 0.8 s).
TEST(ParticleRenderer, FadedInPatchLooksLikeTheHeightfield) {
  Scene s = make_scene();
  ASSERT_TRUE(s.renderer);
  s.hf.fill({56, 56, 14, 14}, 1.0f, Layer::Material1);  // gravel under part of the patch
  s.renderer->heightfield_changed({56, 56, 14, 14});
  auto alone = s.renderer->render(s.cam);
  ASSERT_TRUE(alone.ok());
  const Eigen::Vector3f origin(29, 0, 29);
  ParticleBuffer patch(stacked_patch(s.hf, 29, 29, 6, 3, 0.0f, origin));
  const auto mask = patch_mask(s, 29, 29, 6, 2);
  ASSERT_GT(masked(mask), 500);
  double mean[3], luma_gap[3];
  int k = 0;
  for (float fade : {1.0f, 0.5f, 0.0f}) {
    ASSERT_TRUE(s.renderer->set_particles({patch.source(origin.cast<double>(), 1.0f, fade)}).ok());
    auto img = s.renderer->render(s.cam);
    ASSERT_TRUE(img.ok()) << img.message();
    const ImageDiff d = compare_images(alone.value(), img.value(), &mask);
    double la = 0, lp = 0;  // mean luma inside the patch: the heightfield alone, the patch
    for (int y = 0; y < img->height; ++y)
      for (int x = 0; x < img->width; ++x)
        if (mask[std::size_t(y) * img->width + x]) {
          const std::uint8_t *a = alone->pixel(x, y), *b = img->pixel(x, y);
          la += 0.2126 * a[0] + 0.7152 * a[1] + 0.0722 * a[2];
          lp += 0.2126 * b[0] + 0.7152 * b[1] + 0.0722 * b[2];
        }
    la /= masked(mask);
    lp /= masked(mask);
    std::printf("fade %.1f: patch vs heightfield mean %.2f p99 %.1f max %d; mean luma %.1f vs %.1f\n", fade, d.mean_abs,
                d.p99, d.max_abs, lp, la);
    luma_gap[k] = lp - la;
    mean[k++] = d.mean_abs;
    int translucent = 0;
    for (int y = 0; y < img->height; ++y)
      for (int x = 0; x < img->width; ++x) translucent += img->pixel(x, y)[3] != 255;
    EXPECT_EQ(translucent, 0) << "pixels with alpha below 255 at fade " << fade;
    if (fade == 1.0f) save_png(output_path("patch_fade1.actual.png"), img.value());
  }
  save_png(output_path("patch_alone.actual.png"), alone.value());
  // Alike: the documented bound (docs/rendering.md; measured 13.1: granules under 6 px in
  // radius are shaded as the bed they make up, with half their tint; 19.7 with full sphere
  // shading at every size, which this bound refuses).
  EXPECT_LE(mean[0], 16.0);
  EXPECT_LT(std::fabs(luma_gap[0]), 12.0);  // measured -8.0 (-16.0 with full sphere shading)
  EXPECT_GT(mean[0], 0.5);           // but really drawn
  EXPECT_LT(mean[1], mean[0]);
  EXPECT_EQ(mean[2], 0.0);
}

// Positions in one buffer and a constant radius (stride 12, radius_offset -1), or interleaved
// with other fields (stride 32, position at byte 16): the same image as vec4 (x, y, z, r).
TEST(ParticleRenderer, BufferLayoutsByStrideAndOffset) {
  Scene s = make_scene();
  ASSERT_TRUE(s.renderer);
  const Eigen::Vector3f origin(29, 0, 29);
  const auto pts = stacked_patch(s.hf, 30, 30, 3, 1, kR, origin);
  ParticleBuffer vec4(pts);
  ASSERT_TRUE(s.renderer->set_particles({vec4.source(origin.cast<double>())}).ok());
  auto ref = s.renderer->render(s.cam);
  ASSERT_TRUE(ref.ok());

  std::vector<float> packed, interleaved;
  for (const auto& p : pts) {
    packed.insert(packed.end(), {p.x(), p.y(), p.z()});
    interleaved.insert(interleaved.end(), {-1, -1, -1, -1, p.x(), p.y(), p.z(), -1});
  }
  unsigned bufs[2];
  glGenBuffers(2, bufs);
  glBindBuffer(GL_ARRAY_BUFFER, bufs[0]);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(packed.size() * 4), packed.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, bufs[1]);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(interleaved.size() * 4), interleaved.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  ParticleSource a;
  a.buffer = bufs[0];
  a.count = std::int64_t(pts.size());
  a.stride = 12;
  a.position_offset = 0;
  a.radius_offset = -1;
  a.radius = kR;
  a.origin = origin.cast<double>();
  ParticleSource b = a;
  b.buffer = bufs[1];
  b.stride = 32;
  b.position_offset = 16;
  for (const auto& src : {a, b}) {
    ASSERT_TRUE(s.renderer->set_particles({src}).ok());
    auto img = s.renderer->render(s.cam);
    ASSERT_TRUE(img.ok());
    EXPECT_EQ(compare_images(ref.value(), img.value()).max_abs, 0) << "stride " << src.stride;
  }
  glDeleteBuffers(2, bufs);
}

// Particle scale (Leach §4.3): a patch simulated at unit scale and drawn at scale 2 around its
// origin covers the same pixels as the same patch built at twice the size.
TEST(ParticleRenderer, ParticleScaleScalesPositionsAndRadii) {
  Scene s = make_scene();
  ASSERT_TRUE(s.renderer);
  const Eigen::Vector3d origin(30, double(s.hf.sample(31, 31)) + 1.0, 30);
  std::vector<Eigen::Vector4f> unit, twice;
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) {
      unit.emplace_back(0.25f * float(i), 0.0f, 0.25f * float(j), 0.1f);
      twice.emplace_back(0.5f * float(i), 0.0f, 0.5f * float(j), 0.2f);
    }
  ParticleBuffer bu(unit), bt(twice);
  ASSERT_TRUE(s.renderer->set_particles({bu.source(origin, 2.0f)}).ok());
  auto a = s.renderer->render(s.cam);
  ASSERT_TRUE(s.renderer->set_particles({bt.source(origin, 1.0f)}).ok());
  auto b = s.renderer->render(s.cam);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_LE(compare_images(a.value(), b.value()).mean_abs, 0.05);
}

// Bad sources are refused with errors naming the source and field; nothing changes.
TEST(ParticleRenderer, BadSourceIsRefused) {
  Scene s = make_scene();
  ASSERT_TRUE(s.renderer);
  ParticleSource bad;
  bad.buffer = 7;
  bad.stride = 8;
  bad.fade = 2;
  bad.shading_scale = 0.5f;
  auto st = s.renderer->set_particles({ParticleSource{}, bad});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("particles[0].buffer"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("particles[1].stride = 8"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("particles[1].fade"), std::string::npos) << st.message();
  EXPECT_NE(st.message().find("particles[1].shading_scale = 0.5"), std::string::npos) << st.message();
  bad = ParticleSource{};
  bad.buffer = 7;
  bad.shading_scale = std::nanf("");
  st = s.renderer->set_particles({bad});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("particles[0].shading_scale = nan"), std::string::npos) << st.message();
  // ids: a byte offset of int32s (a multiple of 4), a limit only with them
  bad = ParticleSource{};
  bad.buffer = 7;
  bad.id_offset = 6;
  st = s.renderer->set_particles({bad});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("particles[0].id_offset = 6"), std::string::npos) << st.message();
  bad.id_offset = -1;
  bad.id_limit = 100;
  st = s.renderer->set_particles({bad});
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("particles[0].id_limit = 100"), std::string::npos) << st.message();
}

namespace {

// Rec. 709 luma (0..255).
double luma(const std::uint8_t* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; }

// A granular bed like a live patch of the default scene (r = 0.04 m, 3 layers on a 2r grid,
// top centres half a radius below the flat ground at y = 0) over the square of side `w`
// centred at c, with a bowl-shaped crater of depth D (1 - rho^2 / Rc^2) pressed into it
// (columns within Rc of c lowered by that much). Positions in the world = patch frame.
std::vector<Eigen::Vector4f> bed_with_crater(const Eigen::Vector2f& c, float w, float r, float D, float Rc) {
  std::vector<Eigen::Vector4f> p;
  for (float z = c.y() - 0.5f * w + r; z < c.y() + 0.5f * w; z += 2 * r)
    for (float x = c.x() - 0.5f * w + r; x < c.x() + 0.5f * w; x += 2 * r) {
      const float rho2 = (Eigen::Vector2f(x, z) - c).squaredNorm();
      const float dent = rho2 < Rc * Rc ? D * (1 - rho2 / (Rc * Rc)) : 0.0f;
      for (int k = 0; k < 3; ++k) p.emplace_back(x, -0.5f * r - dent - 2 * r * float(k), z, r);
    }
  return p;
}

// The pixels onto which the ground disc of radius rho around (cx, cz) projects.
std::vector<std::uint8_t> disc_mask(const SceneRenderer& r, const CameraView& cam, double cx, double cz, double rho) {
  std::vector<std::uint8_t> mask(std::size_t(cam.width) * cam.height, 0);
  for (double z = cz - rho; z <= cz + rho; z += 0.005)
    for (double x = cx - rho; x <= cx + rho; x += 0.005) {
      if ((x - cx) * (x - cx) + (z - cz) * (z - cz) > rho * rho) continue;
      auto p = r.project(cam, {x, 0.0, z});
      if (!p) continue;
      const int px = int(p->pixel.x()), py = int(p->pixel.y());
      if (px >= 0 && px < cam.width && py >= 0 && py < cam.height) mask[std::size_t(py) * cam.width + px] = 1;
    }
  return mask;
}

// Mean over the mask of |luma(a) - luma(b)|.
double mean_luma_change(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
  double sum = 0;
  int n = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x)
      if (mask[std::size_t(y) * a.width + x]) {
        sum += std::fabs(luma(a.pixel(x, y)) - luma(b.pixel(x, y)));
        ++n;
      }
  return n ? sum / n : 0;
}

// Luma box-filtered over 5 x 5 pixels (clamped at the image's edge): the shading of the
// surface the granules make up, without the pixel-to-pixel noise of single granules.
std::vector<double> smooth_luma(const Image& a) {
  std::vector<double> out(std::size_t(a.width) * a.height, 0.0);
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      double sum = 0;
      int n = 0;
      for (int dy = -2; dy <= 2; ++dy)
        for (int dx = -2; dx <= 2; ++dx) {
          const int u = x + dx, v = y + dy;
          if (u < 0 || u >= a.width || v < 0 || v >= a.height) continue;
          sum += luma(a.pixel(u, v));
          ++n;
        }
      out[std::size_t(y) * a.width + x] = sum / n;
    }
  return out;
}

// Mean over the mask of |smooth_luma(a) - smooth_luma(b)|: how much the surface's shading
// changed (a crater's lit and shaded walls), not how many granules moved.
double mean_smooth_luma_change(const Image& a, const Image& b, const std::vector<std::uint8_t>& mask) {
  const auto la = smooth_luma(a), lb = smooth_luma(b);
  double sum = 0;
  int n = 0;
  for (std::size_t i = 0; i < mask.size(); ++i)
    if (mask[i]) {
      sum += std::fabs(la[i] - lb[i]);
      ++n;
    }
  return n ? sum / n : 0;
}

}  // namespace

// A crater one granule diameter deep (8 cm, radius 0.5 m) pressed into a live patch's bed of
// r = 0.04 m granules, seen like the default scene's camera (10 m away, 45 degrees, 320 x 240).
// Metric: the mean over the crater's pixels (the ground disc of 0.6 m around its centre) of
// |luma(with crater) - luma(flat bed)|, Rec. 709 luma in 0..255, each image first box-filtered
// over 5 x 5 pixels (granules are 1.5 px in radius here: unfiltered, every granule that moved
// counts, however flat the shading). With the patch's footprint cut out of the second terrain
// pass it is above 8 (its walls lit as slopes from the granules' depth pre-pass, its floor
// occluded); in Leach's order without the cut the heightfield covers the crater: the change is
// only the granule caps that sank below the surface, and it is checked to be at most half.
TEST(ParticleRenderer, CraterInAPatchShowsWithItsFootprintCutOut) {
  Scene s = make_flat_scene();
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  const Eigen::Vector2f c(32, 32);
  const float r_g = 0.04f, w = 3.0f;
  ParticleBuffer flat(bed_with_crater(c, w, r_g, 0.0f, 0.5f));
  ParticleBuffer crater(bed_with_crater(c, w, r_g, 2 * r_g, 0.5f));
  const auto mask = disc_mask(*s.renderer, s.cam, c.x(), c.y(), 0.6);
  ASSERT_GT(masked(mask), 300);
  s.renderer->clear_particles();
  auto bare = s.renderer->render(s.cam);
  ASSERT_TRUE(bare.ok());
  double change[2], raw[2];  // [cut]
  for (int cut = 0; cut < 2; ++cut) {
    Image img[2];
    for (int k = 0; k < 2; ++k) {
      ParticleSource src = (k ? crater : flat).source({0, 0, 0});
      if (cut) {
        src.footprint = {c.x() - 0.5 * w, c.y() - 0.5 * w, c.x() + 0.5 * w, c.y() + 0.5 * w};
        src.footprint_band = 0.25f;
      }
      ASSERT_TRUE(s.renderer->set_particles({src}).ok());
      auto res = s.renderer->render(s.cam);
      ASSERT_TRUE(res.ok()) << res.message();
      img[k] = std::move(res.value());
    }
    if (cut) ASSERT_TRUE(save_png(output_path("patch_crater.actual.png"), img[1]).ok());
    change[cut] = mean_smooth_luma_change(img[0], img[1], mask);
    raw[cut] = mean_luma_change(img[0], img[1], mask);
    if (cut) {
      // The flat bed seen in full is about as bright as the terrain it replaces.
      double lb = 0, lt = 0;
      for (int y = 0; y < img[0].height; ++y)
        for (int x = 0; x < img[0].width; ++x)
          if (mask[std::size_t(y) * img[0].width + x]) {
            lb += luma(img[0].pixel(x, y));
            lt += luma(bare->pixel(x, y));
          }
      std::printf("flat bed mean luma %.1f, terrain %.1f\n", lb / masked(mask), lt / masked(mask));
      EXPECT_LT(std::fabs(lb - lt) / masked(mask), 12.0);
    }
  }
  std::printf("crater pixels %d: mean |smoothed luma change| %.1f with the footprint cut, %.1f without "
              "(unfiltered %.1f, %.1f)\n", masked(mask), change[1], change[0], raw[1], raw[0]);
  EXPECT_GT(change[1], 8.0) << "the crater reads as a crater";
  EXPECT_GT(change[1], 2.0 * change[0]) << "the cut is what shows it";
}

namespace {

// Pixels whose luma differs by more than `threshold` from the median of their 3 x 3
// neighbourhood (themselves included), within the mask: a speck, a lone pixel or a line one
// pixel wide (a median keeps edges and areas; an edge pixel is its neighbourhood's majority).
int count_specks(const Image& img, const std::vector<std::uint8_t>& mask, double threshold) {
  int n = 0;
  for (int y = 1; y + 1 < img.height; ++y)
    for (int x = 1; x + 1 < img.width; ++x) {
      if (!mask[std::size_t(y) * img.width + x]) continue;
      double v[9];
      int k = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) v[k++] = luma(img.pixel(x + dx, y + dy));
      std::nth_element(v, v + 4, v + 9);
      n += std::fabs(luma(img.pixel(x, y)) - v[4]) > threshold;
    }
  return n;
}

}  // namespace

// Where a coarse patch meets the terrain: a bed of r = 0.12 m granules (a patch of the default
// scene's 4 cm sand at particle scale 3), two layers, its top column by column up to half a
// radius above or below the ground (a worked bed), a 4 m footprint with the scene runner's band
// (six diameters), and granules thrown out onto the ground around it; seen from 10 m like
// CraterInAPatchShowsWithItsFootprintCutOut. Specks (count_specks, luma more than 40 from its
// 3 x 3 median) over the pixels of the ground within 0.6 m of the footprint's edge: few (the
// bed's normal taken across a silhouette no longer tilts a pixel wildly, and a granule of a
// coarse patch is shaded as the finer sand it stands for, not as a ball with a hard outline).
TEST(ParticleRenderer, FewSpecksWhereACoarsePatchMeetsTheTerrain) {
  Scene s = make_flat_scene();
  if (!s.renderer) GTEST_SKIP() << "no GL context";
  const float r = 0.12f, w = 4.0f, cx = 32, cz = 32;
  std::uint32_t seed = 12345;
  auto rnd = [&seed] {  // uniform in [0, 1)
    seed = seed * 1664525u + 1013904223u;
    return float(seed >> 8) / 16777216.0f;
  };
  std::vector<Eigen::Vector4f> p;
  for (float z = cz - 0.5f * w + r; z < cz + 0.5f * w; z += 2 * r)
    for (float x = cx - 0.5f * w + r; x < cx + 0.5f * w; x += 2 * r) {
      const float top = -0.5f * r + r * (rnd() - 0.5f);
      for (int k = 0; k < 2; ++k) p.emplace_back(x, top - 2 * r * float(k), z, r);
    }
  for (int k = 0; k < 60; ++k) {  // thrown out: on the ground within 1 m outside the footprint
    const float a = 6.2831853f * rnd(), d = 0.5f * w + 0.2f + 0.8f * rnd();
    const float x = cx + d * std::cos(a), z = cz + d * std::sin(a);
    if (std::max(std::fabs(x - cx), std::fabs(z - cz)) > 0.5f * w + r) p.emplace_back(x, r, z, r);
  }
  ParticleBuffer buf(p);
  ParticleSource src = buf.source({0, 0, 0});
  src.footprint = {cx - 0.5 * w, cz - 0.5 * w, cx + 0.5 * w, cz + 0.5 * w};
  src.footprint_band = 12 * r;
  src.shading_scale = 3;
  ASSERT_TRUE(s.renderer->set_particles({src}).ok());
  auto img = s.renderer->render(s.cam);
  ASSERT_TRUE(img.ok()) << img.message();
  ASSERT_TRUE(save_png(output_path("patch_edge.actual.png"), *img).ok());
  std::vector<std::uint8_t> edge(std::size_t(s.cam.width) * s.cam.height, 0);
  for (double z = cz - 0.5 * w - 0.6; z <= cz + 0.5 * w + 0.6; z += 0.01)
    for (double x = cx - 0.5 * w - 0.6; x <= cx + 0.5 * w + 0.6; x += 0.01) {
      const double out = std::max(std::fabs(x - cx), std::fabs(z - cz)) - 0.5 * w;  // m outside the footprint
      if (std::fabs(out) > 0.6) continue;
      auto q = s.renderer->project(s.cam, {x, 0.0, z});
      if (!q) continue;
      const int px = int(q->pixel.x()), py = int(q->pixel.y());
      if (px >= 0 && px < s.cam.width && py >= 0 && py < s.cam.height) edge[std::size_t(py) * s.cam.width + px] = 1;
    }
  ASSERT_GT(masked(edge), 5000);
  const int specks = count_specks(*img, edge, 40.0);
  std::printf("patch edge: %d pixels, %d specks (%.2f %%)\n", masked(edge), specks, 100.0 * specks / masked(edge));
  EXPECT_LT(specks, masked(edge) / 200) << "fewer than 0.5 % of the edge's pixels";
}
