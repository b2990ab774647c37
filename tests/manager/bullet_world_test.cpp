// tests manager/bullet_world.cpp: fixed steps without an accumulator, heightfield contact
// across tiles, and the double-precision world origin.
#include <gtest/gtest.h>

#include <cmath>

#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"

using namespace sandpatch;

namespace {

Heightfield flat(int n, float spacing, int tile_cells, double ox = 0, double oy = 0, double oz = 0) {
  HeightfieldDef d;
  d.samples_x = d.samples_z = n;
  d.spacing = spacing;
  d.tile_cells = tile_cells;
  d.origin_x = ox;
  d.origin_y = oy;
  d.origin_z = oz;
  auto hf = Heightfield::create(d);
  EXPECT_TRUE(hf.ok());
  return std::move(*hf);
}

RigidBodyDef ball(Eigen::Vector3d pos, float r = 0.5f) {
  RigidBodyDef b;
  b.name = "ball";
  b.shape.kind = RigidShapeKind::Sphere;
  b.shape.radius = r;
  b.mass = 10.0f;
  b.position = pos;
  b.restitution = 0.0f;
  return b;
}

}  // namespace

// Bullet's integrator is semi-implicit Euler: after n steps of dt from rest,
// v_n = -g n dt and y_n = y_0 - g dt^2 n(n+1)/2. Both exactly, up to float round-off
// (tolerance 1e-4 m, 1e-4 m/s): this proves step(dt) takes exactly one step of dt.
TEST(BulletWorld, FreeFallFollowsSemiImplicitEulerExactly) {
  Heightfield hf = flat(17, 1.0f, 8);
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  auto id = (*w)->add_body(ball({8, 50, 8}));
  ASSERT_TRUE(id.ok());
  const float dt = 1.0f / 60.0f;
  const int n = 60;
  for (int i = 0; i < n; ++i) (*w)->step(dt);
  const BodyState s = (*w)->state(*id);
  EXPECT_NEAR(s.linear_velocity.y(), -9.81 * n * dt, 1e-4);
  EXPECT_NEAR(s.position.y(), 50.0 - 9.81 * dt * dt * n * (n + 1) / 2.0, 1e-4);
}

// A sphere dropped on a flat heightfield rests with its centre one radius above the surface
// (tolerance 2 cm: Bullet's contact slop), also exactly on a tile corner where four tile
// shapes meet, and it lands where it fell: less than 5 cm sideways (no kick from triangle
// edges; see adjust_internal_edges and the CCD settings in bullet_world.cpp).
TEST(BulletWorld, SphereRestsOnHeightfieldAcrossTileCorners) {
  Heightfield hf = flat(33, 0.5f, 8);  // tiles of 8 cells = 4 m; corner at (4, 4)
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  EXPECT_EQ((*w)->terrain_tile_count(), 16);
  auto a = (*w)->add_body(ball({4.0, 2.0, 4.0}));
  auto b = (*w)->add_body(ball({10.3, 3.0, 6.1}));
  ASSERT_TRUE(a.ok() && b.ok());
  for (int i = 0; i < 240; ++i) (*w)->step(1.0f / 60.0f);
  const Eigen::Vector3d start[2] = {{4.0, 0, 4.0}, {10.3, 0, 6.1}};
  for (int k = 0; k < 2; ++k) {
    const BodyState s = (*w)->state(k == 0 ? *a : *b);
    EXPECT_NEAR(s.position.y(), 0.5, 0.02);
    EXPECT_NEAR(s.position.x(), start[k].x(), 0.05);
    EXPECT_NEAR(s.position.z(), start[k].z(), 0.05);
    EXPECT_LT(s.linear_velocity.norm(), 0.05f);
  }
}

// The terrain may sit 10 km from the world origin: Bullet works relative to the terrain
// origin, so the resting height is as accurate as at the origin (same 2 cm tolerance).
TEST(BulletWorld, FarFromOriginKeepsPrecision) {
  const double X = 10000.0, Y = 250.0, Z = -10000.0;
  Heightfield hf = flat(33, 0.5f, 8, X, Y, Z);
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  auto id = (*w)->add_body(ball({X + 8.0, Y + 2.0, Z + 8.0}));
  ASSERT_TRUE(id.ok());
  for (int i = 0; i < 240; ++i) (*w)->step(1.0f / 60.0f);
  const BodyState s = (*w)->state(*id);
  EXPECT_NEAR(s.position.y(), Y + 0.5, 0.02);
  EXPECT_NEAR(s.position.x(), X + 8.0, 1e-3);
}

// Bad definitions are refused with the field named; removed handles become stale.
TEST(BulletWorld, RefusesBadMassAndDetectsStaleHandles) {
  Heightfield hf = flat(9, 1.0f, 8);
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  RigidBodyDef bad = ball({4, 2, 4});
  bad.mass = -1.0f;
  auto r = (*w)->add_body(bad);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("bodies.ball.mass"), std::string::npos) << r.message();
  auto id = (*w)->add_body(ball({4, 2, 4}));
  ASSERT_TRUE(id.ok());
  (*w)->remove_body(*id);
  EXPECT_FALSE((*w)->alive(*id));
  auto id2 = (*w)->add_body(ball({4, 2, 4}));
  ASSERT_TRUE(id2.ok());
  EXPECT_EQ(id2->index, id->index);
  EXPECT_FALSE((*w)->alive(*id));
  EXPECT_TRUE((*w)->alive(*id2));
}

// Bullet reads the heightfield's own tile arrays (no copy): raise the terrain by 1 m after
// the world was built and a sphere dropped on it rests 1 m higher (2 cm tolerance).
TEST(BulletWorld, SeesHeightfieldEditsWithoutCopy) {
  Heightfield hf = flat(17, 0.5f, 16);
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  auto id = (*w)->add_body(ball({4.0, 3.0, 4.0}));
  ASSERT_TRUE(id.ok());
  for (int j = 0; j < 17; ++j)
    for (int i = 0; i < 17; ++i) hf.set_height(i, j, 1.0f);
  (*w)->terrain_changed();
  for (int i = 0; i < 300; ++i) (*w)->step(1.0f / 60.0f);
  EXPECT_NEAR((*w)->state(*id).position.y(), 1.5, 0.02);
}
