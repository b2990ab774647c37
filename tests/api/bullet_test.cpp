// tests include/sandpatch/bullet.hpp: a Bullet body the game owns handed over to a Terrain
// (by copy) and its state pulled back into the game's btRigidBody.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <sandpatch/bullet.hpp>

namespace sp = sandpatch::api;

namespace {

sp::TerrainDef flat_def() {
  sp::TerrainDef d;
  d.procedural = "flat";
  d.samples_x = d.samples_z = 41;
  d.spacing = 0.25;
  d.base_height = 1.0f;
  d.granular_patches = false;
  return d;
}

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

  GameBody fixed(new btSphereShape(0.5f), 0.0f, btVector3(2, 3, 2));
  auto s = sp::bullet::body_def(*fixed.body);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.errors().front().field, "btRigidBody.mass");
}
