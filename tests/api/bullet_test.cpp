// tests include/sandpatch/bullet.hpp: a Bullet body the game owns handed over to a Terrain,
// in place (adopt: Sandpatch steps the game's own object) or by copy (body_def / pull / push).
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <sandpatch/bullet.hpp>

#include "tests/api/terrain_defs.hpp"

namespace sp = sandpatch::api;
using sp::test::flat_def;  // 10 m flat, no granular patches
using sp::test::sand_def;  // 4 m flat, coarse granules (5 cm), k_n = 1e5 N/m

namespace {

// A game-side body: shape, motion state and the body, kept alive together.
struct GameBody {
  std::unique_ptr<btCollisionShape> shape;
  std::unique_ptr<btDefaultMotionState> motion;
  std::unique_ptr<btRigidBody> body;
  GameBody(btCollisionShape* s, float mass, const btVector3& at) : shape(s) {
    btTransform tr;
    tr.setIdentity();
    tr.setOrigin(at);
    motion = std::make_unique<btDefaultMotionState>(tr);
    btVector3 inertia(0, 0, 0);
    if (mass > 0) shape->calculateLocalInertia(mass, inertia);
    body = std::make_unique<btRigidBody>(btRigidBody::btRigidBodyConstructionInfo(mass, motion.get(), shape.get(), inertia));
  }
};

}  // namespace

// A sphere the game made falls onto the terrain in Sandpatch; pulled back each step, the
// game's body ends at surface + radius within 1 cm, at rest.
TEST(ApiBullet, HandedOverSphereRestsAndIsPulledBack) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  GameBody g(new btSphereShape(0.4f), 10.0f, btVector3(5.0f, 4.0f, 5.0f));
  g.body->setLinearVelocity(btVector3(0.0f, -1.0f, 0.0f));
  auto def = sp::bullet::body_def(*g.body, "ball");
  ASSERT_TRUE(def.ok()) << def.message();
  EXPECT_EQ(def->shape.kind, sp::ShapeKind::Sphere);
  EXPECT_NEAR(def->shape.radius, 0.4, 1e-6);
  EXPECT_NEAR(def->mass, 10.0, 1e-4);
  EXPECT_NEAR(def->linear_velocity[1], -1.0f, 1e-6f);
  auto h = t->add_body(*def);
  ASSERT_TRUE(h.ok()) << h.message();
  for (int k = 0; k < 180; ++k) {
    ASSERT_TRUE(t->step(1.0 / 60.0).ok());
    ASSERT_TRUE(sp::bullet::pull(*t, *h, *g.body).ok());
  }
  const btVector3 p = g.body->getWorldTransform().getOrigin();
  EXPECT_NEAR(p.y(), 1.0f + 0.4f, 0.01f);
  EXPECT_NEAR(p.x(), 5.0f, 0.01f);
  EXPECT_LT(g.body->getLinearVelocity().length(), 0.01f);
  // The game teleports its body; push() hands the new pose to Sandpatch.
  g.body->getWorldTransform().setOrigin(btVector3(3.0f, 3.0f, 3.0f));
  ASSERT_TRUE(sp::bullet::push(*t, *h, *g.body).ok());
  EXPECT_NEAR(t->body_state(*h)->position[1], 3.0, 1e-6);
}

TEST(ApiBullet, ShapesConvertOrAreRefusedByName) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();

  GameBody box(new btBoxShape(btVector3(0.5f, 0.25f, 1.0f)), 2.0f, btVector3(2, 3, 2));
  auto b = sp::bullet::body_def(*box.body);
  ASSERT_TRUE(b.ok()) << b.message();
  EXPECT_EQ(b->shape.kind, sp::ShapeKind::Box);
  EXPECT_NEAR(b->shape.half_extents[1], 0.25, 1e-6);  // with Bullet's margin: the box's true size

  GameBody cyl(new btCylinderShape(btVector3(0.3f, 0.6f, 0.3f)), 2.0f, btVector3(2, 3, 2));
  auto c = sp::bullet::body_def(*cyl.body);
  ASSERT_TRUE(c.ok()) << c.message();
  EXPECT_NEAR(c->shape.radius, 0.3, 1e-6);
  EXPECT_NEAR(c->shape.height, 1.2, 1e-6);

  // A unit cube as a convex hull: 8 corners, 6 square faces → 12 triangles, a closed mesh the
  // terrain accepts.
  auto* hull = new btConvexHullShape();
  for (int k = 0; k < 8; ++k) hull->addPoint(btVector3(k & 1 ? 0.5f : -0.5f, k & 2 ? 0.5f : -0.5f, k & 4 ? 0.5f : -0.5f));
  GameBody hb(hull, 1.0f, btVector3(2, 3, 2));
  auto hd = sp::bullet::body_def(*hb.body, "crate");
  ASSERT_TRUE(hd.ok()) << hd.message();
  EXPECT_EQ(hd->shape.kind, sp::ShapeKind::Mesh);
  EXPECT_EQ(hd->shape.vertices.size(), 8u * 3u);
  EXPECT_EQ(hd->shape.triangles.size(), 12u * 3u);
  auto hh = t->add_body(*hd);
  EXPECT_TRUE(hh.ok()) << hh.message();

  GameBody cx(new btCylinderShapeX(btVector3(0.6f, 0.3f, 0.3f)), 2.0f, btVector3(2, 3, 2));
  auto e = sp::bullet::body_def(*cx.body);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.errors().front().field, "btRigidBody.shape");

  GameBody cone(new btConeShape(0.3f, 0.6f), 2.0f, btVector3(2, 3, 2));
  auto f = sp::bullet::body_def(*cone.body);
  ASSERT_FALSE(f.ok());
  EXPECT_EQ(f.errors().front().field, "btRigidBody.shape");
  EXPECT_EQ(f.errors().front().value, "Cone");

  // Inverse mass 0: a static body, or a kinematic one when flagged so; the copy moves the same way.
  GameBody fixed(new btSphereShape(0.5f), 0.0f, btVector3(2, 3, 2));
  auto s = sp::bullet::body_def(*fixed.body);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(s->motion, sp::BodyMotion::Static);
  fixed.body->setCollisionFlags(fixed.body->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
  auto k = sp::bullet::body_def(*fixed.body);
  ASSERT_TRUE(k.ok()) << k.message();
  EXPECT_EQ(k->motion, sp::BodyMotion::Kinematic);
}

// In place, no patches: the game's own btRigidBody (not a copy) falls under Terrain::step and
// rests at surface + radius within 1 cm; its motion state follows; remove_body gives it back
// out of Sandpatch's world with the game's gravity and the pose it had, and the game's own
// world can step it again.
TEST(ApiBullet, AdoptedBodyMovesInPlaceAndIsGivenBack) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  GameBody g(new btSphereShape(0.4f), 10.0f, btVector3(5.0f, 4.0f, 5.0f));
  g.body->setLinearVelocity(btVector3(0.0f, -1.0f, 0.0f));
  g.body->setGravity(btVector3(0.0f, -1.0f, 0.0f));  // the game's own gravity, restored on give-back
  btRigidBody* const mine = g.body.get();
  auto h = sp::bullet::adopt(*t, *mine, "ball");
  ASSERT_TRUE(h.ok()) << h.message();
  EXPECT_NE(mine->getBroadphaseHandle(), nullptr);
  EXPECT_NEAR(mine->getGravity().y(), -9.81f, 1e-5f);
  for (int k = 0; k < 180; ++k) ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  const btVector3 p = mine->getWorldTransform().getOrigin();
  EXPECT_NEAR(p.y(), 1.0f + 0.4f, 0.01f);
  EXPECT_NEAR(p.x(), 5.0f, 0.01f);
  EXPECT_LT(mine->getLinearVelocity().length(), 0.01f);
  btTransform drawn;
  g.motion->getWorldTransform(drawn);
  EXPECT_NEAR(drawn.getOrigin().y(), p.y(), 1e-6f);
  EXPECT_NEAR(t->body_state(*h)->position[1], p.y(), 1e-6);
  // Sandpatch's teleport moves the game's object too.
  ASSERT_TRUE(t->set_body_transform(*h, {5.0, 2.0, 5.0}, {1, 0, 0, 0}).ok());
  EXPECT_NEAR(mine->getWorldTransform().getOrigin().y(), 2.0f, 1e-6f);
  ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  const btVector3 before = mine->getWorldTransform().getOrigin();

  ASSERT_TRUE(t->remove_body(*h).ok());
  EXPECT_FALSE(t->alive(*h));
  EXPECT_EQ(mine->getBroadphaseHandle(), nullptr);
  EXPECT_EQ(mine->getWorldTransform().getOrigin(), before);
  EXPECT_NEAR(mine->getGravity().y(), -1.0f, 1e-6f);
  EXPECT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_EQ(mine->getWorldTransform().getOrigin(), before);  // Sandpatch no longer moves it

  // Back in the game's own world.
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld game(&dispatcher, &broadphase, &solver, &config);
  game.setGravity(btVector3(0, -9.81f, 0));
  game.addRigidBody(mine);
  game.stepSimulation(0.1f, 0, 0.1f);
  EXPECT_LT(mine->getWorldTransform().getOrigin().y(), before.y());
  game.removeRigidBody(mine);
}

// Destroying the Terrain gives adopted bodies back as remove_body does (the body must outlive
// the adoption, not the other way round); with a terrain origin away from 0 the body is in
// terrain-local coordinates while adopted and back in world coordinates afterwards.
TEST(ApiBullet, DestroyedTerrainGivesAdoptedBodiesBack) {
  GameBody g(new btSphereShape(0.4f), 10.0f, btVector3(105.0f, 4.0f, 205.0f));
  g.body->setGravity(btVector3(0.0f, -2.0f, 0.0f));
  {
    sp::TerrainDef def = flat_def();
    def.origin = {100.0, 0.0, 200.0};
    auto t = sp::Terrain::create(def);
    ASSERT_TRUE(t.ok()) << t.message();
    auto h = sp::bullet::adopt(*t, *g.body, "ball");
    ASSERT_TRUE(h.ok()) << h.message();
    EXPECT_NEAR(g.body->getWorldTransform().getOrigin().x(), 5.0f, 1e-5f);  // world − origin
    EXPECT_NEAR(t->body_state(*h)->position[0], 105.0, 1e-5);                 // the API speaks world
    for (int k = 0; k < 180; ++k) ASSERT_TRUE(t->step(1.0 / 60.0).ok());
    EXPECT_NEAR(t->body_state(*h)->position[1], 1.0 + 0.4, 0.01);
  }
  EXPECT_EQ(g.body->getBroadphaseHandle(), nullptr);
  EXPECT_NEAR(g.body->getGravity().y(), -2.0f, 1e-6f);
  // Sideways: within 5 cm (a game body keeps its own rolling friction, 0 here, and Bullet's
  // landing on the heightfield's triangle edges pushes it 2.7 cm sideways; measured).
  EXPECT_NEAR(g.body->getWorldTransform().getOrigin().x(), 105.0f, 0.05f);
  EXPECT_NEAR(g.body->getWorldTransform().getOrigin().y(), 1.4f, 0.01f);
  EXPECT_NEAR(g.body->getWorldTransform().getOrigin().z(), 205.0f, 0.05f);
}

// Refusals name what is wrong: a body still in the game's world, a static body, a cone, the
// same body twice, a Bullet of another build (btRigidBody.abi); none is left in the terrain.
TEST(ApiBullet, AdoptionRefusalsNameTheProblem) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher(&config);
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btDiscreteDynamicsWorld game(&dispatcher, &broadphase, &solver, &config);
  GameBody in_world(new btSphereShape(0.3f), 1.0f, btVector3(2, 3, 2));
  game.addRigidBody(in_world.body.get());
  auto a = sp::bullet::adopt(*t, *in_world.body);
  ASSERT_FALSE(a.ok());
  EXPECT_EQ(a.errors().front().field, "btRigidBody");
  EXPECT_NE(a.message().find("remove it from the game's world"), std::string::npos) << a.message();
  game.removeRigidBody(in_world.body.get());

  GameBody fixed(new btSphereShape(0.5f), 0.0f, btVector3(2, 3, 2));
  auto b = sp::bullet::adopt(*t, *fixed.body);
  ASSERT_FALSE(b.ok());
  EXPECT_EQ(b.errors().front().field, "btRigidBody.mass");

  GameBody cone(new btConeShape(0.3f, 0.6f), 2.0f, btVector3(2, 3, 2));
  auto c = sp::bullet::adopt(*t, *cone.body);
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.errors().front().field, "btRigidBody.shape");
  EXPECT_EQ(c.errors().front().value, "Cone");

  GameBody ok(new btBoxShape(btVector3(0.2f, 0.2f, 0.2f)), 2.0f, btVector3(2, 3, 2));
  auto good = sp::bullet::adopt(*t, *ok.body);
  ASSERT_TRUE(good.ok()) << good.message();
  auto twice = sp::bullet::adopt(*t, *ok.body);
  ASSERT_FALSE(twice.ok());
  EXPECT_EQ(twice.errors().front().field, "btRigidBody");

  sp::Terrain::BulletAbi wrong;
  wrong.scalar_bytes = 8;
  wrong.version = BT_BULLET_VERSION;
  wrong.rigid_body_bytes = sizeof(btRigidBody);
  auto d = t->adopt_bullet_body(in_world.body.get(), "", wrong);
  ASSERT_FALSE(d.ok());
  EXPECT_EQ(d.errors().front().field, "btRigidBody.abi");
  EXPECT_EQ(t->bodies().size(), 1u);
  EXPECT_EQ(in_world.body->getBroadphaseHandle(), nullptr);
  // The game's body must outlive its adoption: give it back before it is destroyed.
  ASSERT_TRUE(t->remove_body(*good).ok());
}

// In place, on sand: the game's 0.15 m, 20 kg sphere is predicted, a patch is promoted before
// it lands, and the game's own object comes to rest on the granules, its centre within 1 d
// of surface + radius (d = 10 cm, as the copied sphere of sandpatch_test.cpp), slower than
// 5 cm/s; given back while a patch carries it, the patch steps on.
TEST(ApiBullet, AdoptedBodyLandsOnTheParticles) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  GameBody g(new btSphereShape(0.15f), 20.0f, btVector3(2.0f, 1.0f + 0.15f + 0.3f, 2.0f));
  btRigidBody* const mine = g.body.get();
  auto h = sp::bullet::adopt(*t, *mine, "ball");
  ASSERT_TRUE(h.ok()) << h.message();
  bool promoted_before_landing = false;
  for (int k = 0; k < 150; ++k) {  // 2.5 s
    ASSERT_TRUE(t->step(1.0 / 60.0).ok());
    for (const auto& e : t->poll_events())
      if (e.kind == sp::EventKind::Promoted && e.time < 0.247) promoted_before_landing = true;
  }
  EXPECT_TRUE(promoted_before_landing);
  EXPECT_EQ(t->active_patches(), 1);
  const double d = 0.1;
  const btVector3 p = mine->getWorldTransform().getOrigin();
  EXPECT_NEAR(p.y(), 1.0 + 0.15, 1.0 * d);
  EXPECT_LT(std::hypot(p.x() - 2.0, p.z() - 2.0), 3.0 * d);
  EXPECT_LT(mine->getLinearVelocity().length(), 0.05f);
  std::printf("adopted sphere on sand: centre at %.4f m (surface + radius = 1.15 m), speed %.4f m/s\n", p.y(),
              mine->getLinearVelocity().length());
  const btVector3 before = p;
  ASSERT_TRUE(t->remove_body(*h).ok());
  EXPECT_EQ(mine->getBroadphaseHandle(), nullptr);
  for (int k = 0; k < 6; ++k) ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_EQ(mine->getWorldTransform().getOrigin(), before);
  EXPECT_EQ(t->active_patches(), 1);
}

// In place, a convex hull on sand: the game's 0.3 m cube (a btConvexHullShape of 8 points,
// 20 kg) enters the patch with a mesh shell sampled from its signed distance field (spheres
// inset by r, so the granules meet the cube's own faces: docs/manager.md "Mesh shells") and
// comes to rest on the granules, its centre within 1 d of surface + 0.15 m, slower than 5 cm/s.
TEST(ApiBullet, AdoptedHullLandsOnTheParticles) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  auto* hull = new btConvexHullShape();
  for (int k = 0; k < 8; ++k) hull->addPoint(btVector3(k & 1 ? 0.15f : -0.15f, k & 2 ? 0.15f : -0.15f, k & 4 ? 0.15f : -0.15f));
  GameBody g(hull, 20.0f, btVector3(2.0f, 1.0f + 0.15f + 0.3f, 2.0f));
  btRigidBody* const mine = g.body.get();
  auto h = sp::bullet::adopt(*t, *mine, "crate");
  ASSERT_TRUE(h.ok()) << h.message();
  for (int k = 0; k < 150; ++k) {
    auto st = t->step(1.0 / 60.0);
    ASSERT_TRUE(st.ok()) << st.message();
  }
  EXPECT_EQ(t->active_patches(), 1);
  const btVector3 p = mine->getWorldTransform().getOrigin();
  EXPECT_NEAR(p.y(), 1.0 + 0.15, 0.1);
  EXPECT_LT(mine->getLinearVelocity().length(), 0.05f);
  std::printf("adopted hull cube on sand: centre at %.4f m (surface + half side = 1.15 m), speed %.4f m/s\n", p.y(),
              mine->getLinearVelocity().length());
  ASSERT_TRUE(t->remove_body(*h).ok());
}
