// tests manager/granule_tile.cpp: a pre-settled tile fills a patch that is already at rest
// and whose surface renders back where it was cut.
#include <gtest/gtest.h>

#include <cmath>

#include "manager/granule_tile.hpp"

using namespace sandpatch;

namespace {

const GranuleTile& tile() {
  static GranuleTile t = [] {
    GranuleTileDef d;
    d.radius = 0.025f;
    d.material.normal_stiffness = 2.0e4f;
    d.material.density = 2650.0f;
    d.columns = 8;
    d.layers = 8;
    d.surface_probe = 2.0f * d.radius;  // as the terrain manager makes its tiles
    d.settle_friction = 0.2f;
    auto r = make_granule_tile(d);
    EXPECT_TRUE(r.ok()) << (r.ok() ? "" : r.message());
    return r.ok() ? *r : GranuleTile{};
  }();
  return t;
}

}  // namespace

// The tile settled (every granule slower than 2 cm/s), holds granules, and its packing
// fraction is that of a loose random packing of tetrahedral granules (0.35..0.65).
TEST(GranuleTile, SettlesAndMeasuresPackingFraction) {
  const GranuleTile& t = tile();
  EXPECT_LT(t.settled_speed, 0.02f);
  EXPECT_GT(t.granules.size(), 20u);
  EXPECT_GT(t.packing_fraction, 0.35f);
  EXPECT_LT(t.packing_fraction, 0.65f);
  EXPECT_GT(t.period_xz, 0.0f);
  EXPECT_GT(t.period_y, 0.0f);
}

// Flat fills cut at heights across the upper part of the tile render back at their heights
// within 0.2 d (d = 2 r, the sphere diameter), on the surface the demotion renders (probe of
// 2 r). The calibration centres the error over the tile's depth; single heights scatter by
// the tile's layering: measured -0.17 ... +0.06 d above 2 d from the floor for a tile settled
// at μ = 0.2 (as the manager settles them; +0.3 d at 1.2 d from the floor). No two spheres of
// different granules overlap by more than 10% of r (checked on the last fill).
TEST(GranuleTile, FlatFillRendersBackAtItsHeight) {
  const GranuleTile& t = tile();
  const float W = 3.0f * t.period_xz;  // patches are whole tile periods wide (terrain_manager.cpp region_for)
  for (float f : {0.4f, 0.55f, 0.7f}) {  // patches are cut 0.7 P_y above their floor (patch_depth)
    const float H = f * t.period_y;
    auto g = fill_from_tile(t, W, W, [&](float, float) { return H; });
    const float m = mean_top_height(g, t.shape, 0.1f * W, 0.1f * W, 0.9f * W, 0.9f * W, 0.25f * t.shape.radius, 0.0f, t.surface_probe);
    EXPECT_NEAR(m, H, 0.2f * 2.0f * t.shape.radius) << "H = " << H;
  }
  const float H = 0.8f * t.period_y;
  auto g = fill_from_tile(t, W, W, [&](float, float) { return H; });
  const float m = mean_top_height(g, t.shape, 0.1f * W, 0.1f * W, 0.9f * W, 0.9f * W, 0.25f * t.shape.radius, 0.0f, t.surface_probe);
  EXPECT_NEAR(m, H, 0.2f * 2.0f * t.shape.radius);
  std::vector<Vec3> s;
  for (const auto& p : g)
    for (const auto& o : t.shape.offsets) s.push_back(p.position + rotate(p.orientation, o));
  int overlaps = 0;
  for (std::size_t i = 0; i < s.size(); ++i)
    for (std::size_t j = i + 1; j < s.size(); ++j)
      if (i / 4 != j / 4 && length(s[i] - s[j]) < 1.8f * t.shape.radius - 1e-6f) ++overlaps;
  EXPECT_EQ(overlaps, 0);
}

// A sloped cut (rising 0.5 P_y across the patch) follows the slope: the mean height over
// each half matches the slope's mean there within 0.2 d (measured 0.14 d: a sloped cut meets
// the packing at every phase across the patch, the flat calibration does not see that).
TEST(GranuleTile, SlopedFillFollowsTheSurface) {
  const GranuleTile& t = tile();
  const float W = 2.0f * t.period_xz, H = 0.5f * t.period_y, slope = 0.5f * t.period_y / W;
  auto surf = [&](float x, float) { return H + slope * (x - 0.5f * W); };
  auto g = fill_from_tile(t, W, W, surf);
  const float step = 0.25f * t.shape.radius, d = 2.0f * t.shape.radius;
  const float left = mean_top_height(g, t.shape, 0.1f * W, 0.1f * W, 0.45f * W, 0.9f * W, step, 0.0f, t.surface_probe);
  const float right = mean_top_height(g, t.shape, 0.55f * W, 0.1f * W, 0.9f * W, 0.9f * W, step, 0.0f, t.surface_probe);
  EXPECT_NEAR(left, surf(0.275f * W, 0), 0.2f * d);
  EXPECT_NEAR(right, surf(0.725f * W, 0), 0.2f * d);
}

// A fill cut in steps (FillCut, what a promotion spreads over frames) gives the granules the
// whole cut gives, in its order, whatever the step size; each step does at most its units
// (and the sort of the candidates, whole, once); the cut takes many small steps.
TEST(GranuleTile, FillCutInStepsEqualsTheWholeCut) {
  const GranuleTile& t = tile();
  const float W = 3.0f * t.period_xz, D = 2.0f * t.period_xz, H = 0.6f * t.period_y;
  auto surf = [&](float x, float z) { return H + 0.1f * t.period_y * std::sin(x / W * 6.0f) * std::cos(z / D * 4.0f); };
  const std::vector<PlacedGranule> whole = fill_from_tile(t, W, D, surf);
  ASSERT_GT(whole.size(), 100u);
  for (std::size_t units : {std::size_t(1), std::size_t(97), std::size_t(4096)}) {
    FillCut cut(t, W, D, surf);
    int steps = 0;
    while (!cut.step(units)) {
      ++steps;
      ASSERT_LT(steps, 10000000) << "the cut never finishes with " << units << " units a step";
    }
    EXPECT_TRUE(cut.done());
    const std::vector<PlacedGranule> got = cut.take();
    ASSERT_EQ(got.size(), whole.size()) << units << " units a step";
    for (std::size_t k = 0; k < got.size(); ++k) {
      EXPECT_EQ(got[k].position.x, whole[k].position.x);
      EXPECT_EQ(got[k].position.y, whole[k].position.y);
      EXPECT_EQ(got[k].position.z, whole[k].position.z);
      EXPECT_EQ(got[k].orientation.w, whole[k].orientation.w);
    }
    // A copy's candidates are made together (tile.granules() units), the sort is one step.
    const std::size_t per_copy = t.granules.size();
    if (units >= per_copy) EXPECT_GE(steps, int(whole.size() / units)) << "the cut was spread over steps";
    if (units == 97) EXPECT_GT(steps, 10);
  }
}

// A successor's cut leaves out the tile copies inside its predecessor but a period deep from the
// side it reaches past (skip_copies_within): the granules beyond that side are those of the
// whole cut, in its order, and the cut takes fewer steps.
TEST(GranuleTile, FillCutWithoutTheCopiesItSkipsKeepsTheRestAlike) {
  const GranuleTile& t = tile();
  const float P = t.period_xz, W = 4.0f * P, D = 2.0f * P, H = 0.6f * t.period_y;
  auto surf = [&](float x, float z) { return H + 0.1f * t.period_y * std::sin(x / W * 6.0f) * std::cos(z / D * 4.0f); };
  auto beyond = [&](const std::vector<PlacedGranule>& g) {  // (past the predecessor, x > 3 P)
    std::vector<PlacedGranule> out;
    for (const PlacedGranule& p : g)
      if (p.position.x > 3.0f * P) out.push_back(p);
    return out;
  };
  auto run = [&](bool skip, int* steps) {
    FillCut cut(t, W, D, surf);
    if (skip) cut.skip_copies_within(-1e-4f * P, 2.0f * P + 1e-4f * P, -1e-4f * P, D + 1e-4f * P);
    *steps = 0;
    while (!cut.step(4096)) ++*steps;
    return cut.take();
  };
  int steps_whole = 0, steps_skip = 0;
  const std::vector<PlacedGranule> whole = run(false, &steps_whole), skipped = run(true, &steps_skip);
  const std::vector<PlacedGranule> a = beyond(whole), b = beyond(skipped);
  ASSERT_GT(a.size(), 20u);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].position.x, b[k].position.x);
    EXPECT_EQ(a[k].position.y, b[k].position.y);
    EXPECT_EQ(a[k].position.z, b[k].position.z);
    EXPECT_EQ(a[k].orientation.w, b[k].orientation.w);
  }
  // (no granule of a skipped copy: none centred within its columns but round the edges)
  for (const PlacedGranule& p : skipped) EXPECT_GT(p.position.x, 2.0f * P - t.shape.centre_distance - t.shape.radius);
  EXPECT_LT(skipped.size(), whole.size());
  EXPECT_LT(steps_skip, steps_whole);
}

// Fine, stiff granules (r = 1.4 cm at k_n = 1.5e5 N/m: t_c / 20 = 7e-5 s) need 120 substeps
// in each 1/120 s settling frame, more than a game frame's 64: the tile still settles (it
// was refused with "max_substeps = 64", which no caller of the manager could raise).
TEST(GranuleTile, FineStiffGranulesSettle) {
  GranuleTileDef d;
  d.radius = 0.014f;
  d.material.normal_stiffness = 1.5e5f;
  d.material.density = 2650.0f;
  d.columns = 4;
  d.layers = 4;
  d.settle_max_time = 0.3f;
  auto r = make_granule_tile(d);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_GT(r->granules.size(), 10u);
}
