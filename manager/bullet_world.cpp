// Bullet wrapper: see bullet_world.hpp.
#include "manager/bullet_world.hpp"

#include <BulletCollision/CollisionDispatch/btInternalEdgeUtility.h>
#include <BulletCollision/CollisionShapes/btHeightfieldTerrainShape.h>
#include <BulletCollision/CollisionShapes/btTriangleInfoMap.h>
#include <btBulletDynamicsCommon.h>

#include <cmath>

#include "heightfield/heightfield.hpp"

namespace sandpatch {
namespace {

// Bullet reports contacts against individual terrain triangles; a body pressing on the
// shared edge of two coplanar triangles gets a tilted normal and a sideways kick (Bullet's
// "internal edge" problem). Each tile carries a btTriangleInfoMap, and this callback (the
// one global Bullet asks for, installed by BulletWorld) snaps such normals back onto the
// surface's.
bool adjust_internal_edges(btManifoldPoint& cp, const btCollisionObjectWrapper* a, int part_a, int index_a,
                           const btCollisionObjectWrapper* b, int part_b, int index_b) {

  if (a->getCollisionObject()->getCollisionShape()->getShapeType() == TERRAIN_SHAPE_PROXYTYPE)
    btAdjustInternalEdgeContacts(cp, a, b, part_a, index_a);
  else if (b->getCollisionObject()->getCollisionShape()->getShapeType() == TERRAIN_SHAPE_PROXYTYPE)
    btAdjustInternalEdgeContacts(cp, b, a, part_b, index_b);
  return true;
}

btVector3 bt(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }
Eigen::Vector3f eig(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

}  // namespace

struct BulletWorld::Impl {
  const Heightfield* terrain = nullptr;
  Eigen::Vector3d origin;  // m, world position of Bullet's (0,0,0): the terrain origin

  std::unique_ptr<btDefaultCollisionConfiguration> config;
  std::unique_ptr<btCollisionDispatcher> dispatcher;
  std::unique_ptr<btDbvtBroadphase> broadphase;
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver;
  std::unique_ptr<btDiscreteDynamicsWorld> world;

  struct Tile {
    int tx, tz;
    float min_h, max_h;  // m, local: the vertical range the shape was built with
    std::unique_ptr<btHeightfieldTerrainShape> shape;
    std::unique_ptr<btTriangleInfoMap> edges;  // internal-edge info (see adjust_internal_edges)
    std::unique_ptr<btCollisionObject> object;
  };
  std::vector<Tile> tiles;

  // Collision groups: terrain tiles vs bodies, so a body can stop colliding with the terrain.
  static constexpr int kGroupBody = 1, kGroupTerrain = 2;

  struct Body {
    int generation = 0;
    RigidBodyDef def;
    bool terrain = true;  // collides with the heightfield
    std::unique_ptr<btCollisionShape> shape;
    std::unique_ptr<btTriangleMesh> mesh;  // mesh bodies keep their triangles alive
    std::unique_ptr<btDefaultMotionState> motion;
    std::unique_ptr<btRigidBody> body;
  };
  std::vector<Body> bodies;
  std::vector<int> free_slots;

  void build_tile(Tile& t) {
    const Heightfield& hf = *terrain;
    const int w = hf.tile_samples_x(t.tx), l = hf.tile_samples_z(t.tz);
    t.min_h = hf.tile_min_height(t.tx, t.tz);
    t.max_h = hf.tile_max_height(t.tx, t.tz);
    // Bullet needs a non-degenerate vertical range.
    if (t.max_h - t.min_h < 1e-3f) t.max_h = t.min_h + 1e-3f;
    t.shape = std::make_unique<btHeightfieldTerrainShape>(w, l, hf.tile_data(t.tx, t.tz), 1.0f, t.min_h, t.max_h, 1,
                                                          PHY_FLOAT, false);
    const float sp = hf.spacing();
    t.shape->setLocalScaling(btVector3(sp, 1.0f, sp));
    t.edges = std::make_unique<btTriangleInfoMap>();
    btGenerateInternalEdgeInfo(t.shape.get(), t.edges.get());
    // Bullet centres the shape on its bounding box; place it so sample (i,j) sits at local
    // (i*spacing, h, j*spacing) relative to the terrain origin.
    const GridRegion r = hf.tile_region(t.tx, t.tz);
    const btVector3 centre((r.i0 + 0.5f * (w - 1)) * sp, 0.5f * (t.min_h + t.max_h), (r.j0 + 0.5f * (l - 1)) * sp);
    if (!t.object) {
      t.object = std::make_unique<btCollisionObject>();
      t.object->setFriction(0.8f);
      t.object->setRestitution(0.1f);
      t.object->setRollingFriction(1.0f);  // combined = product with the body's coefficient
      t.object->setSpinningFriction(1.0f);
      t.object->setCollisionFlags(t.object->getCollisionFlags() | btCollisionObject::CF_CUSTOM_MATERIAL_CALLBACK);
    }
    t.object->setCollisionShape(t.shape.get());
    btTransform tr;
    tr.setIdentity();
    tr.setOrigin(centre);
    t.object->setWorldTransform(tr);
  }
};

Result<std::unique_ptr<BulletWorld>> BulletWorld::create(const Heightfield& terrain, const Eigen::Vector3f& gravity) {
  if (!gravity.allFinite()) {
    return Error{"", "gravity", "", "must be finite (m/s^2)"};
  }
  std::unique_ptr<BulletWorld> w(new BulletWorld());
  auto& m = *(w->impl_ = std::make_unique<Impl>());
  m.terrain = &terrain;
  m.origin = {terrain.origin_x(), terrain.origin_y(), terrain.origin_z()};
  m.config = std::make_unique<btDefaultCollisionConfiguration>();
  m.dispatcher = std::make_unique<btCollisionDispatcher>(m.config.get());
  m.broadphase = std::make_unique<btDbvtBroadphase>();
  m.solver = std::make_unique<btSequentialImpulseConstraintSolver>();
  m.world = std::make_unique<btDiscreteDynamicsWorld>(m.dispatcher.get(), m.broadphase.get(), m.solver.get(),
                                                      m.config.get());
  m.world->setGravity(bt(gravity));
  gContactAddedCallback = adjust_internal_edges;
  // Determinism: Bullet's solver randomises constraint order unless told not to.
  m.world->getSolverInfo().m_solverMode &= ~SOLVER_RANDMIZE_ORDER;
  m.tiles.reserve(std::size_t(terrain.tiles_x()) * terrain.tiles_z());
  for (int tz = 0; tz < terrain.tiles_z(); ++tz) {
    for (int tx = 0; tx < terrain.tiles_x(); ++tx) {
      Impl::Tile& t = m.tiles.emplace_back();
      t.tx = tx;
      t.tz = tz;
      m.build_tile(t);
      m.world->addCollisionObject(t.object.get(), Impl::kGroupTerrain, Impl::kGroupBody);
    }
  }
  return w;
}

BulletWorld::~BulletWorld() {
  if (!impl_) return;
  for (auto& b : impl_->bodies)
    if (b.body) impl_->world->removeRigidBody(b.body.get());
  for (auto& t : impl_->tiles) impl_->world->removeCollisionObject(t.object.get());
}

Result<RigidBodyId> BulletWorld::add_body(const RigidBodyDef& def) {
  auto& m = *impl_;
  const std::string field = "bodies." + def.name;
  if (!(def.mass > 0.0f) || !std::isfinite(def.mass)) {
    return Error{"", field + ".mass", std::to_string(def.mass), "must be finite and > 0 (kg)"};
  }
  Impl::Body b;
  const RigidShape& s = def.shape;
  switch (s.kind) {
    case RigidShapeKind::Sphere: b.shape = std::make_unique<btSphereShape>(s.radius); break;
    case RigidShapeKind::Box: b.shape = std::make_unique<btBoxShape>(bt(s.half_extents)); break;
    case RigidShapeKind::Cylinder:
      b.shape = std::make_unique<btCylinderShape>(btVector3(s.radius, 0.5f * s.height, s.radius));
      break;
    case RigidShapeKind::Capsule: b.shape = std::make_unique<btCapsuleShape>(s.radius, s.height); break;
    case RigidShapeKind::Mesh: {
      // A dynamic body collides through the convex hull of its mesh (Bullet has no robust
      // dynamic concave-vs-heightfield pair); inside patches the particle shell is exact.
      auto hull = std::make_unique<btConvexHullShape>();
      for (const auto& v : s.vertices) hull->addPoint(bt(v), false);
      hull->recalcLocalAabb();
      b.shape = std::move(hull);
      break;
    }
  }
  btVector3 inertia(0, 0, 0);
  b.shape->calculateLocalInertia(def.mass, inertia);
  btTransform tr;
  tr.setIdentity();
  const Eigen::Vector3d local = def.position - m.origin;
  tr.setOrigin(btVector3(float(local.x()), float(local.y()), float(local.z())));
  const Eigen::Quaternionf q = def.orientation.normalized();
  tr.setRotation(btQuaternion(q.x(), q.y(), q.z(), q.w()));
  b.motion = std::make_unique<btDefaultMotionState>(tr);
  btRigidBody::btRigidBodyConstructionInfo ci(def.mass, b.motion.get(), b.shape.get(), inertia);
  ci.m_friction = def.friction;
  ci.m_restitution = def.restitution;
  ci.m_rollingFriction = def.rolling_friction;
  ci.m_spinningFriction = def.rolling_friction;
  b.body = std::make_unique<btRigidBody>(ci);
  b.body->setLinearVelocity(bt(def.linear_velocity));
  b.body->setAngularVelocity(bt(def.angular_velocity));
  // Continuous collision for fast bodies: sweep a sphere of half the smallest extent.
  btVector3 lo, hi;
  b.shape->getAabb(btTransform::getIdentity(), lo, hi);
  const float min_extent = (hi - lo).minAxis() >= 0 ? (hi - lo)[(hi - lo).minAxis()] : 0.1f;
  b.body->setCcdMotionThreshold(0.05f * min_extent);
  b.body->setCcdSweptSphereRadius(0.5f * min_extent);
  m.world->addRigidBody(b.body.get(), Impl::kGroupBody, Impl::kGroupBody | Impl::kGroupTerrain);
  b.def = def;

  int index;
  if (!m.free_slots.empty()) {
    index = m.free_slots.back();
    m.free_slots.pop_back();
    b.generation = m.bodies[index].generation + 1;
    m.bodies[index] = std::move(b);
  } else {
    index = int(m.bodies.size());
    m.bodies.push_back(std::move(b));
  }
  return RigidBodyId{index, m.bodies[index].generation};
}

bool BulletWorld::alive(RigidBodyId id) const {
  return id.index >= 0 && id.index < int(impl_->bodies.size()) && impl_->bodies[id.index].body &&
         impl_->bodies[id.index].generation == id.generation;
}

void BulletWorld::remove_body(RigidBodyId id) {
  assert(alive(id));
  auto& b = impl_->bodies[id.index];
  impl_->world->removeRigidBody(b.body.get());
  b.body.reset();
  b.motion.reset();
  b.shape.reset();
  b.mesh.reset();
  impl_->free_slots.push_back(id.index);
}

BodyState BulletWorld::state(RigidBodyId id) const {
  assert(alive(id));
  const btRigidBody& rb = *impl_->bodies[id.index].body;
  const btTransform& tr = rb.getWorldTransform();
  const btQuaternion q = tr.getRotation();
  BodyState s;
  s.position = impl_->origin + eig(tr.getOrigin()).cast<double>();
  s.orientation = Eigen::Quaternionf(q.w(), q.x(), q.y(), q.z());
  s.linear_velocity = eig(rb.getLinearVelocity());
  s.angular_velocity = eig(rb.getAngularVelocity());
  return s;
}

void BulletWorld::bounds(RigidBodyId id, Eigen::Vector3d* lo, Eigen::Vector3d* hi) const {
  assert(alive(id));
  btVector3 a, b;
  impl_->bodies[id.index].body->getAabb(a, b);
  *lo = impl_->origin + eig(a).cast<double>();
  *hi = impl_->origin + eig(b).cast<double>();
}

std::vector<RigidBodyId> BulletWorld::bodies() const {
  std::vector<RigidBodyId> out;
  for (int i = 0; i < int(impl_->bodies.size()); ++i)
    if (impl_->bodies[i].body) out.push_back({i, impl_->bodies[i].generation});
  return out;
}

int BulletWorld::body_count() const { return int(impl_->bodies.size() - impl_->free_slots.size()); }

void BulletWorld::step(float dt) {
  assert(dt > 0.0f);
  // maxSubSteps = 0: Bullet steps exactly dt once, with no internal accumulator.
  impl_->world->stepSimulation(dt, 0, dt);
}

void BulletWorld::terrain_changed() {
  for (auto& t : impl_->tiles) {
    const float lo = impl_->terrain->tile_min_height(t.tx, t.tz), hi = impl_->terrain->tile_max_height(t.tx, t.tz);
    if (lo < t.min_h || hi > t.max_h) {
      impl_->world->removeCollisionObject(t.object.get());
      impl_->build_tile(t);
      impl_->world->addCollisionObject(t.object.get(), Impl::kGroupTerrain, Impl::kGroupBody);
    }
  }
}

int BulletWorld::terrain_tile_count() const { return int(impl_->tiles.size()); }

void BulletWorld::apply_force(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3f& torque) {
  assert(alive(id));
  btRigidBody& rb = *impl_->bodies[id.index].body;
  rb.applyCentralForce(bt(force));
  rb.applyTorque(bt(torque));
  rb.activate(true);
}

void BulletWorld::set_terrain_collision(RigidBodyId id, bool enabled) {
  assert(alive(id));
  auto& b = impl_->bodies[id.index];
  if (b.terrain == enabled) return;
  b.terrain = enabled;
  // Re-adding the body is Bullet's way to change its filter and drop its cached pairs.
  impl_->world->removeRigidBody(b.body.get());
  impl_->world->addRigidBody(b.body.get(), Impl::kGroupBody,
                             enabled ? (Impl::kGroupBody | Impl::kGroupTerrain) : Impl::kGroupBody);
  b.body->activate(true);
}

bool BulletWorld::terrain_collision(RigidBodyId id) const {
  assert(alive(id));
  return impl_->bodies[id.index].terrain;
}

float BulletWorld::mass(RigidBodyId id) const {
  assert(alive(id));
  const float inv = impl_->bodies[id.index].body->getInvMass();
  return inv > 0 ? 1.0f / inv : 0.0f;
}

Eigen::Vector3f BulletWorld::principal_inertia(RigidBodyId id) const {
  assert(alive(id));
  const btVector3 inv = impl_->bodies[id.index].body->getInvInertiaDiagLocal();
  return {inv.x() > 0 ? 1.0f / inv.x() : 0.0f, inv.y() > 0 ? 1.0f / inv.y() : 0.0f,
          inv.z() > 0 ? 1.0f / inv.z() : 0.0f};
}

const RigidBodyDef& BulletWorld::definition(RigidBodyId id) const {
  assert(alive(id));
  return impl_->bodies[id.index].def;
}

void BulletWorld::set_state(RigidBodyId id, const BodyState& s) {
  assert(alive(id));
  btRigidBody& rb = *impl_->bodies[id.index].body;
  btTransform tr;
  const Eigen::Vector3d local = s.position - impl_->origin;
  tr.setOrigin(btVector3(float(local.x()), float(local.y()), float(local.z())));
  const Eigen::Quaternionf q = s.orientation.normalized();
  tr.setRotation(btQuaternion(q.x(), q.y(), q.z(), q.w()));
  rb.setWorldTransform(tr);
  rb.getMotionState()->setWorldTransform(tr);
  rb.setLinearVelocity(bt(s.linear_velocity));
  rb.setAngularVelocity(bt(s.angular_velocity));
  rb.activate(true);
}

}  // namespace sandpatch
