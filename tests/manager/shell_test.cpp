// tests manager/shell.cpp: shell spheres lie on the body surface and are evenly spaced.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "manager/shell.hpp"

using namespace sandpatch;

namespace {

// Distance from p to the surface of the shape (analytic, body frame).
float surface_distance(const RigidShape& s, const Eigen::Vector3f& p) {
  switch (s.kind) {
    case RigidShapeKind::Sphere: return std::abs(p.norm() - s.radius);
    case RigidShapeKind::Box: {
      const Eigen::Vector3f q = p.cwiseAbs() - s.half_extents;
      const float outside = q.cwiseMax(0.0f).norm(), inside = std::min(q.maxCoeff(), 0.0f);
      return std::abs(outside + inside);
    }
    case RigidShapeKind::Cylinder: {
      const float dr = std::hypot(p.x(), p.z()) - s.radius, dy = std::abs(p.y()) - 0.5f * s.height;
      const float outside = std::hypot(std::max(dr, 0.0f), std::max(dy, 0.0f));
      return std::abs(outside + std::min(std::max(dr, dy), 0.0f));
    }
    case RigidShapeKind::Capsule: {
      const float y = std::clamp(p.y(), -0.5f * s.height, 0.5f * s.height);
      return std::abs((p - Eigen::Vector3f(0, y, 0)).norm() - s.radius);
    }
    default: return 0;
  }
}

// Largest and smallest nearest-neighbour distance over the points.
std::pair<float, float> nn_range(const std::vector<Eigen::Vector3f>& pts) {
  float lo = std::numeric_limits<float>::max(), hi = 0;
  for (std::size_t i = 0; i < pts.size(); ++i) {
    float best = std::numeric_limits<float>::max();
    for (std::size_t j = 0; j < pts.size(); ++j)
      if (i != j) best = std::min(best, (pts[i] - pts[j]).norm());
    lo = std::min(lo, best);
    hi = std::max(hi, best);
  }
  return {lo, hi};
}

}  // namespace

// Every primitive: points within 1e-5 m of the surface, nearest neighbours between
// 0.3 and 1.2 spacings apart (no clumps, no holes a granule sphere of radius spacing/2 could
// pass), and the count within a factor 2 of area / spacing².
TEST(Shell, PrimitivesOnSurfaceAndEvenlySpaced) {
  const float sp = 0.05f;
  RigidShape shapes[4];
  shapes[0].kind = RigidShapeKind::Sphere;
  shapes[0].radius = 0.3f;
  shapes[1].kind = RigidShapeKind::Box;
  shapes[1].half_extents = {0.2f, 0.1f, 0.3f};
  shapes[2].kind = RigidShapeKind::Cylinder;
  shapes[2].radius = 0.3f;
  shapes[2].height = 0.9f;
  shapes[3].kind = RigidShapeKind::Capsule;
  shapes[3].radius = 0.2f;
  shapes[3].height = 0.5f;
  const float pi = 3.14159265f;
  const float areas[4] = {4 * pi * 0.09f, 8 * (0.02f + 0.06f + 0.03f), 2 * pi * 0.3f * 0.9f + 2 * pi * 0.09f,
                          2 * pi * 0.2f * 0.5f + 4 * pi * 0.04f};
  for (int k = 0; k < 4; ++k) {
    auto pts = sample_shell(shapes[k], sp, sp / 1.5f, 100000);
    ASSERT_TRUE(pts.ok()) << pts.message();
    for (const auto& p : *pts) ASSERT_LT(surface_distance(shapes[k], p), 1e-5f) << "shape " << k;
    auto [lo, hi] = nn_range(*pts);
    EXPECT_GT(lo, 0.3f * sp) << "shape " << k;
    EXPECT_LT(hi, 1.2f * sp) << "shape " << k;
    const float expected = areas[k] / (sp * sp);
    EXPECT_GT(float(pts->size()), 0.5f * expected) << "shape " << k;
    EXPECT_LT(float(pts->size()), 2.0f * expected) << "shape " << k;
  }
}

// A closed mesh (a cube of 12 triangles): every centre sphere_radius inside a face (on the
// inner box), none closer than 0.75 spacing to another (tests/manager/mesh_sdf_test.cpp has the
// rest: coverage, spheres, bad meshes).
TEST(Shell, MeshCentresOnTheInsetSurface) {
  RigidShape s;
  s.kind = RigidShapeKind::Mesh;
  for (int i = 0; i < 8; ++i) s.vertices.push_back({i & 1 ? 0.25f : -0.25f, i & 2 ? 0.25f : -0.25f, i & 4 ? 0.25f : -0.25f});
  s.triangles = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
                 {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  auto pts = sample_shell(s, 0.05f, 0.02f, 100000);
  ASSERT_TRUE(pts.ok()) << pts.message();
  RigidShape inner;
  inner.kind = RigidShapeKind::Box;
  inner.half_extents = {0.23f, 0.23f, 0.23f};
  for (const auto& p : *pts) ASSERT_LT(surface_distance(inner, p), 1e-5f);
  EXPECT_GT(pts->size(), 6 * 0.46f * 0.46f / (0.05f * 0.05f) * 0.7f);
  EXPECT_GT(nn_range(*pts).first, 0.75f * 0.05f - 1e-6f);
  // The second request for the same mesh, spacing and radius is the cached shell; a smaller
  // capacity still gets the capacity error.
  auto again = sample_shell(s, 0.05f, 0.02f, 100000);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(*again, *pts);
  auto small = sample_shell(s, 0.05f, 0.02f, 10);
  ASSERT_FALSE(small.ok());
  EXPECT_EQ(small.error().field, "simulation.pool.shell_spheres_per_slot");
}

TEST(Shell, CapacityAndSpacingErrorsNameTheField) {
  RigidShape s;
  s.radius = 1.0f;
  auto big = sample_shell(s, 0.01f, 0.005f, 1000);
  ASSERT_FALSE(big.ok());
  EXPECT_NE(big.message().find("shell_spheres_per_slot"), std::string::npos) << big.message();
  EXPECT_FALSE(sample_shell(s, 0.0f, 0.005f, 1000).ok());
  EXPECT_FALSE(sample_shell(s, std::nanf(""), 0.005f, 1000).ok());
}
