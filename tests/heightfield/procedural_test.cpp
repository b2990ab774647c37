// Tests heightfield/procedural.cpp: analytic kinds against their formulas, noise bounds
// and determinism.
#include "heightfield/procedural.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace sandpatch {
namespace {

HeightfieldDef grid(int n = 65, float spacing = 0.5f) {
  HeightfieldDef d;
  d.samples_x = n;
  d.samples_z = n + 6;
  d.spacing = spacing;
  d.tile_cells = 16;
  return d;
}

TEST(HeightfieldProcedural, FlatAndPlaneMatchFormula) {
  ProceduralHeightsDef p;
  p.height = 1.25f;
  auto flat = make_procedural(grid(), p);
  ASSERT_TRUE(flat.ok()) << flat.message();
  EXPECT_EQ(flat->min_height(), 1.25f);
  EXPECT_EQ(flat->max_height(), 1.25f);
  p.kind = "plane";
  p.slope_x = 0.1f;
  p.slope_z = -0.3f;
  auto plane = make_procedural(grid(), p);
  ASSERT_TRUE(plane.ok());
  for (int j = 0; j < plane->samples_z(); j += 7)
    for (int i = 0; i < plane->samples_x(); i += 5) {
      const double want = 1.25 + 0.1f * (i * 0.5) - 0.3f * (j * 0.5);  // formula in double, rounded once
      ASSERT_NEAR(plane->height(i, j), want, 1e-6 * std::max(1.0, std::fabs(want)));
    }
}

TEST(HeightfieldProcedural, HillsPeakAndValley) {
  ProceduralHeightsDef p;
  p.kind = "hills";
  p.height = 2;
  p.amplitude = 3;
  p.wavelength = 8;  // 16 samples at 0.5 m
  auto hf = make_procedural(grid(), p);
  ASSERT_TRUE(hf.ok());
  EXPECT_FLOAT_EQ(hf->height(0, 0), 5.0f);    // c(0) c(0) = 1
  EXPECT_FLOAT_EQ(hf->height(8, 0), -1.0f);   // c(wavelength/2) = -1
  EXPECT_FLOAT_EQ(hf->height(8, 8), 5.0f);    // (-1)(-1)
  EXPECT_FLOAT_EQ(hf->height(4, 0), 2.0f);    // quarter period: c = 0
  EXPECT_GE(hf->min_height(), -1.0f);
  EXPECT_LE(hf->max_height(), 5.0f);
}

TEST(HeightfieldProcedural, NoiseIsBoundedAndDeterministic) {
  ProceduralHeightsDef p;
  p.kind = "noise";
  p.height = 10;
  p.amplitude = 4;
  p.wavelength = 12;
  p.seed = 42;
  p.octaves = 5;
  auto a = make_procedural(grid(), p), b = make_procedural(grid(), p);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->hash(), b->hash());  // same seed, same bytes
  // Normalised fBm: |h - height| <= amplitude.
  EXPECT_GE(a->min_height(), 10.0f - 4.0f);
  EXPECT_LE(a->max_height(), 10.0f + 4.0f);
  EXPECT_GT(a->max_height() - a->min_height(), 1.0f);  // not flat
  p.seed = 43;
  auto c = make_procedural(grid(), p);
  EXPECT_NE(a->hash(), c->hash());
  // The bytes are pinned: uses only +, -, *, /, floor and integer hashing, so every
  // IEEE-754 machine must produce this hash. Change it only with the algorithm or with the
  // set of layers Heightfield::hash() covers (Elevation and Material0..3).
  EXPECT_EQ(a->hash(), 0xc28cac946031db2bull) << std::hex << a->hash();
}

TEST(HeightfieldProcedural, ErrorsNameTheField) {
  ProceduralHeightsDef p;
  p.kind = "mountains";
  p.wavelength = 0;
  p.octaves = 0;
  auto r = make_procedural(grid(), p);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors().size(), 3u) << r.message();
  EXPECT_NE(r.message().find("kind = \"mountains\""), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("wavelength = 0"), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("octaves = 0"), std::string::npos) << r.message();
  HeightfieldDef g = grid();
  g.samples_z = 1;
  r = make_procedural(g, ProceduralHeightsDef{});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "samples_z");
}

}  // namespace
}  // namespace sandpatch
