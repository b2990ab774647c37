// tests manager/planning.hpp: where a patch goes on the heightfield (its region, rounded to
// whole tile periods and kept on the terrain), how deep (its floor over soil and bedrock),
// and the soil volume of its ledger.
#include <gtest/gtest.h>

#include <limits>
#include <vector>

#include "heightfield/heightfield.hpp"
#include "manager/planning.hpp"
#include "tests/manager/rig.hpp"

using namespace sandpatch;

namespace {

PatchRequest rect(double x0, double z0, double x1, double z1) {
  PatchRequest r;
  r.x0 = x0, r.z0 = z0, r.x1 = x1, r.z1 = z1;
  return r;
}

}  // namespace

// The samples bracketing the request, rounded out to whole tile periods around it.
TEST(Planning, RegionIsWholeTilePeriodsAroundTheRequest) {
  const Heightfield hf = test::terrain_8m("flat");  // 81 × 81 samples, 0.1 m
  auto reg = patch_region(hf, rect(3.05, 2.05, 3.35, 2.95), 7);
  ASSERT_TRUE(reg.ok()) << reg.message();
  // Samples 30..34 (4 cells) on x round out to 7 cells, centred: 29..36; 20..30 (10 cells)
  // on z round out to 14: 18..32.
  EXPECT_EQ(reg->i0, 29);
  EXPECT_EQ(reg->ni, 8);
  EXPECT_EQ(reg->j0, 18);
  EXPECT_EQ(reg->nj, 15);
}

// A rectangle whose sides lie on samples (a patch asked for ahead of another abuts it on a
// sample line) and spans exactly one tile period takes one period, not two: its high side's
// sample is the last of the region, not one beyond it (a car's second wheel track got 4 m of
// sand for 2 m that way, docs/BENCHMARKS.md "Patches side by side").
TEST(Planning, ARectangleOfOnePeriodOnSamplesTakesOnePeriod) {
  const Heightfield hf = test::terrain_8m("flat");  // 81 × 81 samples, 0.1 m
  auto reg = patch_region(hf, rect(3.0, 2.0, 3.7, 2.7), 7);
  ASSERT_TRUE(reg.ok()) << reg.message();
  EXPECT_EQ(reg->i0, 30);
  EXPECT_EQ(reg->ni, 8) << "samples 30..37: 7 cells, one period";
  EXPECT_EQ(reg->j0, 20);
  EXPECT_EQ(reg->nj, 8);
  // a hair past the sample still rounds out to the next period
  auto more = patch_region(hf, rect(3.0, 2.0, 3.71, 2.7), 7);
  ASSERT_TRUE(more.ok()) << more.message();
  EXPECT_EQ(more->ni, 15);
}

// At the terrain's edge the rounded region shifts onto the terrain; where the terrain is
// narrower than the rounded region, the cut sides stay; off the terrain there is no region.
TEST(Planning, RegionStaysOnTheTerrain) {
  const Heightfield hf = test::terrain_8m("flat");
  auto edge = patch_region(hf, rect(0.05, 7.65, 0.35, 7.95), 7);
  ASSERT_TRUE(edge.ok()) << edge.message();
  EXPECT_EQ(edge->i0, 0);
  EXPECT_EQ(edge->ni, 8);
  EXPECT_EQ(edge->j0 + edge->nj, 81);
  EXPECT_EQ(edge->nj, 8);

  const Heightfield small = test::flat_terrain(9, 0.1f, 1.0f);
  auto cut = patch_region(small, rect(0.0, 0.0, 0.8, 0.8), 7);
  ASSERT_TRUE(cut.ok()) << cut.message();
  EXPECT_EQ(cut->i0, 0);
  EXPECT_EQ(cut->ni, 9);

  EXPECT_FALSE(patch_region(hf, rect(9.0, 9.0, 10.0, 10.0), 7).ok());
}

TEST(Planning, RequestsAreClippedToTheTerrain) {
  const Heightfield hf = test::terrain_8m("flat");
  const PatchRequest t = terrain_rect(hf);
  EXPECT_DOUBLE_EQ(t.x0, 0.0);
  EXPECT_NEAR(t.x1, 8.0, 1e-6);
  PatchRequest r = rect(-1.0, 7.0, 1.0, 9.0);
  clip_to_terrain(hf, r);
  EXPECT_DOUBLE_EQ(r.x0, 0.0);
  EXPECT_DOUBLE_EQ(r.x1, 1.0);
  EXPECT_DOUBLE_EQ(r.z0, 7.0);
  EXPECT_DOUBLE_EQ(r.z1, t.z1);
}

// The floor: patch_depth below the lowest sample, never below the bedrock (the higher of
// surface - soil_depth and min(surface, bedrock_height)); at or above the top: no soil.
TEST(Planning, FloorStopsAtTheBedrock) {
  const Heightfield hf = test::terrain_8m("flat");  // y = 1 m
  const GridRegion region{10, 10, 8, 8};
  const double inf = std::numeric_limits<double>::infinity();
  float lo = 0, hi = 0;
  EXPECT_NEAR(patch_floor(hf, region, 0.25, 2.0, -inf, &lo, &hi), 0.75, 1e-6);
  EXPECT_FLOAT_EQ(lo, 1.0f);
  EXPECT_FLOAT_EQ(hi, 1.0f);
  EXPECT_NEAR(patch_floor(hf, region, 0.25, 0.1, -inf, &lo, &hi), 0.9, 1e-6);   // thin soil
  EXPECT_NEAR(patch_floor(hf, region, 0.25, 2.0, 0.95, &lo, &hi), 0.95, 1e-6);  // flat bedrock
  EXPECT_GE(patch_floor(hf, region, 0.25, 2.0, 1.2, &lo, &hi), hi);             // bare rock: no soil
}

// The ledger's volume before promotion: between the floor and the surface over the region.
TEST(Planning, SoilVolumeOfTheLedger) {
  Heightfield hf = test::terrain_8m("flat");
  const GridRegion region{10, 10, 8, 6};  // 0.7 m × 0.5 m
  const double v = soil_volume(hf, region, 0.75);
  EXPECT_NEAR(v, 0.25 * 0.7 * 0.5, 1e-6);
}
