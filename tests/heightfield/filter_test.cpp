// Tests heightfield/filter.cpp: the 3x3 Gaussian and the border band (Leach & Marais §5.2).
#include "heightfield/filter.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace sandpatch {
namespace {

Heightfield make(int nx, int nz, float spacing, int tile_cells) {
  HeightfieldDef d;
  d.samples_x = nx;
  d.samples_z = nz;
  d.spacing = spacing;
  d.tile_cells = tile_cells;
  return *Heightfield::create(d);
}

std::vector<float> all(const Heightfield& hf) {
  std::vector<float> v(std::size_t(hf.samples_x()) * hf.samples_z());
  hf.read(hf.whole(), v.data());
  return v;
}

bool inside(GridRegion r, int i, int j) { return i >= r.i0 && i < r.i0 + r.ni && j >= r.j0 && j < r.j0 + r.nj; }

TEST(HeightfieldFilter, KeepsConstant) {
  // Weights sum to 16/16: a constant is reproduced up to round-off (1e-5 relative).
  Heightfield hf = make(20, 17, 1, 4);
  hf.fill(hf.whole(), 3.25f);
  gaussian3x3(hf, hf.whole());
  gaussian3x3(hf, {4, 5, 7, 6});
  for (float v : all(hf)) ASSERT_NEAR(v, 3.25f, 1e-5f * 3.25f);
}

TEST(HeightfieldFilter, KeepsPlaneIncludingGridEdges) {
  // The kernel is symmetric with unit sum, so it maps a linear function to itself; at the
  // grid edge the linearly extrapolated neighbour keeps that true. Tolerance 1e-5 relative.
  Heightfield hf = make(25, 21, 0.5f, 8);
  auto plane = [](float x, float z) { return -1.0f + 0.6f * x + 0.35f * z; };
  for (int j = 0; j < 21; ++j)
    for (int i = 0; i < 25; ++i) hf.set_height(i, j, plane(i * 0.5f, j * 0.5f));
  gaussian3x3(hf, hf.whole());
  gaussian3x3(hf, {0, 0, 5, 3});     // corner region
  gaussian3x3(hf, {22, 10, 3, 11});  // region on the far x edge
  for (int j = 0; j < 21; ++j)
    for (int i = 0; i < 25; ++i) {
      const float want = plane(i * 0.5f, j * 0.5f);
      ASSERT_NEAR(hf.height(i, j), want, 1e-5f * std::max(1.0f, std::fabs(want))) << i << "," << j;
    }
}

TEST(HeightfieldFilter, SmoothsSymmetricStepAndKeepsItsMean) {
  // Step 0 -> 1 between i = 15 and 16; region i in [8, 24) is symmetric about it. Along x
  // the [1 2 1]/4 pass turns 0, 0, 1, 1 into 0, 1/4, 3/4, 1: the largest jump between
  // neighbours drops from 1 to 1/2, and the region mean (0.5) is unchanged because the
  // mass moved across the step stays inside the region (tolerance 1e-6).
  Heightfield hf = make(32, 12, 1, 8);
  for (int j = 0; j < 12; ++j)
    for (int i = 16; i < 32; ++i) hf.set_height(i, j, 1.0f);
  const GridRegion r{8, 0, 16, 12};
  auto region_mean = [&] {
    double s = 0;
    for (int j = r.j0; j < r.j0 + r.nj; ++j)
      for (int i = r.i0; i < r.i0 + r.ni; ++i) s += hf.height(i, j);
    return s / (r.ni * r.nj);
  };
  auto max_jump = [&] {
    float m = 0;
    for (int j = 0; j < 12; ++j)
      for (int i = 0; i + 1 < 32; ++i) m = std::max(m, std::fabs(hf.height(i + 1, j) - hf.height(i, j)));
    return m;
  };
  const std::vector<float> before = all(hf);
  EXPECT_NEAR(region_mean(), 0.5, 1e-6);
  EXPECT_FLOAT_EQ(max_jump(), 1.0f);
  gaussian3x3(hf, r);
  EXPECT_NEAR(region_mean(), 0.5, 1e-6);
  EXPECT_FLOAT_EQ(max_jump(), 0.5f);
  EXPECT_FLOAT_EQ(hf.height(15, 6), 0.25f);
  EXPECT_FLOAT_EQ(hf.height(16, 6), 0.75f);
  // Only r changed.
  const std::vector<float> after = all(hf);
  for (int j = 0; j < 12; ++j)
    for (int i = 0; i < 32; ++i)
      if (!inside(r, i, j)) {
        ASSERT_EQ(after[j * 32 + i], before[j * 32 + i]);
      }
}

TEST(HeightfieldFilter, BorderBandChangesOnlyTheBand) {
  // A raised patch r = [10, 22) x [8, 18) written into a flat field; the band is r's
  // outermost `width` rows/columns plus `width` rows/columns outside it.
  for (int width : {1, 2}) {
    Heightfield hf = make(34, 28, 1, 8);
    const GridRegion r{10, 8, 12, 10};
    std::mt19937 rng(1);
    std::uniform_real_distribution<float> U(1.5f, 2.5f);
    for (int j = r.j0; j < r.j0 + r.nj; ++j)
      for (int i = r.i0; i < r.i0 + r.ni; ++i) hf.set_height(i, j, U(rng));
    const std::vector<float> before = all(hf);
    smooth_border_band(hf, r, width);
    const std::vector<float> after = all(hf);
    const GridRegion outer{r.i0 - width, r.j0 - width, r.ni + 2 * width, r.nj + 2 * width};
    const GridRegion hole{r.i0 + width, r.j0 + width, r.ni - 2 * width, r.nj - 2 * width};
    int changed = 0;
    for (int j = 0; j < 28; ++j)
      for (int i = 0; i < 34; ++i) {
        const bool band = inside(outer, i, j) && !inside(hole, i, j);
        const std::size_t k = std::size_t(j) * 34 + i;
        if (!band) {
          ASSERT_EQ(after[k], before[k]) << "width " << width << " at " << i << "," << j;
        } else {
          changed += after[k] != before[k];
        }
      }
    // Every band sample next to the step moved (the outer ring of the band is all zeros
    // beside a raised neighbour, so all of it changes for width 1).
    if (width == 1) {
      EXPECT_EQ(changed, outer.ni * outer.nj - hole.ni * hole.nj);
    }
    // The step across r's boundary shrank: compare the jump at (r.i0 - 1 -> r.i0).
    for (int j = r.j0 + 1; j < r.j0 + r.nj - 1; ++j) {
      const std::size_t a = std::size_t(j) * 34 + r.i0 - 1, b = a + 1;
      EXPECT_LT(std::fabs(after[b] - after[a]), std::fabs(before[b] - before[a]));
    }
  }
}

TEST(HeightfieldFilter, BorderBandIsOrderIndependent) {
  // All strips are filtered from the original values: a mirror-symmetric input gives a
  // mirror-symmetric output exactly.
  Heightfield hf = make(21, 21, 1, 4);
  for (int j = 0; j < 21; ++j)
    for (int i = 0; i < 21; ++i) hf.set_height(i, j, float((i - 10) * (i - 10) + 3 * (j - 10) * (j - 10)));
  smooth_border_band(hf, {5, 5, 11, 11}, 1);
  for (int j = 0; j < 21; ++j)
    for (int i = 0; i < 21; ++i) {
      ASSERT_EQ(hf.height(i, j), hf.height(20 - i, j)) << i << "," << j;
      ASSERT_EQ(hf.height(i, j), hf.height(i, 20 - j)) << i << "," << j;
    }
}

TEST(HeightfieldFilter, BorderBandAtGridEdgeIsClipped) {
  Heightfield hf = make(12, 12, 1, 256);
  hf.fill({0, 0, 5, 5}, 1.0f);
  smooth_border_band(hf, {0, 0, 5, 5}, 1);
  EXPECT_EQ(hf.height(2, 2), 1.0f);   // inside the hole
  EXPECT_EQ(hf.height(7, 7), 0.0f);   // outside the band
  EXPECT_LT(hf.height(4, 2), 1.0f);   // inner band
  EXPECT_GT(hf.height(5, 2), 0.0f);   // outer band
}

TEST(HeightfieldFilter, OtherLayers) {
  Heightfield hf = make(10, 10, 1, 4);
  hf.set_layer(Layer::Material2, 5, 5, 1.0f);
  gaussian3x3(hf, hf.whole(), Layer::Material2);
  EXPECT_FLOAT_EQ(hf.layer(Layer::Material2, 5, 5), 4.0f / 16);
  EXPECT_FLOAT_EQ(hf.layer(Layer::Material2, 4, 4), 1.0f / 16);
  EXPECT_FLOAT_EQ(hf.layer(Layer::Material2, 5, 4), 2.0f / 16);
  EXPECT_EQ(hf.height(5, 5), 0.0f);  // elevation untouched
}

}  // namespace
}  // namespace sandpatch
