// tests particles/dem_physics.hpp: the C++ side of shaders/dem/physics_common.glsl (the
// physics the CPU backend and the GL kernels compile from one source): terrain sampling and
// the boundary planes. The contact law is tested by contact_test.cpp (and against the AVX2
// kernel by contact_avx2_test.cpp); the GL side by tests/particles/gpu/gl_simulation_test.cpp.
#include "particles/dem_physics.hpp"

#include <gtest/gtest.h>

#include <cmath>

namespace sandpatch {
namespace {

// A 3 x 3 grid (spacing 0.1 m from (0, 0)) of the plane h = 0.2 x + 0.1 z + 0.05, filled
// rectangle [0.05, 0.15]^2.
TerrainGrid plane_grid() {
  TerrainGrid t;
  t.nx = t.nz = 3;
  t.x0 = t.z0 = 0.0f;
  t.spacing = 0.1f;
  for (int iz = 0; iz < 3; ++iz)
    for (int ix = 0; ix < 3; ++ix) t.heights.push_back(0.2f * (0.1f * ix) + 0.1f * (0.1f * iz) + 0.05f);
  t.fill_min_x = t.fill_min_z = 0.05f;
  t.fill_max_x = t.fill_max_z = 0.15f;
  return t;
}

}  // namespace

// Bilinear samples reproduce a plane inside the grid and clamp to the edge outside; the
// normal of the plane is exact to float round-off.
TEST(DemPhysics, TerrainHeightAndNormalOfAPlane) {
  const TerrainGrid t = plane_grid();
  for (float x : {0.0f, 0.03f, 0.1f, 0.17f, 0.2f})
    for (float z : {0.0f, 0.08f, 0.2f}) EXPECT_NEAR(physics::terrain_height(t, x, z), 0.2f * x + 0.1f * z + 0.05f, 1e-6f);
  EXPECT_NEAR(physics::terrain_height(t, -1.0f, 0.0f), 0.05f, 1e-6f);  // clamped at the edge
  EXPECT_NEAR(physics::terrain_height(t, 0.5f, 0.5f), 0.11f, 1e-6f);  // clamped to (0.2, 0.2)
  const Vec3 n = physics::terrain_normal(t, 0.1f, 0.1f);
  const float s = 1.0f / std::sqrt(1.0f + 0.04f + 0.01f);
  EXPECT_NEAR(n.x, -0.2f * s, 1e-5f);
  EXPECT_NEAR(n.y, s, 1e-5f);
  EXPECT_NEAR(n.z, -0.1f * s, 1e-5f);
  EXPECT_EQ(t.height(0.03f, 0.08f), physics::terrain_height(t, 0.03f, 0.08f));  // TerrainGrid calls it
}

// Floor and side walls: touching below r, with the inward normal and the centre's distance.
TEST(DemPhysics, FloorAndWalls) {
  const TerrainGrid none;
  const physics::Boundaries b{0.0f, true, false, Vec3{-1, 0, -1}, Vec3{1, 1, 1}};
  Vec3 n;
  float dist = 0;
  const float r = 0.005f;
  ASSERT_TRUE(physics::boundary_plane(b, none, 0, Vec3{0, 0.004f, 0}, r, n, dist));
  EXPECT_EQ(n.y, 1.0f);
  EXPECT_FLOAT_EQ(dist, 0.004f);
  EXPECT_FALSE(physics::boundary_plane(b, none, 0, Vec3{0, 0.006f, 0}, r, n, dist));
  ASSERT_TRUE(physics::boundary_plane(b, none, 2, Vec3{0.997f, 0.5f, 0}, r, n, dist));  // wall x = bmax.x
  EXPECT_EQ(n.x, -1.0f);
  EXPECT_NEAR(dist, 0.003f, 1e-6f);
  EXPECT_FALSE(physics::boundary_plane(b, none, 3, Vec3{0, 0.5f, 0}, r, n, dist));
  EXPECT_FALSE(physics::boundary_plane(b, none, 5, Vec3{0, 0.5f, 0}, r, n, dist));  // no terrain
  const physics::Boundaries open{0.0f, false, false, Vec3{-1, 0, -1}, Vec3{1, 1, 1}};
  EXPECT_FALSE(physics::boundary_plane(open, none, 2, Vec3{0.997f, 0.5f, 0}, r, n, dist));  // no walls
}

// The terrain outside the filled rectangle (slot 5) and the rectangle's sides without walls:
// a wall below the outside surface h, its top edge above h (the contact turns from the wall
// to the edge as a sphere rises past h).
TEST(DemPhysics, TerrainSurfaceAndFillSides) {
  const TerrainGrid t = plane_grid();
  const physics::Boundaries b{-1.0f, false, true, Vec3{0, -1, 0}, Vec3{0.2f, 1, 0.2f}};
  const float r = 0.005f;
  Vec3 n;
  float dist = 0;
  // outside the fill, 3 mm above the surface along y
  const float x = 0.02f, z = 0.1f, h = physics::terrain_height(t, x, z);
  ASSERT_TRUE(physics::boundary_plane(b, t, 5, Vec3{x, h + 0.003f, z}, r, n, dist));
  EXPECT_NEAR(dist, 0.003f * n.y, 1e-6f);
  EXPECT_FALSE(physics::boundary_plane(b, t, 1, Vec3{x, h + 0.003f, z}, r, n, dist));  // outside: no side
  // inside, 2 mm from the side x = fill_min_x, below the outside surface: the wall
  const float hs = physics::terrain_height(t, t.fill_min_x - r, 0.1f);
  ASSERT_TRUE(physics::boundary_plane(b, t, 1, Vec3{t.fill_min_x + 0.002f, hs - 0.01f, 0.1f}, r, n, dist));
  EXPECT_EQ(n.x, 1.0f);
  EXPECT_NEAR(dist, 0.002f, 1e-6f);
  // above it by 3 mm: the edge, at distance sqrt(2^2 + 3^2) mm, normal from the edge
  ASSERT_TRUE(physics::boundary_plane(b, t, 1, Vec3{t.fill_min_x + 0.002f, hs + 0.003f, 0.1f}, r, n, dist));
  EXPECT_NEAR(dist, std::sqrt(0.002f * 0.002f + 0.003f * 0.003f), 1e-6f);
  EXPECT_NEAR(n.x, 0.002f / dist, 1e-4f);
  EXPECT_NEAR(n.y, 0.003f / dist, 1e-4f);
  // far above the edge: no contact
  EXPECT_FALSE(physics::boundary_plane(b, t, 1, Vec3{t.fill_min_x + 0.002f, hs + 0.01f, 0.1f}, r, n, dist));
  EXPECT_FALSE(physics::boundary_plane(b, t, 5, Vec3{0.1f, 1.0f, 0.1f}, r, n, dist));  // inside: no surface
  // past the side x = fill_min_x by 2 mm, 20 mm below the outside surface: pushed back through
  // the side (overlap r + 2 mm), not up through 20 mm of soil; 1 mm below it: up, the nearer
  const float hb = physics::terrain_height(t, t.fill_min_x - 0.002f, 0.1f);
  ASSERT_TRUE(physics::boundary_plane(b, t, 5, Vec3{t.fill_min_x - 0.002f, hb - 0.02f, 0.1f}, r, n, dist));
  EXPECT_NEAR(n.x, 1.0f, 1e-6f);
  EXPECT_EQ(n.y, 0.0f);
  EXPECT_NEAR(dist, -0.002f, 1e-6f);
  ASSERT_TRUE(physics::boundary_plane(b, t, 5, Vec3{t.fill_min_x - 0.002f, hb - 0.001f, 0.1f}, r, n, dist));
  EXPECT_GT(n.y, 0.9f);
  EXPECT_NEAR(dist, -0.001f * n.y, 1e-6f);
  // past a corner (2 mm in x, 3 mm in z) deep below: back toward the corner, 3.6 mm
  const float hc = physics::terrain_height(t, t.fill_min_x - 0.002f, t.fill_min_z - 0.003f);
  ASSERT_TRUE(physics::boundary_plane(b, t, 5, Vec3{t.fill_min_x - 0.002f, hc - 0.02f, t.fill_min_z - 0.003f}, r, n, dist));
  EXPECT_NEAR(dist, -std::sqrt(0.002f * 0.002f + 0.003f * 0.003f), 1e-6f);
  EXPECT_NEAR(n.x, 0.002f / -dist, 1e-5f);
  EXPECT_NEAR(n.z, 0.003f / -dist, 1e-5f);
}

}  // namespace sandpatch
