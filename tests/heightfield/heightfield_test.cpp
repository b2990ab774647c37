// Tests heightfield/heightfield.cpp: creation errors, tiles and shared edges, region
// views, lazy layers, and the bilinear surface against analytic surfaces.
#include "heightfield/heightfield.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

namespace sandpatch {
namespace {

Heightfield make(int nx, int nz, float spacing, int tile_cells, float h0 = 0) {
  HeightfieldDef d;
  d.samples_x = nx;
  d.samples_z = nz;
  d.spacing = spacing;
  d.tile_cells = tile_cells;
  d.initial_height = h0;
  auto r = Heightfield::create(d);
  EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
  return std::move(r).value();
}

// Writes f(x, z) at every sample (local metres).
template <class F>
void fill_with(Heightfield& hf, F f) {
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i) hf.set_height(i, j, f(i * hf.spacing(), j * hf.spacing()));
}

// ---- creation ----

TEST(HeightfieldCreate, RejectsOneSampleNamingField) {
  HeightfieldDef d;
  d.samples_x = 1;
  d.samples_z = 4;
  auto r = Heightfield::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "samples_x");
  EXPECT_NE(r.message().find("samples_x = 1"), std::string::npos) << r.message();
}

TEST(HeightfieldCreate, RejectsZeroSpacingNamingField) {
  HeightfieldDef d;
  d.samples_x = 4;
  d.samples_z = 4;
  d.spacing = 0;
  auto r = Heightfield::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "spacing");
  EXPECT_NE(r.message().find("> 0"), std::string::npos) << r.message();
}

TEST(HeightfieldCreate, RejectsNaNSpacingNamingField) {
  HeightfieldDef d;
  d.samples_x = 4;
  d.samples_z = 4;
  d.spacing = std::nanf("");
  auto r = Heightfield::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "spacing");
  EXPECT_NE(r.message().find("nan"), std::string::npos) << r.message();
}

TEST(HeightfieldCreate, ReportsEveryBadFieldAtOnce) {
  HeightfieldDef d;  // samples 0 x 0
  d.tile_cells = 0;
  d.initial_height = INFINITY;
  auto r = Heightfield::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors().size(), 4u) << r.message();  // samples_x, samples_z, tile_cells, initial_height
}

// ---- tiles ----

TEST(HeightfieldTiles, CountsAndSizes) {
  // 10 samples = 9 cells along x in tiles of 4 cells: 4 + 4 + 1 cells -> 5, 5, 2 samples.
  Heightfield hf = make(10, 5, 1, 4);
  EXPECT_EQ(hf.tiles_x(), 3);
  EXPECT_EQ(hf.tiles_z(), 1);
  EXPECT_EQ(hf.tile_samples_x(0), 5);
  EXPECT_EQ(hf.tile_samples_x(2), 2);
  EXPECT_EQ(hf.tile_samples_z(0), 5);
  EXPECT_FLOAT_EQ(hf.extent_x(), 9.0f);
  EXPECT_FLOAT_EQ(hf.extent_z(), 4.0f);
}

TEST(HeightfieldTiles, SetHeightOnSharedCornerSeenFromAllFourTiles) {
  Heightfield hf = make(17, 17, 1, 8);
  hf.set_height(8, 8, 3.5f);
  // Sample (8, 8) is the corner shared by tiles (0,0), (1,0), (0,1), (1,1).
  const int n = hf.tile_samples_x(0);  // 9
  EXPECT_EQ(hf.tile_data(0, 0)[8 * n + 8], 3.5f);
  EXPECT_EQ(hf.tile_data(1, 0)[8 * hf.tile_samples_x(1) + 0], 3.5f);
  EXPECT_EQ(hf.tile_data(0, 1)[0 * n + 8], 3.5f);
  EXPECT_EQ(hf.tile_data(1, 1)[0], 3.5f);
  EXPECT_EQ(hf.height(8, 8), 3.5f);
  // The surface next to the corner, evaluated in cells of tiles (0,0) and (1,1), sees it:
  // bilinear weight of the corner is (1 - 0.1)^2 = 0.81 (1e-5 m round-off).
  EXPECT_NEAR(hf.sample(7.9f, 7.9f), 0.81f * 3.5f, 1e-5f);
  EXPECT_NEAR(hf.sample(8.1f, 8.1f), 0.81f * 3.5f, 1e-5f);
  EXPECT_NEAR(hf.sample(8.1f, 7.9f), 0.81f * 3.5f, 1e-5f);
}

TEST(HeightfieldTiles, RegionWriteAcrossTilesKeepsEdgesConsistent) {
  Heightfield hf = make(23, 19, 0.5f, 4);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(-3, 3);
  const GridRegion r{3, 2, 15, 13};  // straddles several tile edges in both directions
  std::vector<float> in(std::size_t(r.ni) * r.nj);
  for (float& v : in) v = U(rng);
  hf.write(r, in.data());
  std::vector<float> out(in.size());
  hf.read(r, out.data());
  EXPECT_EQ(in, out);
  // Every stored copy of every sample equals height(i, j).
  for (int tz = 0; tz < hf.tiles_z(); ++tz)
    for (int tx = 0; tx < hf.tiles_x(); ++tx) {
      const GridRegion t = hf.tile_region(tx, tz);
      for (int j = 0; j < t.nj; ++j)
        for (int i = 0; i < t.ni; ++i)
          ASSERT_EQ(hf.tile_data(tx, tz)[j * t.ni + i], hf.height(t.i0 + i, t.j0 + j)) << tx << "," << tz;
    }
  // Outside r nothing changed.
  EXPECT_EQ(hf.height(2, 2), 0.0f);
  EXPECT_EQ(hf.height(18, 15), 0.0f);
}

TEST(HeightfieldTiles, SamplesAcrossTileBoundariesMatchSingleTile) {
  Heightfield tiled = make(37, 29, 0.25f, 8), single = make(37, 29, 0.25f, 256);
  ASSERT_EQ(single.tiles_x(), 1);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(-1, 1);
  for (int j = 0; j < 29; ++j)
    for (int i = 0; i < 37; ++i) {
      const float h = U(rng);
      tiled.set_height(i, j, h);
      single.set_height(i, j, h);
    }
  std::uniform_real_distribution<float> X(-1, 10), Z(-1, 8);
  std::vector<std::pair<float, float>> pts;
  for (int k = 0; k < 2000; ++k) pts.emplace_back(X(rng), Z(rng));
  for (int k = 0; k <= 4; ++k) pts.emplace_back(2.0f * k, 2.0f * k);  // exactly on tile edges (8 cells * 0.25 m)
  for (auto [x, z] : pts) {
    // Same samples, same formula: bit-identical.
    ASSERT_EQ(tiled.sample(x, z), single.sample(x, z)) << x << "," << z;
    ASSERT_EQ(tiled.normal(x, z), single.normal(x, z)) << x << "," << z;
  }
}

// ---- bilinear surface against analytic surfaces ----

TEST(HeightfieldSample, PlaneIsReproducedExactly) {
  // A bilinear patch of a plane is the plane: error is float round-off only, 1e-5 relative.
  Heightfield hf = make(40, 33, 0.7f, 8);
  auto plane = [](float x, float z) { return 1.5f + 0.3f * x - 0.45f * z; };
  fill_with(hf, plane);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> X(0, hf.extent_x()), Z(0, hf.extent_z());
  for (int k = 0; k < 5000; ++k) {
    const float x = X(rng), z = Z(rng);
    const float want = plane(x, z);
    ASSERT_NEAR(hf.sample(x, z), want, 1e-5f * std::max(1.0f, std::fabs(want))) << x << "," << z;
  }
}

TEST(HeightfieldSample, ParaboloidErrorWithinBilinearBound) {
  // h = a (x^2 + z^2). Bilinear interpolation is linear in the data and a x^2 does not
  // depend on z, so the interpolant of a x^2 is the linear interpolant in x, whose error
  // inside [x0, x0 + s] is a (x - x0)(x0 + s - x) <= a s^2 / 4 (at mid-cell). The two
  // terms add: 0 <= interpolant - h <= a s^2/4 + a s^2/4 = a s^2 / 2, attained at cell
  // centres. (The bound a s^2/4 holds per axis; for h = a x^2 alone it is tight.)
  const float a = 0.02f, s = 0.5f;
  Heightfield hf = make(65, 65, s, 16);
  fill_with(hf, [&](float x, float z) { return a * (x * x + z * z); });
  const float bound = a * s * s / 2;
  const float roundoff = 1e-5f * a * 2 * 32 * 32;  // 1e-5 relative to the largest height
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> X(0, hf.extent_x());
  for (int k = 0; k < 5000; ++k) {
    const float x = X(rng), z = X(rng);
    const float err = hf.sample(x, z) - a * (x * x + z * z);
    ASSERT_GE(err, -roundoff) << x << "," << z;
    ASSERT_LE(err, bound + roundoff) << x << "," << z;
  }
  // Tightness: at a cell centre the error is exactly the bound.
  const float xc = 10.25f, zc = 3.75f;
  EXPECT_NEAR(hf.sample(xc, zc) - a * (xc * xc + zc * zc), bound, roundoff);
  // One axis only: h = a x^2 has error <= a s^2 / 4, reached at mid-cell.
  fill_with(hf, [&](float x, float) { return a * x * x; });
  EXPECT_NEAR(hf.sample(xc, 1.0f) - a * xc * xc, a * s * s / 4, roundoff);
}

TEST(HeightfieldSample, PlaneNormalMatchesAnalytic) {
  Heightfield hf = make(20, 20, 1.25f, 4);
  const float sx = 0.4f, sz = -0.7f;
  fill_with(hf, [&](float x, float z) { return 2 + sx * x + sz * z; });
  const Eigen::Vector3f want = Eigen::Vector3f(-sx, 1, -sz).normalized();
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> X(-2, hf.extent_x() + 2);
  for (int k = 0; k < 2000; ++k) {
    const Eigen::Vector3f n = hf.normal(X(rng), X(rng));
    ASSERT_LT((n - want).norm(), 1e-5f);
  }
}

TEST(HeightfieldSample, ClampsOutsideTheGridAndReadsNaNAsZero) {
  Heightfield hf = make(5, 5, 1, 256);
  fill_with(hf, [](float x, float z) { return x + 10 * z; });
  EXPECT_EQ(hf.sample(-3, -3), hf.height(0, 0));
  EXPECT_EQ(hf.sample(100, 100), hf.height(4, 4));
  EXPECT_EQ(hf.sample(100, 2), hf.height(4, 2));
  EXPECT_EQ(hf.sample(std::nanf(""), std::nanf("")), hf.height(0, 0));
  EXPECT_EQ(hf.sample(4, 4), hf.height(4, 4));  // far corner exactly
}

// ---- layers ----

TEST(HeightfieldLayers, DefaultsAndLazyAllocationPerTile) {
  Heightfield hf = make(33, 33, 1, 8, 2.0f);
  const std::size_t elevation_bytes = hf.memory_bytes();
  EXPECT_EQ(elevation_bytes, std::size_t(4 * 4) * 9 * 9 * sizeof(float));
  EXPECT_FALSE(hf.layer_allocated(Layer::Material2));
  EXPECT_EQ(hf.layer(Layer::Elevation, 3, 3), 2.0f);
  EXPECT_EQ(hf.layer(Layer::Material0, 3, 3), 1.0f);
  EXPECT_EQ(hf.layer(Layer::Material3, 3, 3), 0.0f);
  const std::uint64_t before = hf.hash();
  // Writing the default value allocates one tile but changes no value: same hash.
  hf.set_layer(Layer::Material1, 3, 3, 0.0f);
  EXPECT_TRUE(hf.layer_allocated(Layer::Material1));
  EXPECT_EQ(hf.memory_bytes(), elevation_bytes + 9 * 9 * sizeof(float));
  EXPECT_EQ(hf.hash(), before);
  hf.set_layer(Layer::Material1, 3, 3, 0.25f);
  EXPECT_NE(hf.hash(), before);
  EXPECT_EQ(hf.layer(Layer::Material1, 3, 3), 0.25f);
  // Bilinear on a layer: halfway between 0.25 and the default 0.
  EXPECT_FLOAT_EQ(hf.sample_layer(Layer::Material1, 3.5f, 3.0f), 0.125f);
  EXPECT_FLOAT_EQ(hf.sample_layer(Layer::Material2, 3.5f, 3.0f), 0.0f);
  // Region read of an unallocated layer returns defaults.
  std::vector<float> out(4);
  hf.read({20, 20, 2, 2}, out.data(), Layer::Material0);
  EXPECT_EQ(out, std::vector<float>(4, 1.0f));
}

TEST(HeightfieldLayers, HugeGridIsCreatableWithElevationOnly) {
  // 8193^2 samples: 268 MB of Elevation; other layers cost nothing until written.
  HeightfieldDef d;
  d.samples_x = d.samples_z = 8193;
  auto r = Heightfield::create(d);
  ASSERT_TRUE(r.ok()) << r.message();
  Heightfield& hf = *r;
  EXPECT_EQ(hf.tiles_x(), 32);
  EXPECT_EQ(hf.memory_bytes(), std::size_t(32 * 32) * 257 * 257 * sizeof(float));
  hf.set_layer(Layer::Material2, 4000, 5000, 0.5f);  // inside one tile
  EXPECT_EQ(hf.memory_bytes(), std::size_t(32 * 32 + 1) * 257 * 257 * sizeof(float));
  hf.set_height(8192, 8192, 7.0f);
  EXPECT_EQ(hf.sample(1e9f, 1e9f), 7.0f);
  EXPECT_EQ(hf.max_height(), 7.0f);
}

// ---- min / max, hash, copies ----

TEST(HeightfieldRange, MinMaxFollowEdits) {
  Heightfield hf = make(20, 20, 1, 4, 1.0f);
  EXPECT_EQ(hf.min_height(), 1.0f);
  EXPECT_EQ(hf.max_height(), 1.0f);
  hf.set_height(5, 5, -2.0f);
  hf.set_height(19, 19, 4.0f);
  EXPECT_EQ(hf.min_height(), -2.0f);
  EXPECT_EQ(hf.max_height(), 4.0f);
  EXPECT_EQ(hf.tile_min_height(1, 1), -2.0f);  // sample (5,5) is in tile (1,1) only
  EXPECT_EQ(hf.tile_max_height(0, 0), 1.0f);
  hf.set_height(5, 5, 1.0f);  // undo: range shrinks again
  EXPECT_EQ(hf.min_height(), 1.0f);
}

TEST(HeightfieldHash, ByteExactAndCopiesAreDeep) {
  Heightfield a = make(12, 9, 1, 4);
  a.set_height(3, 4, 1.0f);
  Heightfield b = a;  // deep copy
  EXPECT_EQ(a.hash(), b.hash());
  b.set_height(3, 4, std::nextafter(1.0f, 2.0f));  // one ulp
  EXPECT_NE(a.hash(), b.hash());
  EXPECT_EQ(a.height(3, 4), 1.0f);
  HeightfieldDef d;
  d.samples_x = 12;
  d.samples_z = 9;
  d.tile_cells = 4;
  d.origin_x = 1e-9;
  Heightfield c = *Heightfield::create(d);
  c.set_height(3, 4, 1.0f);
  EXPECT_NE(a.hash(), c.hash());  // origin is hashed
}

}  // namespace
// Regions near INT_MAX: i0 + ni once wrapped negative and passed the bounds check.
TEST(HeightfieldRegions, ContainsDoesNotOverflow) {
  HeightfieldDef d;
  d.samples_x = d.samples_z = 9;
  const Heightfield hf = *Heightfield::create(d);
  const int big = std::numeric_limits<int>::max();
  EXPECT_FALSE(hf.contains({1, 0, big, 1}));
  EXPECT_FALSE(hf.contains({0, 1, 1, big}));
  EXPECT_FALSE(hf.contains({big, big, big, big}));
  EXPECT_TRUE(hf.contains({8, 8, 1, 1}));
  EXPECT_FALSE(hf.contains({8, 8, 2, 1}));
  const GridRegion r = intersect({5, 5, big, big}, hf.whole());
  EXPECT_EQ(r.ni, 4);
  EXPECT_EQ(r.nj, 4);
}

// The grid cap (common/limits.hpp): refused from the dimensions, before the tiles are allocated.
TEST(HeightfieldCreate, GridOverTheMemoryCapIsRefused) {
  HeightfieldDef d;
  d.samples_x = d.samples_z = 65536;
  auto r = Heightfield::create(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors()[0].field, "samples_x × samples_z");
  EXPECT_NE(r.errors()[0].message().find("at most 268435456 samples"), std::string::npos) << r.errors()[0].message();
}

}  // namespace sandpatch
