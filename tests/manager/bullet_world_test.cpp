// tests manager/bullet_world.cpp: fixed steps without an accumulator, heightfield contact
// across tiles, the double-precision world origin, and applied forces held over a frame's
// substeps (step_frame).
#include <btBulletDynamicsCommon.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "rig.hpp"

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

// Joint groups (handed to the DEM as collision groups): bodies connected by joints, directly
// or through others, share 1 + their lowest slot; a body alone or jointed only to the world
// has 0; removing a joint or a body splits the group.
TEST(BulletWorld, JointGroupsFollowTheJoints) {
  Heightfield hf = flat(9, 1.0f, 8);
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  std::vector<RigidBodyId> b;
  for (int k = 0; k < 5; ++k) {
    auto id = (*w)->add_body(ball({1.0 + 1.5 * k, 3, 4}, 0.4f));
    ASSERT_TRUE(id.ok());
    b.push_back(*id);
  }
  auto joint = [&](RigidBodyId a, RigidBodyId c) {
    RigidJointDef j;
    j.kind = JointKind::Fixed;
    j.a = a;
    j.b = c;
    j.anchor = (*w)->state(a).position;
    auto id = (*w)->add_joint(j);
    EXPECT_TRUE(id.ok()) << id.message();
    return *id;
  };
  const JointId j34 = joint(b[3], b[4]);
  joint(b[1], b[4]);  // 1 - 4 - 3: one group, lowest slot 1
  RigidJointDef to_world;
  to_world.kind = JointKind::Fixed;
  to_world.a = b[0];
  to_world.anchor = (*w)->state(b[0]).position;
  ASSERT_TRUE((*w)->add_joint(to_world).ok());
  std::vector<std::int32_t> g = (*w)->joint_groups();
  ASSERT_EQ(g.size(), 5u);
  EXPECT_EQ(g[0], 0);  // jointed to the world only
  EXPECT_EQ(g[1], 2);
  EXPECT_EQ(g[2], 0);  // alone
  EXPECT_EQ(g[3], 2);
  EXPECT_EQ(g[4], 2);
  (*w)->remove_joint(j34);
  g = (*w)->joint_groups();
  EXPECT_EQ(g[3], 0);
  EXPECT_EQ(g[1], 2);
  EXPECT_EQ(g[4], 2);
  (*w)->remove_body(b[1]);  // its joint goes with it
  g = (*w)->joint_groups();
  EXPECT_EQ(g[4], 0);
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

// After a demotion writes a crater (inside the tile's height range) or a mound (above it), the
// tile's internal-edge info is renewed around the change only, and it is what a full build on
// the new heights gives: the same triangles, the same flags, angles within 1e-5 rad (the
// sub-heightfield's vertices are the same points, shifted). No whole map is built again. The
// renewal waits (terrain_changed marks the change stale) until renew_edges: all at once, or a
// strip of 8 cells at a time (every strip computed with its neighbours: the same entries).
TEST(BulletWorld, TerrainChangeRenewsEdgeInfoAroundTheChangeOnly) {
  for (const int strip : {0, 8})
    for (const float dh : {-0.3f, 2.0f}) {
      Heightfield hf = flat(41, 0.5f, 40);  // one tile of 40 cells
      for (int j = 0; j < 41; ++j)
        for (int i = 0; i < 41; ++i) hf.set_height(i, j, 0.05f * std::sin(0.7f * i) * std::cos(0.5f * j));
      auto w = BulletWorld::create(hf, {0, -9.81f, 0});
      ASSERT_TRUE(w.ok());
      ASSERT_EQ((*w)->stats().edge_maps_built, 1);  // small terrains build it at once
      const auto before = (*w)->tile_edge_info(0);
      const GridRegion r{12, 17, 6, 5};
      for (int j = r.j0; j < r.j0 + r.nj; ++j)
        for (int i = r.i0; i < r.i0 + r.ni; ++i) hf.set_height(i, j, hf.height(i, j) + dh * (1.0f + 0.1f * float(i - j)));
      (*w)->terrain_changed(r);
      EXPECT_EQ((*w)->stats().edge_maps_refreshed, 0) << "dh " << dh << ": renewed before renew_edges";
      EXPECT_EQ((*w)->stats().stale_edge_samples, 30) << "dh " << dh;
      EXPECT_EQ((*w)->tile_edge_info(0).size(), before.size());
      int renewals = 0;
      for (int left = 1; left > 0 && renewals < 100; ++renewals) left = (*w)->renew_edges(strip);
      EXPECT_EQ((*w)->stats().stale_edge_samples, 0);
      EXPECT_EQ((*w)->stats().edge_maps_built, 1) << "dh " << dh;
      if (strip == 0) EXPECT_EQ((*w)->stats().edge_maps_refreshed, 1) << "dh " << dh;
      else EXPECT_GE((*w)->stats().edge_maps_refreshed, 30 / strip) << "dh " << dh << ": strips of " << strip << " cells";
      const auto renewed = (*w)->tile_edge_info(0);
      auto fresh_world = BulletWorld::create(hf, {0, -9.81f, 0});
      ASSERT_TRUE(fresh_world.ok());
      const auto full = (*fresh_world)->tile_edge_info(0);
      ASSERT_EQ(renewed.size(), full.size()) << "dh " << dh;
      int differ = 0;
      for (std::size_t k = 0; k < full.size(); ++k) {
        const bool same = renewed[k].key == full[k].key && renewed[k].flags == full[k].flags &&
                          std::abs(renewed[k].angles[0] - full[k].angles[0]) < 1e-5f &&
                          std::abs(renewed[k].angles[1] - full[k].angles[1]) < 1e-5f &&
                          std::abs(renewed[k].angles[2] - full[k].angles[2]) < 1e-5f;
        differ += !same;
      }
      EXPECT_EQ(differ, 0) << "dh " << dh << ", strips of " << strip << ": entries differing from a full build";
    }
}

// A body never touches stale internal-edge info: a change within a metre of a resting ball is
// renewed before the ball's next step, one 10 m away waits for renew_edges.
TEST(BulletWorld, ChangedEdgesNearABodyAreRenewedBeforeItsStep) {
  Heightfield hf = flat(41, 0.5f, 40);  // one tile of 40 cells, 20 m
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  auto id = (*w)->add_body(ball({4.0, 0.5, 4.0}));
  ASSERT_TRUE(id.ok());
  const GridRegion near{9, 9, 3, 3}, far{30, 30, 3, 3};  // samples 4.5-5.5 m and 15-16 m
  for (const GridRegion& r : {near, far}) {
    for (int j = r.j0; j < r.j0 + r.nj; ++j)
      for (int i = r.i0; i < r.i0 + r.ni; ++i) hf.set_height(i, j, -0.2f);
    (*w)->terrain_changed(r);
  }
  EXPECT_EQ((*w)->stats().stale_edge_samples, 18);
  (*w)->step(1.0f / 60.0f);
  EXPECT_EQ((*w)->stats().stale_edge_samples, 9) << "the change near the ball renewed, the far one waiting";
  EXPECT_EQ((*w)->stats().edge_maps_refreshed, 1);
  EXPECT_EQ((*w)->renew_edges(0), 0);
  EXPECT_EQ((*w)->stats().edge_maps_refreshed, 2);
}

// An idle tile costs a step nothing, counted rather than timed (BulletWorld::stats): the same
// ball dropped on the shared edge of two tiles of a 4-tile and a 1024-tile terrain (same
// 16-cell tiles, same local ground) gives Bullet the same work, whatever the tile count:
// bounds recomputed only for the active ball (none once it sleeps), the tiles in the
// broadphase's fixed tree, the same overlapping pairs, internal-edge info only for the tiles
// the ball came near; and the ball ends where it would on the small terrain (1e-5 m: the same
// float arithmetic), resting one radius above the ground (2 cm: Bullet's contact slop).
TEST(BulletWorld, IdleTilesCostAStepNothing) {
  Heightfield small = flat(33, 0.5f, 16);    // 2 × 2 tiles of 8 m; shared edge at x = 8 m
  Heightfield large = flat(513, 0.5f, 16);   // 32 × 32 tiles
  auto ws = BulletWorld::create(small, {0, -9.81f, 0});
  auto wl = BulletWorld::create(large, {0, -9.81f, 0});
  ASSERT_TRUE(ws.ok() && wl.ok());
  EXPECT_EQ((*ws)->stats().tiles, 4);
  EXPECT_EQ((*wl)->stats().tiles, 1024);
  EXPECT_EQ((*wl)->stats().edge_maps, 0);  // nothing built before a body comes near
  for (int i = 0; i < 3; ++i) (*wl)->step(1.0f / 120.0f);
  EXPECT_EQ((*wl)->stats().aabb_updates_per_step, 0);  // empty world: nothing to update
  EXPECT_EQ((*wl)->stats().dynamic_proxies, 0);
  EXPECT_EQ((*wl)->stats().fixed_proxies, 1024);
  auto a = (*ws)->add_body(ball({8.0, 1.5, 4.0}, 0.25f));
  auto b = (*wl)->add_body(ball({8.0, 1.5, 4.0}, 0.25f));
  ASSERT_TRUE(a.ok() && b.ok());
  for (int i = 0; i < 120; ++i) {
    (*ws)->step(1.0f / 120.0f);
    (*wl)->step(1.0f / 120.0f);
  }
  const BulletWorld::Stats s = (*ws)->stats(), l = (*wl)->stats();
  EXPECT_EQ(l.aabb_updates_per_step, s.aabb_updates_per_step);
  EXPECT_LE(l.aabb_updates_per_step, 1);  // the ball, while awake
  EXPECT_LE(l.dynamic_proxies, 1);
  EXPECT_EQ(l.pairs, s.pairs);
  EXPECT_LE(l.pairs, 2);                  // the ball against the two tiles under it
  EXPECT_EQ(s.edge_maps, 4);              // a terrain of at most 64 tiles builds every tile's at start-up
  EXPECT_EQ(l.edge_maps, 2);              // x in [7, 9] m, z in [3, 5] m: tiles (0, 0) and (1, 0)
  const BodyState ps = (*ws)->state(*a), pl = (*wl)->state(*b);
  EXPECT_NEAR(pl.position.y(), 0.25, 0.02);
  EXPECT_NEAR(pl.position.x(), 8.0, 0.05);
  EXPECT_NEAR(pl.position.z(), 4.0, 0.05);
  EXPECT_LT((pl.position - ps.position).norm(), 1e-5);
}

// Internal-edge info is built ahead of a moving body: a frictionless ball sliding at 6 m/s
// across fifteen 4 m tiles stays on the ground (centre within 2 cm of one radius up: no hop at
// a tile edge or a triangle edge) and on its line (z within 5 cm), and the tiles it passed
// have their info, the rest of the terrain none.
TEST(BulletWorld, SlidingBallCrossesTilesWithoutKicks) {
  Heightfield hf = flat(129, 0.5f, 8);  // 16 × 16 tiles of 4 m
  auto w = BulletWorld::create(hf, {0, -9.81f, 0});
  ASSERT_TRUE(w.ok());
  RigidBodyDef d = ball({2.0, 0.25, 10.0}, 0.25f);
  d.linear_velocity = {6.0f, 0.0f, 0.0f};
  d.friction = 0.0f;  // combined μ = 0.8 × 0; rolling resistance 1 × 0 + 0 × 0.8 (Bullet's rule)
  d.rolling_friction = 0.0f;
  auto id = (*w)->add_body(d);
  ASSERT_TRUE(id.ok());
  double worst_y = 0, worst_z = 0;
  for (int i = 0; i < 1200 && (*w)->state(*id).position.x() < 60.0; ++i) {
    (*w)->step(1.0f / 120.0f);
    const BodyState s = (*w)->state(*id);
    worst_y = std::max(worst_y, std::abs(s.position.y() - 0.25));
    worst_z = std::max(worst_z, std::abs(s.position.z() - 10.0));
  }
  EXPECT_GT((*w)->state(*id).position.x(), 60.0);
  EXPECT_LT(worst_y, 0.02);
  EXPECT_LT(worst_z, 0.05);
  const BulletWorld::Stats s = (*w)->stats();
  // Swept: x from 0.75 m to past 61 m, z from 8.75 to 11.25 m (the ball ± 1 m reach): tile
  // columns 0-15 of row 2 (z 8-12 m).
  EXPECT_EQ(s.edge_maps, 16);
  EXPECT_LT(s.edge_maps, s.tiles);
}

namespace {

// |a − b| / |b|.
double rel_err(const Eigen::Vector3f& a, const Eigen::Vector3f& b) {
  return (a.cast<double>() - b.cast<double>()).norm() / b.cast<double>().norm();
}

}  // namespace

// A force and torque given by apply_force act over every substep of step_frame(dt, k): a free
// sphere (10 kg, r = 0.5 m, 45 m above the ground) given F and τ gains Δv = (F/m + g) dt and
// Δω = τ dt / I (I = 2/5 m r², Bullet's sphere) in one frame of dt, whatever k (1, 2, 4 and 3),
// within 1e-6 relative (float round-off of k additions). A loop of step(dt / k) gives
// (F/(k m) + g) dt: Bullet's stepSimulation clears applied forces after each call, and that
// is what the terrain manager's coupling lost with more than one substep (docs/tradeoff.md).
// Gravity is not held twice (Bullet adds it inside each step), and the next frame without
// apply_force feels gravity only.
TEST(BulletWorld, StepFrameHoldsAppliedForceOverEverySubstep) {
  Heightfield hf = flat(17, 1.0f, 8);
  const Eigen::Vector3f g(0, -9.81f, 0), F(30.0f, 70.0f, -50.0f), tau(0.2f, -0.1f, 0.3f);
  const float dt = 1.0f / 60.0f;
  for (int k : {1, 2, 3, 4}) {
    SCOPED_TRACE("substeps " + std::to_string(k));
    auto w = BulletWorld::create(hf, g);
    ASSERT_TRUE(w.ok());
    auto id = (*w)->add_body(ball({8, 45, 8}));
    ASSERT_TRUE(id.ok());
    const float m = (*w)->mass(*id);
    const Eigen::Vector3f I = (*w)->principal_inertia(*id);
    EXPECT_NEAR(I.x(), 0.4 * 10.0 * 0.25, 1e-5);
    (*w)->apply_force(*id, F, tau);
    (*w)->step_frame(dt, k);
    const BodyState s1 = (*w)->state(*id);
    EXPECT_LT(rel_err(s1.linear_velocity, (F / m + g) * dt), 1e-6) << s1.linear_velocity.transpose();
    EXPECT_LT(rel_err(s1.angular_velocity, tau.cwiseQuotient(I) * dt), 1e-6) << s1.angular_velocity.transpose();
    (*w)->step_frame(dt, k);  // no force given: gravity only, the spin kept
    const BodyState s2 = (*w)->state(*id);
    EXPECT_LT(rel_err(s2.linear_velocity - s1.linear_velocity, g * dt), 1e-5);
    EXPECT_LT(rel_err(s2.angular_velocity, s1.angular_velocity), 1e-6);
  }
}

// The same for a body the game hands over (adopt_body) with a linear factor (0.5, 1, 0) and an
// angular factor (1, 0, 2): Bullet scales an applied force by the factors once
// (btRigidBody::applyCentralForce, applyTorque), and step_frame holds that scaled force, not
// the factor applied twice: Δv = f ∘ F dt / m, Δω = a ∘ τ dt / I over 3 substeps (no gravity),
// within 1e-6 relative.
TEST(BulletWorld, StepFrameHoldsForceOfAdoptedBodyWithFactors) {
  Heightfield hf = flat(17, 1.0f, 8);
  const float m = 4.0f, r = 0.3f;
  btSphereShape shape(r);
  btVector3 inertia;
  shape.calculateLocalInertia(m, inertia);
  btTransform tr;
  tr.setIdentity();
  tr.setOrigin(btVector3(8, 40, 8));
  btDefaultMotionState motion(tr);
  btRigidBody body(btRigidBody::btRigidBodyConstructionInfo(m, &motion, &shape, inertia));
  body.setLinearFactor(btVector3(0.5f, 1.0f, 0.0f));
  body.setAngularFactor(btVector3(1.0f, 0.0f, 2.0f));
  {
    auto w = BulletWorld::create(hf, Eigen::Vector3f::Zero());
    ASSERT_TRUE(w.ok());
    auto id = (*w)->adopt_body(&body, "game ball");
    ASSERT_TRUE(id.ok()) << id.message();
    const Eigen::Vector3f F(30.0f, 70.0f, -50.0f), tau(0.2f, -0.1f, 0.3f);
    const Eigen::Vector3f f(0.5f, 1.0f, 0.0f), a(1.0f, 0.0f, 2.0f);
    const Eigen::Vector3f I = (*w)->principal_inertia(*id);
    const float dt = 1.0f / 60.0f;
    (*w)->apply_force(*id, F, tau);
    (*w)->step_frame(dt, 3);
    const BodyState s = (*w)->state(*id);
    EXPECT_LT(rel_err(s.linear_velocity, f.cwiseProduct(F) * dt / m), 1e-6) << s.linear_velocity.transpose();
    EXPECT_EQ(s.linear_velocity.z(), 0.0f);
    EXPECT_LT(rel_err(s.angular_velocity, a.cwiseProduct(tau).cwiseQuotient(I) * dt), 1e-6)
        << s.angular_velocity.transpose();
    EXPECT_NEAR(s.angular_velocity.y(), 0.0f, 1e-9);  // round-off of the world inertia tensor only
  }  // the world gives the body back before it goes
}

// What the terrain manager's coupling sees: a sphere (r = 0.1 m, 5 kg) dropped from 0.3 m onto
// a patch (the rig of tests/manager/rig.hpp: granules of r = 2.5 cm, patch 0.2 m deep) in the
// frames of manager/run.cpp with `substeps` Bullet steps of dt / substeps (step_frame). With 1
// and with 2 substeps the sphere comes to rest and the patch falls asleep within 5 s, the
// sphere stays put while it sleeps (1e-4 m: hold_resting_bodies' support force held over both
// substeps), and it rests within 1 cm (0.4 granule radius) of the 1-substep depth. Measured:
// 7.6 mm deeper at 2 substeps. That rest is the coupling's position update, not the force:
// after a frame Bullet puts the body at x0 + dt (v0 + (v1 − v0)(k + 1) / 2k), i.e. x0 + v1 dt at
// one substep, which trails the shell's own path (≈ x0 + (v0 + v1) dt / 2) while the sphere is
// braked, and k substeps move it toward the shell's. With a loop of step(dt / 2) the patch's
// force reached the first substep only: the sphere sank 16.6 mm deeper in 5 s, Bullet left it
// falling at 4.1 cm/s (g dt / 4) after every frame, and the patch never slept.
TEST(BulletWorld, SubstepsKeepTheSphereOnAPatch) {
  double rest_y[2] = {0, 0};
  for (int k : {1, 2}) {
    SCOPED_TRACE("substeps " + std::to_string(k));
    test::Rig rig(test::terrain_8m("flat"));
    ASSERT_TRUE(rig.ok()) << rig.error;
    auto id = rig.add_sphere(0.1f, 5.0f, {4.0, 1.4, 4.0});
    ASSERT_TRUE(id.ok());
    auto def = test::sphere_patch_def();
    ASSERT_TRUE(rig.start(def).ok()) << rig.error;
    TerrainManager& m = *rig.manager;
    auto frame = [&] { return rig.frame(k); };  // World::step with k Bullet substeps
    double asleep_at = -1;
    for (int f = 0; f < 300 && asleep_at < 0; ++f) {
      Status s = frame();
      ASSERT_TRUE(s.ok()) << s.message();
      asleep_at = test::last_event_time(m, PatchEventKind::Asleep);
    }
    ASSERT_GE(asleep_at, 0.0) << "the patch carrying a resting sphere did not fall asleep within 5 s";
    EXPECT_FALSE(rig.world->terrain_collision(*id)) << "the particles carry the sphere";
    const double y = rig.world->state(*id).position.y();
    for (int f = 0; f < 60; ++f) {
      Status s = frame();
      ASSERT_TRUE(s.ok()) << s.message();
    }
    rest_y[k - 1] = rig.world->state(*id).position.y();
    std::printf("substeps %d: asleep at %.3f s, sphere centre %.5f m, after 60 frames more %.5f m\n", k, asleep_at, y,
                rest_y[k - 1]);
    EXPECT_NEAR(rest_y[k - 1], y, 1e-4) << "asleep, the sphere stays put (m)";
  }
  EXPECT_NEAR(rest_y[1], rest_y[0], 0.01) << "2 substeps against 1 (m)";
}
