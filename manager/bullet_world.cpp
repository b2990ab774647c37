// Bullet wrapper: see bullet_world.hpp. Bodies, the terrain and the step here; joints in
// bullet_joints.cpp; the shared state in bullet_world_impl.hpp.
#include "manager/bullet_world_impl.hpp"

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


}  // namespace


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
  // Only active objects get new bounds each step: the terrain tiles are static and asleep
  // (build_tile), so an idle terrain costs Bullet nothing per tile.
  m.world->setForceUpdateAllAabbs(false);
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
  // Internal-edge info (about 15 ms a 128 × 128-cell tile) is built now for terrains of up to
  // kEagerEdgeTiles tiles, so the first frame a body touches a tile does not pay it (it was the
  // longest frame of every shipped scene: the first, at 15-20 ms against a 1 ms median); larger
  // terrains build it for the tiles bodies come near, before their step (ensure_edges).
  if (m.tiles.size() <= Impl::kEagerEdgeTiles)
    for (auto& t : m.tiles) m.build_edges(t);
  return w;
}

BulletWorld::~BulletWorld() {
  if (!impl_) return;
  for (std::size_t k = 0; k < impl_->joints.size(); ++k)
    if (impl_->joints[k].c) impl_->drop_joint(int(k));
  for (auto& b : impl_->bodies)
    if (b.rb) {
      impl_->world->removeRigidBody(b.rb);
      if (b.adopted) impl_->give_back(b);
    }
  for (auto& t : impl_->tiles) impl_->world->removeCollisionObject(t.object.get());
}

Result<RigidBodyId> BulletWorld::add_body(const RigidBodyDef& def) {
  auto& m = *impl_;
  const std::string field = "bodies." + def.name;
  const bool dynamic = def.motion == RigidMotion::Dynamic;
  if (dynamic && (!(def.mass > 0.0f) || !std::isfinite(def.mass))) {
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
  if (dynamic) b.shape->calculateLocalInertia(def.mass, inertia);
  if (dynamic && s.kind == RigidShapeKind::Mesh) {
    // Bullet's hull inertia is its bounding box's (a tessellated sphere would get 2/3 m R²
    // instead of 2/5 m R²): use the closed mesh's exact tensor (scene/mesh.hpp), whose
    // diagonal in the mesh axes is the body's principal inertia when those axes are principal
    // (symmetric meshes; docs/manager.md "Mesh shells").
    TriangleMesh tm;
    tm.vertices = s.vertices;
    tm.triangles = s.triangles;
    const Eigen::Vector3d d = tm.inertia(def.mass).diagonal();
    if (d.allFinite() && d.minCoeff() > 0) inertia = btVector3(float(d.x()), float(d.y()), float(d.z()));
  }
  btTransform tr;
  tr.setIdentity();
  const Eigen::Vector3d local = def.position - m.origin;
  tr.setOrigin(btVector3(float(local.x()), float(local.y()), float(local.z())));
  const Eigen::Quaternionf q = def.orientation.normalized();
  tr.setRotation(btQuaternion(q.x(), q.y(), q.z(), q.w()));
  b.motion = std::make_unique<btDefaultMotionState>(tr);
  // Kinematic and static bodies have no mass for Bullet (inverse mass 0: nothing moves them).
  btRigidBody::btRigidBodyConstructionInfo ci(dynamic ? def.mass : 0.0f, b.motion.get(), b.shape.get(), inertia);
  ci.m_friction = def.friction;
  ci.m_restitution = def.restitution;
  ci.m_rollingFriction = def.rolling_friction;
  ci.m_spinningFriction = def.rolling_friction;
  b.body = std::make_unique<btRigidBody>(ci);
  if (dynamic) {
    b.body->setLinearVelocity(bt(def.linear_velocity));
    b.body->setAngularVelocity(bt(def.angular_velocity));
    // Continuous collision for fast bodies: sweep a sphere of half the smallest extent.
    btVector3 lo, hi;
    b.shape->getAabb(btTransform::getIdentity(), lo, hi);
    const float min_extent = (hi - lo).minAxis() >= 0 ? (hi - lo)[(hi - lo).minAxis()] : 0.1f;
    b.body->setCcdMotionThreshold(0.05f * min_extent);
    b.body->setCcdSweptSphereRadius(0.5f * min_extent);
  } else if (def.motion == RigidMotion::Kinematic) {
    // Bullet reads a kinematic body's pose from its motion state at every step and derives its
    // velocity from the change; it must never be deactivated.
    b.body->setCollisionFlags(b.body->getCollisionFlags() | btCollisionObject::CF_KINEMATIC_OBJECT);
    b.body->setActivationState(DISABLE_DEACTIVATION);
  } else {
    b.body->setCollisionFlags(b.body->getCollisionFlags() | btCollisionObject::CF_STATIC_OBJECT);
  }
  b.rb = b.body.get();
  m.world->addRigidBody(b.rb, Impl::kGroupBody, Impl::kGroupBody | Impl::kGroupTerrain);
  b.def = def;
  return m.insert(std::move(b));
}

namespace {

// The RigidShape of a game's Bullet shape (for shells); the mapping of include/sandpatch/bullet.hpp.
Result<RigidShape> shape_of(const btCollisionShape* shape) {
  RigidShape r;
  if (!shape) return Error{"", "btRigidBody.shape", "null", "the body needs a collision shape"};
  const btVector3 scale = shape->getLocalScaling();
  switch (shape->getShapeType()) {
    case SPHERE_SHAPE_PROXYTYPE:
      r.kind = RigidShapeKind::Sphere;
      r.radius = static_cast<const btSphereShape*>(shape)->getRadius();
      return r;
    case BOX_SHAPE_PROXYTYPE:
      r.kind = RigidShapeKind::Box;
      r.half_extents = eig(static_cast<const btBoxShape*>(shape)->getHalfExtentsWithMargin());
      return r;
    case CYLINDER_SHAPE_PROXYTYPE: {
      const auto* c = static_cast<const btCylinderShape*>(shape);
      if (c->getUpAxis() != 1) break;
      r.kind = RigidShapeKind::Cylinder;
      r.radius = c->getHalfExtentsWithMargin().x();
      r.height = 2 * c->getHalfExtentsWithMargin().y();
      return r;
    }
    case CAPSULE_SHAPE_PROXYTYPE: {
      const auto* c = static_cast<const btCapsuleShape*>(shape);
      if (c->getUpAxis() != 1) break;
      r.kind = RigidShapeKind::Capsule;
      r.radius = c->getRadius();
      r.height = 2 * c->getHalfHeight();
      return r;
    }
    case CONVEX_HULL_SHAPE_PROXYTYPE: {
      // The hull's faces (btConvexHullComputer: convex polygons, fanned into triangles), in the
      // body frame as Bullet has it (the game's centre of mass at the origin).
      const auto* hull = static_cast<const btConvexHullShape*>(shape);
      btConvexHullComputer ch;
      const btVector3* pts = hull->getUnscaledPoints();
      if (ch.compute(&pts[0].getX(), sizeof(btVector3), hull->getNumPoints(), 0, 0) < 0 || ch.faces.size() < 4)
        return Error{"", "btRigidBody.shape", "convex hull of " + std::to_string(hull->getNumPoints()) + " points",
                     "the hull must enclose a volume"};
      r.kind = RigidShapeKind::Mesh;
      for (int k = 0; k < ch.vertices.size(); ++k) r.vertices.push_back(eig(ch.vertices[k] * scale));
      for (int f = 0; f < ch.faces.size(); ++f) {
        const btConvexHullComputer::Edge* first = &ch.edges[ch.faces[f]];
        const int v0 = first->getSourceVertex();
        const btConvexHullComputer::Edge* e = first->getNextEdgeOfFace();
        for (const btConvexHullComputer::Edge* n = e->getNextEdgeOfFace(); n != first; e = n, n = n->getNextEdgeOfFace())
          r.triangles.push_back({v0, e->getSourceVertex(), n->getSourceVertex()});
      }
      return r;
    }
    default: break;
  }
  return Error{"", "btRigidBody.shape", shape->getName(),
               "must be a btSphereShape, btBoxShape, btCylinderShape or btCapsuleShape (axis on y) or a btConvexHullShape"};
}

}  // namespace

Result<RigidBodyId> BulletWorld::adopt_body(btRigidBody* rb, const std::string& name) {
  auto& m = *impl_;
  if (!rb) return Error{"", "btRigidBody", "null", "a body to adopt"};
  if (rb->getBroadphaseHandle())
    return Error{"", "btRigidBody", name.empty() ? "(unnamed)" : name,
                 "must not be in a Bullet world (remove it from the game's world before handing it over)"};
  for (const auto& b : m.bodies)
    if (b.rb == rb) return Error{"", "btRigidBody", name.empty() ? "(unnamed)" : name, "is already in this terrain"};
  if (!(rb->getInvMass() > 0))
    return Error{"", "btRigidBody.mass", "0 (static)", "only dynamic bodies (inverse mass > 0) can be handed over"};
  auto shape = shape_of(rb->getCollisionShape());
  if (!shape) return shape.errors();
  Impl::Body b;
  b.rb = rb;
  b.adopted = true;
  b.game_gravity = rb->getGravity();
  // The definition the rest of Sandpatch reads (shells, bounds, names); Bullet keeps the
  // game's own inertia, damping, CCD and flags.
  RigidBodyDef& d = b.def;
  d.name = name;
  d.shape = std::move(*shape);
  d.mass = 1.0f / rb->getInvMass();
  d.friction = rb->getFriction();
  d.restitution = rb->getRestitution();
  d.rolling_friction = rb->getRollingFriction();
  const btTransform& tr = rb->getWorldTransform();
  d.position = eig(tr.getOrigin()).cast<double>();
  const btQuaternion q = tr.getRotation();
  d.orientation = Eigen::Quaternionf(q.w(), q.x(), q.y(), q.z());
  d.linear_velocity = eig(rb->getLinearVelocity());
  d.angular_velocity = eig(rb->getAngularVelocity());
  // Bullet runs relative to the terrain origin (the precision boundary): the body moves into
  // that frame while Sandpatch has it, and back when it is given back.
  Impl::shift(*rb, -btVector3(float(m.origin.x()), float(m.origin.y()), float(m.origin.z())));
  m.world->addRigidBody(rb, Impl::kGroupBody, Impl::kGroupBody | Impl::kGroupTerrain);  // sets the world's gravity
  rb->activate(true);
  return m.insert(std::move(b));
}

void BulletWorld::bullet_abi(int* scalar_bytes, int* version, std::size_t* rigid_body_bytes) {
  *scalar_bytes = int(sizeof(btScalar));
  *version = BT_BULLET_VERSION;
  *rigid_body_bytes = sizeof(btRigidBody);
}

bool BulletWorld::adopted(RigidBodyId id) const { return alive(id) && impl_->bodies[id.index].adopted; }

bool BulletWorld::alive(RigidBodyId id) const {
  return id.index >= 0 && id.index < int(impl_->bodies.size()) && impl_->bodies[id.index].rb &&
         impl_->bodies[id.index].generation == id.generation;
}

void BulletWorld::remove_body(RigidBodyId id) {
  assert(alive(id));
  // Its joints go with it (a constraint must leave Bullet before its bodies).
  for (std::size_t k = 0; k < impl_->joints.size(); ++k) {
    const auto& j = impl_->joints[k];
    if (!j.c) continue;
    auto is = [&](RigidBodyId x) { return x.index == id.index && x.generation == id.generation; };
    if (is(j.def.a) || is(j.def.b)) impl_->drop_joint(int(k));
  }
  auto& b = impl_->bodies[id.index];
  impl_->world->removeRigidBody(b.rb);
  if (b.adopted) impl_->give_back(b);
  b.rb = nullptr;
  b.adopted = false;
  b.body.reset();
  b.motion.reset();
  b.shape.reset();
  b.mesh.reset();
  impl_->free_slots.push_back(id.index);
}

BodyState BulletWorld::state(RigidBodyId id) const {
  assert(alive(id));
  const btRigidBody& rb = *impl_->bodies[id.index].rb;
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
  impl_->bodies[id.index].rb->getAabb(a, b);
  *lo = impl_->origin + eig(a).cast<double>();
  *hi = impl_->origin + eig(b).cast<double>();
}

std::vector<RigidBodyId> BulletWorld::bodies() const {
  std::vector<RigidBodyId> out;
  for (int i = 0; i < int(impl_->bodies.size()); ++i)
    if (impl_->bodies[i].rb) out.push_back({i, impl_->bodies[i].generation});
  return out;
}

int BulletWorld::body_count() const { return int(impl_->bodies.size() - impl_->free_slots.size()); }

void BulletWorld::step(float dt) { step_frame(dt, 1); }

const char* to_string(RigidMotion m) {
  switch (m) {
    case RigidMotion::Dynamic: return "dynamic";
    case RigidMotion::Kinematic: return "kinematic";
    case RigidMotion::Static: return "static";
  }
  return "?";
}

void BulletWorld::step_frame(float dt, int substeps) {
  assert(dt > 0.0f && substeps >= 1);
  const float sub = dt / float(substeps);
  auto& m = *impl_;
  for (auto& b : m.bodies) b.terrain_impulse.setZero();
  for (auto& j : m.joints) j.turn_impulse = j.slide_impulse = 0;
  // One Bullet step of `sub` (maxSubSteps = 0: exactly once, no internal accumulator), the
  // kinematic bodies' motion states first moved to where they are at its end (substep k of n).
  auto one = [&](int k) {
    for (auto& b : m.bodies) {
      if (!b.rb || !b.has_target) continue;
      const float u = float(k + 1) / float(substeps);
      btTransform tr;
      tr.setOrigin(b.from.getOrigin().lerp(b.to.getOrigin(), u));
      tr.setRotation(k + 1 == substeps ? b.to.getRotation() : b.from.getRotation().slerp(b.to.getRotation(), u));
      if (k + 1 == substeps) tr.setOrigin(b.to.getOrigin());
      b.rb->getMotionState()->setWorldTransform(tr);
    }
    m.ensure_edges(sub);
    m.steer_wheels(sub);
    m.world->stepSimulation(sub, 0, sub);
    m.gather_terrain_impulses();
    m.gather_joint_impulses(sub);
  };
  auto finish = [&]() {
    for (auto& b : m.bodies) b.has_target = false;
    for (auto& j : m.joints) {
      j.torque = float(j.turn_impulse / dt);
      j.force = float(j.slide_impulse / dt);
    }
    m.last_frame_dt = dt;
  };
  if (substeps == 1) {
    one(0);
    finish();
    return;
  }
  // The force and torque each body holds now (N, N m; apply_force's, or the game's on an
  // adopted body). Bullet adds gravity inside stepSimulation, so these are the applied ones
  // only; it clears them after each stepSimulation, and they are given again before every
  // substep after the first.
  struct Held {
    btRigidBody* rb;
    btVector3 force, torque;
  };
  std::vector<Held> held;
  for (const auto& b : impl_->bodies) {
    if (!b.rb) continue;
    const btVector3& f = b.rb->getTotalForce();
    const btVector3& t = b.rb->getTotalTorque();
    if (!f.isZero() || !t.isZero()) held.push_back({b.rb, f, t});
  }
  // getTotalForce() is after the body's linear factor (applyCentralForce adds force *
  // m_linearFactor; applyTorque torque * m_angularFactor): divide it out so that applying
  // again gives the same total. Exact for a factor of 1 (every body add_body creates); for an
  // adopted body with another factor, to float round-off; a component whose factor is 0
  // holds no force, and gets none.
  auto unfactor = [](const btVector3& v, const btVector3& factor) {
    btVector3 r(0, 0, 0);
    for (int i = 0; i < 3; ++i)
      if (factor[i] != btScalar(0)) r[i] = v[i] / factor[i];
    return r;
  };
  for (auto& h : held) {
    h.force = unfactor(h.force, h.rb->getLinearFactor());
    h.torque = unfactor(h.torque, h.rb->getAngularFactor());
  }
  for (int k = 0; k < substeps; ++k) {
    if (k > 0)
      for (const auto& h : held) {
        h.rb->applyCentralForce(h.force);
        h.rb->applyTorque(h.torque);
      }
    one(k);
  }
  finish();
}

void BulletWorld::terrain_changed() {
  terrain_changed(GridRegion{0, 0, impl_->terrain->samples_x(), impl_->terrain->samples_z()});
}

void BulletWorld::terrain_changed(const GridRegion& changed) {
  auto& m = *impl_;
  for (auto& t : m.tiles) {
    if (intersect(changed, m.terrain->tile_region(t.tx, t.tz)).empty()) continue;
    const float lo = m.terrain->tile_min_height(t.tx, t.tz), hi = m.terrain->tile_max_height(t.tx, t.tz);
    if (lo < t.min_h || hi > t.max_h) {
      m.world->removeCollisionObject(t.object.get());
      m.build_tile(t, /*keep_edges=*/true);
      m.world->addCollisionObject(t.object.get(), Impl::kGroupTerrain, Impl::kGroupBody);
    }
    // (renewed before a body comes near, or by renew_edges: about 1 ms for a car's track
    // patch, the costliest part of its demotion's write; docs/BENCHMARKS.md "Internal edges
    // renewed after the write")
    if (!t.edges) continue;
    const GridRegion c = intersect(changed, m.terrain->tile_region(t.tx, t.tz));
    if (!c.empty()) t.stale.push_back(c);
  }
}

int BulletWorld::stale_edge_samples() const {
  int n = 0;
  for (const auto& t : impl_->tiles)
    for (const GridRegion& r : t.stale) n += r.ni * r.nj;
  return n;
}

int BulletWorld::renew_edges(int max_cells) {
  auto& m = *impl_;
  for (auto& t : m.tiles) {
    while (!t.stale.empty()) {
      GridRegion& r = t.stale.front();
      if (max_cells <= 0) {
        const GridRegion whole = r;
        t.stale.erase(t.stale.begin());
        m.refresh_edges(t, whole);  // (a whole tile's renewal clears the rest: build_edges)
        continue;
      }
      // A strip across the region's longer side: whole columns (or rows) of it.
      GridRegion strip = r;
      if (r.ni >= r.nj) {
        strip.ni = std::clamp(max_cells / std::max(1, r.nj), 1, r.ni);
        r.i0 += strip.ni, r.ni -= strip.ni;
      } else {
        strip.nj = std::clamp(max_cells / std::max(1, r.ni), 1, r.nj);
        r.j0 += strip.nj, r.nj -= strip.nj;
      }
      if (r.empty()) t.stale.erase(t.stale.begin());
      m.refresh_edges(t, strip);
      return stale_edge_samples();
    }
  }
  return 0;
}

int BulletWorld::terrain_tile_count() const { return int(impl_->tiles.size()); }

std::vector<BulletWorld::EdgeInfo> BulletWorld::tile_edge_info(int tile) const {
  std::vector<EdgeInfo> out;
  if (tile < 0 || tile >= int(impl_->tiles.size()) || !impl_->tiles[std::size_t(tile)].edges) return out;
  const btTriangleInfoMap& m = *impl_->tiles[std::size_t(tile)].edges;
  out.reserve(std::size_t(m.size()));
  for (int k = 0; k < m.size(); ++k) {
    const btTriangleInfo& t = *m.getAtIndex(k);
    out.push_back({m.getKeyAtIndex(k).getUid1(), t.m_flags, {t.m_edgeV0V1Angle, t.m_edgeV1V2Angle, t.m_edgeV2V0Angle}});
  }
  std::sort(out.begin(), out.end(), [](const EdgeInfo& a, const EdgeInfo& b) { return a.key < b.key; });
  return out;
}

BulletWorld::Stats BulletWorld::stats() const {
  const auto& m = *impl_;
  Stats s;
  s.tiles = int(m.tiles.size());
  s.edge_maps = 0;
  for (const auto& t : m.tiles) s.edge_maps += t.edges != nullptr;
  s.edge_maps_built = m.edge_maps_built;
  s.edge_maps_refreshed = m.edge_maps_refreshed;
  s.stale_edge_samples = stale_edge_samples();
  // btCollisionWorld::updateAabbs visits an object when forceUpdateAllAabbs is on or the object is active.
  s.aabb_updates_per_step = 0;
  const btCollisionObjectArray& objects = m.world->getCollisionObjectArray();
  for (int k = 0; k < objects.size(); ++k)
    s.aabb_updates_per_step += m.world->getForceUpdateAllAabbs() || objects[k]->isActive();
  s.dynamic_proxies = m.broadphase->m_sets[0].m_leaves;
  s.fixed_proxies = m.broadphase->m_sets[1].m_leaves;
  s.pairs = m.broadphase->getOverlappingPairCache()->getNumOverlappingPairs();
  return s;
}

void BulletWorld::apply_force(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3f& torque) {
  assert(alive(id));
  btRigidBody& rb = *impl_->bodies[id.index].rb;
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
  impl_->world->removeRigidBody(b.rb);
  impl_->world->addRigidBody(b.rb, Impl::kGroupBody,
                             enabled ? (Impl::kGroupBody | Impl::kGroupTerrain) : Impl::kGroupBody);
  b.rb->activate(true);
}

bool BulletWorld::terrain_collision(RigidBodyId id) const {
  assert(alive(id));
  return impl_->bodies[id.index].terrain;
}

float BulletWorld::mass(RigidBodyId id) const {
  assert(alive(id));
  const float inv = impl_->bodies[id.index].rb->getInvMass();
  return inv > 0 ? 1.0f / inv : 0.0f;
}

Eigen::Vector3f BulletWorld::principal_inertia(RigidBodyId id) const {
  assert(alive(id));
  const btVector3 inv = impl_->bodies[id.index].rb->getInvInertiaDiagLocal();
  return {inv.x() > 0 ? 1.0f / inv.x() : 0.0f, inv.y() > 0 ? 1.0f / inv.y() : 0.0f,
          inv.z() > 0 ? 1.0f / inv.z() : 0.0f};
}

const RigidBodyDef& BulletWorld::definition(RigidBodyId id) const {
  assert(alive(id));
  return impl_->bodies[id.index].def;
}

void BulletWorld::set_state(RigidBodyId id, const BodyState& s) {
  assert(alive(id));
  auto& body = impl_->bodies[id.index];
  btRigidBody& rb = *body.rb;
  btTransform tr;
  const Eigen::Vector3d local = s.position - impl_->origin;
  tr.setOrigin(btVector3(float(local.x()), float(local.y()), float(local.z())));
  const Eigen::Quaternionf q = s.orientation.normalized();
  tr.setRotation(btQuaternion(q.x(), q.y(), q.z(), q.w()));
  rb.setWorldTransform(tr);
  if (rb.getMotionState()) rb.getMotionState()->setWorldTransform(tr);
  if (body.def.motion != RigidMotion::Dynamic) {
    // A teleport: no velocity from the jump (Bullet derives a kinematic body's velocity from
    // its interpolation transform to its motion state's), and any target given before is void.
    rb.setInterpolationWorldTransform(tr);
    body.has_target = false;
  }
  rb.setLinearVelocity(bt(s.linear_velocity));
  rb.setAngularVelocity(bt(s.angular_velocity));
  rb.activate(true);
}

RigidMotion BulletWorld::motion(RigidBodyId id) const {
  assert(alive(id));
  return impl_->bodies[id.index].def.motion;
}

void BulletWorld::set_kinematic_target(RigidBodyId id, const Eigen::Vector3d& position,
                                       const Eigen::Quaternionf& orientation, float dt) {
  assert(alive(id) && dt > 0);
  auto& b = impl_->bodies[id.index];
  if (b.def.motion != RigidMotion::Kinematic) return;
  btTransform to;
  const Eigen::Vector3d local = position - impl_->origin;
  to.setOrigin(btVector3(float(local.x()), float(local.y()), float(local.z())));
  const Eigen::Quaternionf q = orientation.normalized();
  to.setRotation(btQuaternion(q.x(), q.y(), q.z(), q.w()));
  b.from = b.rb->getWorldTransform();
  b.to = to;
  b.has_target = true;
  btVector3 v, w;
  btTransformUtil::calculateVelocity(b.from, b.to, dt, v, w);
  b.rb->setLinearVelocity(v);
  b.rb->setAngularVelocity(w);
}

Eigen::Vector3f BulletWorld::terrain_force(RigidBodyId id) const {
  assert(alive(id));
  const float t = impl_->last_frame_dt;
  return t > 0 ? Eigen::Vector3f(eig(impl_->bodies[id.index].terrain_impulse) / t) : Eigen::Vector3f::Zero();
}

}  // namespace sandpatch
