// Tetrahedral granule geometry (particles/granule.cpp) against closed forms.
#include "particles/granule.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace sandpatch {

// Edge = 2 r s for every pair of spheres; centroid at the origin; |offset| = d = a sqrt(3/8).
TEST(Granule, RegularTetrahedron) {
  for (float s : {1.0f, 0.8f}) {
    GranuleShape g = make_granule_shape(0.005f, s, 2500.0f);
    Vec3 c{};
    for (int i = 0; i < 4; ++i) {
      c = c + g.offsets[i];
      EXPECT_NEAR(length(g.offsets[i]), 2 * 0.005 * s * std::sqrt(3.0 / 8.0), 1e-7);
      for (int j = i + 1; j < 4; ++j) EXPECT_NEAR(length(g.offsets[i] - g.offsets[j]), 2 * 0.005 * s, 1e-7);
    }
    EXPECT_NEAR(length(c), 0.0, 1e-8);
  }
}

// Mass 4 m_s; inertia from the parallel-axis sum about random axes equals the isotropic I
// (to 1e-5 relative) and, for s = 1, I = 1.4 m r^2.
TEST(Granule, IsotropicInertia) {
  const double r = 0.005, rho = 2500;
  GranuleShape g = make_granule_shape(float(r), 1.0f, float(rho));
  double ms = rho * 4.0 / 3.0 * std::numbers::pi * r * r * r;
  EXPECT_NEAR(g.mass, 4 * ms, 4 * ms * 1e-6);
  EXPECT_NEAR(g.inertia, 1.4 * g.mass * r * r, 1.4 * g.mass * r * r * 1e-5);
  for (Vec3 u : {Vec3{1, 0, 0}, Vec3{0, 1, 0}, Vec3{0.6f, 0.8f, 0}, Vec3{0.48f, 0.6f, 0.64f}}) {
    double I = 0;
    for (int i = 0; i < 4; ++i) {
      Vec3 p = g.offsets[i];
      double along = dot(p, u);
      I += 0.4 * ms * r * r + ms * (double(dot(p, p)) - along * along);
    }
    EXPECT_NEAR(I, g.inertia, g.inertia * 1e-5);
  }
}

// Point effective mass: no arm -> the body mass.
TEST(Granule, PointEffectiveMass) {
  EXPECT_DOUBLE_EQ(point_effective_mass(2.0, 1.0, 0.0), 2.0);
  EXPECT_NEAR(point_effective_mass(1.0, 1.0, 1.0), 0.5, 1e-12);
}

}  // namespace sandpatch
