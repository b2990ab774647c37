// tests manager/depth_conversion.cpp: the top-down depth render of spheres (Leach & Marais
// §5.2) against the analytic sphere surface and a CPU ray-cast reference, and the write
// back into the heightfield.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "gl/context.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/depth_conversion.hpp"

using namespace sandpatch;

namespace {

// One GL context for the whole test program (created lazily on the test thread).
gl::Context& context() {
  static auto ctx = gl::Context::create();
  EXPECT_TRUE(ctx.ok()) << (ctx.ok() ? "" : ctx.message());
  return **ctx;
}

// CPU reference: the highest sphere surface above a texel centre, or the floor.
float raycast(const std::vector<float>& s, float x, float z, float floor_y) {
  float best = floor_y;
  for (std::size_t i = 0; i < s.size(); i += 4) {
    const float dx = x - s[i], dz = z - s[i + 2], r = s[i + 3];
    const float d2 = dx * dx + dz * dz;
    if (d2 <= r * r) best = std::max(best, s[i + 1] + std::sqrt(r * r - d2));
  }
  return best;
}

}  // namespace

// A single sphere (R = 1 m, centre height 0.5 m): texels inside 0.98 R read the analytic
// cap height 0.5 + sqrt(R² − d²) within 2 mm (the quad is rasterised at texel centres, depth is
// 32-bit float over 4 m); texels outside 1.02 R read the floor exactly (1e-5 m).
TEST(DepthConversion, SingleSphereMatchesAnalyticCap) {
  context();
  auto r = ParticleDepthRenderer::create({.resolution = 256});
  ASSERT_TRUE(r.ok()) << r.message();
  const std::vector<float> s = {0.0f, 0.5f, 0.0f, 1.0f};
  auto img = (*r)->render(s.data(), 1, -2, -2, 2, 2, -1.0f, 3.0f);
  ASSERT_TRUE(img.ok()) << img.message();
  int inside = 0;
  for (int v = 0; v < img->height; ++v) {
    for (int u = 0; u < img->width; ++u) {
      const float x = -2 + (u + 0.5f) * 4.0f / 256, z = -2 + (v + 0.5f) * 4.0f / 256;
      const float d = std::sqrt(x * x + z * z);
      if (d < 0.98f) {
        ++inside;
        ASSERT_NEAR(img->at(u, v), 0.5f + std::sqrt(1 - d * d), 2e-3f) << u << "," << v;
      } else if (d > 1.02f) {
        ASSERT_NEAR(img->at(u, v), -1.0f, 1e-5f) << u << "," << v;
      }
    }
  }
  EXPECT_GT(inside, 3000);  // π (0.98·64)² ≈ 12,300 texels; guards against an empty image
}

// A random heap of 800 spheres: every texel equals the CPU ray-cast reference within 2 mm,
// except texels within half a texel of a silhouette edge (counted; at most 3% of texels);
// the CPU fallback renderer equals the ray cast everywhere.
TEST(DepthConversion, RandomSpheresMatchCpuRaycast) {
  context();
  auto r = ParticleDepthRenderer::create({.resolution = 128});
  ASSERT_TRUE(r.ok()) << r.message();
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> ux(0.0f, 2.0f), uy(0.0f, 0.5f), ur(0.03f, 0.08f);
  std::vector<float> s;
  for (int i = 0; i < 800; ++i) s.insert(s.end(), {ux(rng), uy(rng), ux(rng), ur(rng)});
  auto img = (*r)->render(s.data(), 800, 0, 0, 2, 2, -0.2f, 1.0f);
  ASSERT_TRUE(img.ok()) << img.message();
  const HeightImage cpu = render_heights_cpu(s.data(), 800, 128, 0, 0, 2, 2, -0.2f);
  int off = 0, cpu_off = 0;
  for (int v = 0; v < 128; ++v)
    for (int u = 0; u < 128; ++u) {
      const float x = (u + 0.5f) * 2.0f / 128, z = (v + 0.5f) * 2.0f / 128;
      const float ref = raycast(s, x, z, -0.2f);
      if (std::abs(img->at(u, v) - ref) > 2e-3f) ++off;
      if (std::abs(cpu.at(u, v) - ref) > 1e-5f) ++cpu_off;  // same formula at the same texel centres
    }
  EXPECT_LE(off, int(0.03 * 128 * 128)) << off << " texels differ";
  EXPECT_EQ(cpu_off, 0);
}

// A rectangle three times as long as it is wide, imaged with square texels (a car's patch;
// the demotion sizes each side by the texel, demotion.cpp render_size): 192 texels along x
// and 64 rows along z. The CPU render equals the ray cast at every texel centre; the GL
// render (its viewport 192 × 64 of its 256-texel target) within 2 mm but at silhouette edges
// (at most 3 % of texels), as the square render.
TEST(DepthConversion, ARectangleRendersInSquareTexels) {
  context();
  auto r = ParticleDepthRenderer::create({.resolution = 256});
  ASSERT_TRUE(r.ok()) << r.message();
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> ux(0.0f, 3.0f), uz(0.0f, 1.0f), uy(0.0f, 0.5f), ur(0.03f, 0.08f);
  std::vector<float> s;
  for (int i = 0; i < 600; ++i) s.insert(s.end(), {ux(rng), uy(rng), uz(rng), ur(rng)});
  const int W = 192, H = 64;
  auto img = (*r)->render(s.data(), 600, 0, 0, 3, 1, -0.2f, 1.0f, W, H);
  ASSERT_TRUE(img.ok()) << img.message();
  ASSERT_EQ(img->width, W);
  ASSERT_EQ(img->height, H);
  const HeightImage cpu = render_heights_cpu(s.data(), 600, W, H, 0, 0, 3, 1, -0.2f);
  ASSERT_EQ(cpu.width, W);
  ASSERT_EQ(cpu.height, H);
  int off = 0, cpu_off = 0;
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const float x = (u + 0.5f) * 3.0f / W, z = (v + 0.5f) * 1.0f / H;  // square texels of 1/64 m
      const float ref = raycast(s, x, z, -0.2f);
      if (std::abs(img->at(u, v) - ref) > 2e-3f) ++off;
      if (std::abs(cpu.at(u, v) - ref) > 1e-5f) ++cpu_off;
    }
  EXPECT_LE(off, int(0.03 * W * H)) << off << " texels differ";
  EXPECT_EQ(cpu_off, 0);
  // in bands of rows, as a staged demotion renders it: the same image
  HeightImage bands = render_heights_cpu(nullptr, 0, W, H, 0, 0, 3, 1, -0.2f);
  for (int v0 = 0; v0 < H; v0 += 24) render_heights_cpu_rows(s.data(), 600, bands, v0, v0 + 24);
  EXPECT_EQ(bands.h, cpu.h);
}

// A CPU render spread over frames, band by band (render_heights_cpu_rows, as a staged
// demotion does it), gives exactly the image of one whole render, whatever the band height.
TEST(DepthConversion, CpuRenderInBandsEqualsTheWholeRender) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> ux(0.0f, 2.0f), uy(0.0f, 0.5f), ur(0.03f, 0.08f);
  std::vector<float> s;
  for (int i = 0; i < 800; ++i) s.insert(s.end(), {ux(rng), uy(rng), ux(rng), ur(rng)});
  const HeightImage whole = render_heights_cpu(s.data(), 800, 100, 0, 0, 2, 2, -0.2f);
  for (const int rows : {1, 7, 64, 100}) {
    HeightImage bands = render_heights_cpu(nullptr, 0, 100, 0, 0, 2, 2, -0.2f);
    for (int v0 = 0; v0 < 100; v0 += rows) render_heights_cpu_rows(s.data(), 800, bands, v0, v0 + rows);
    EXPECT_EQ(bands.h, whole.h) << "bands of " << rows << " rows";
  }
}

// The hat means of a region (hat_means: the tent in x, then in z) are those of
// HeightImage::hat_mean sample by sample: the same texels and weights, only the order of the
// double sums differs; every float agrees within 1e-6 relative (measured: all equal), over a
// region that reaches past the image on two sides (its tents clipped there) and with samples
// finer and coarser than the texels.
TEST(DepthConversion, HatMeansAgreeWithHatMean) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> ux(0.0f, 3.0f), uy(0.0f, 0.5f), ur(0.03f, 0.08f);
  std::vector<float> s;
  for (int i = 0; i < 1500; ++i) s.insert(s.end(), {ux(rng), uy(rng), ux(rng), ur(rng)});
  const HeightImage img = render_heights_cpu(s.data(), 1500, 300, 200, -0.25f, -0.25f, 2.75f, 1.75f, -0.2f);
  for (const float sp : {0.5f, 0.25f, 0.005f}) {
    const int n = int(std::lround(2.0f / sp));
    const GridRegion r{-1, -1, n + 4, n / 2 + 4};
    const std::vector<float> h = hat_means(img, r, sp);
    ASSERT_EQ(h.size(), std::size_t(r.ni) * r.nj);
    int equal = 0;
    for (int j = 0; j < r.nj; ++j)
      for (int i = 0; i < r.ni; ++i) {
        const float want = img.hat_mean(float(r.i0 + i) * sp, float(r.j0 + j) * sp, sp);
        const float got = h[std::size_t(j) * r.ni + i];
        EXPECT_NEAR(got, want, 1e-6f * std::max(1.0f, std::abs(want))) << "sample " << i << ", " << j << " at spacing " << sp;
        equal += got == want;
      }
    std::printf("hat means at spacing %.3f m: %d of %d equal to hat_mean\n", double(sp), equal, r.ni * r.nj);
  }
}

// Writing a flat layer back: a square lattice of touching spheres (r = 5 cm) whose tops are
// at 1.0 m covers the region; every written sample lies between the lowest visible surface
// (the floor at 0.9 m, seen between spheres) and 1.0 m, the region is smooth (neighbouring
// samples differ by < 1 cm), and samples two or more beyond the border band are untouched.
TEST(DepthConversion, WritesRegionAndStitchesBorder) {
  context();
  HeightfieldDef d;
  d.samples_x = d.samples_z = 41;
  d.spacing = 0.1f;
  d.initial_height = 0.5f;
  auto hf = Heightfield::create(d);
  ASSERT_TRUE(hf.ok());
  const GridRegion region{10, 10, 21, 21};  // samples 10..30: x, z in [1.0, 3.0] m
  std::vector<float> s;
  for (float z = 0.95f; z < 3.1f; z += 0.1f)
    for (float x = 0.95f; x < 3.1f; x += 0.1f) s.insert(s.end(), {x, 0.95f, z, 0.05f});
  auto r = ParticleDepthRenderer::create({.resolution = 512});
  ASSERT_TRUE(r.ok()) << r.message();
  auto img = (*r)->render(s.data(), s.size() / 4, 0.95f, 0.95f, 3.05f, 3.05f, 0.9f, 2.0f);
  ASSERT_TRUE(img.ok()) << img.message();
  write_to_heightfield(*img, region, *hf, 1);
  // Interior: samples whose 3x3 neighbourhood and its neighbours stay inside the region (the
  // outer two rows mix with the 0.5 m terrain outside, which is the stitch's job).
  for (int j = 12; j < 28; ++j)
    for (int i = 12; i < 28; ++i) {
      const float h = hf->height(i, j);
      EXPECT_GE(h, 0.9f);
      EXPECT_LE(h, 1.0f + 1e-4f);
      EXPECT_LT(std::abs(h - hf->height(i + 1, j)), 0.01f) << i << "," << j;
    }
  for (int j = 0; j < 41; ++j)
    for (int i = 0; i < 41; ++i)
      if (i < 8 || i > 32 || j < 8 || j > 32) {
        ASSERT_EQ(hf->height(i, j), 0.5f) << i << "," << j;
      }
}

TEST(DepthConversion, RefusesBadResolutionAndRectangle) {
  context();
  auto bad = ParticleDepthRenderer::create({.resolution = 4});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("resolution"), std::string::npos);
  auto r = ParticleDepthRenderer::create({.resolution = 32});
  ASSERT_TRUE(r.ok());
  EXPECT_FALSE((*r)->render(nullptr, 0, 1, 0, 0, 1, 0, 1).ok());
}

// write_to_heightfield with a RenderBaseline (the fill rendered the same way): where the
// render did not change beyond the fill's rise, the heights of before come back exactly,
// however rough the render; where it changed by more than the tolerance, the sample is
// Leach's smoothed render.
TEST(DepthConversion, BaselineKeepsUnmovedGroundAndTakesMovedGround) {
  HeightfieldDef d;
  d.samples_x = d.samples_z = 41;
  d.spacing = 0.1f;
  auto hf = Heightfield::create(d);
  ASSERT_TRUE(hf.ok());
  for (int j = 0; j < 41; ++j)
    for (int i = 0; i < 41; ++i) hf->set_height(i, j, 0.5f + 0.02f * std::sin(0.7f * float(i)) * std::cos(0.5f * float(j)));
  const Heightfield original = *hf;
  const GridRegion region{10, 10, 21, 21};
  std::vector<float> h0(std::size_t(region.ni) * region.nj);
  hf->read(region, h0.data());
  // A rough render of the fill: the surface plus a granular pattern of ±1 cm.
  HeightImage fill;
  fill.width = fill.height = 256;
  fill.x0 = fill.z0 = 0.95f;
  fill.x1 = fill.z1 = 3.05f;
  fill.h.resize(256 * 256);
  for (int v = 0; v < 256; ++v)
    for (int u = 0; u < 256; ++u) {
      const float x = fill.x0 + (u + 0.5f) * (fill.x1 - fill.x0) / 256, z = fill.z0 + (v + 0.5f) * (fill.z1 - fill.z0) / 256;
      fill.h[std::size_t(v) * 256 + u] = hf->sample(x, z) + 0.01f * std::sin(97.0f * x) * std::sin(89.0f * z);
    }
  // Later: risen by 2 mm everywhere (the rebound) and dug 5 cm deep in x, z in [1.8, 2.2].
  const float rise = 0.002f;
  HeightImage now = fill;
  for (int v = 0; v < 256; ++v)
    for (int u = 0; u < 256; ++u) {
      const float x = now.x0 + (u + 0.5f) * (now.x1 - now.x0) / 256, z = now.z0 + (v + 0.5f) * (now.z1 - now.z0) / 256;
      now.h[std::size_t(v) * 256 + u] += rise - ((x > 1.8f && x < 2.2f && z > 1.8f && z < 2.2f) ? 0.05f : 0.0f);
    }
  const RenderBaseline base{&fill, &h0, 0.025f, rise};
  write_to_heightfield(now, region, *hf, 1, &base);
  // Unmoved: at least 3 samples from the dug square and 2 from the border band: exact.
  for (int j = 12; j <= 28; ++j)
    for (int i = 12; i <= 28; ++i) {
      const bool near_dig = i >= 15 && i <= 25 && j >= 15 && j <= 25;
      if (!near_dig) EXPECT_NEAR(hf->height(i, j), original.height(i, j), 1e-5f) << i << "," << j;
    }
  // Moved: the dug square's centre is Leach's rendered surface, about 5 cm down.
  EXPECT_LT(hf->height(20, 20), original.height(20, 20) - 0.03f);
}
