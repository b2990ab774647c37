// Bullet wrapper: see bullet_world.hpp.
#include "manager/bullet_world.hpp"

#include <BulletCollision/CollisionDispatch/btInternalEdgeUtility.h>
#include <BulletCollision/CollisionShapes/btHeightfieldTerrainShape.h>
#include <BulletCollision/CollisionShapes/btTriangleInfoMap.h>
#include <LinearMath/btConvexHullComputer.h>
#include <LinearMath/btTransformUtil.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "heightfield/heightfield.hpp"
#include "scene/mesh.hpp"

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
    // Internal-edge info (see adjust_internal_edges), built on demand (ensure_edges): null
    // until a body first comes near the tile. Building it for every tile up front cost
    // ~4 µs and ~60 bytes per sample: 849 s and most of 4.6 GB for an 8192² terrain.
    std::unique_ptr<btTriangleInfoMap> edges;
    std::unique_ptr<btCollisionObject> object;
  };
  std::vector<Tile> tiles;
  int edge_maps_built = 0;  // tiles whose internal-edge info was built, over the world's life

  // Collision groups: terrain tiles vs bodies, so a body can stop colliding with the terrain.
  static constexpr int kGroupBody = 1, kGroupTerrain = 2;

  struct Body {
    int generation = 0;
    RigidBodyDef def;
    bool terrain = true;  // collides with the heightfield
    // Kinematic: the pose at the start of the next frame and its end (Bullet-local), set by
    // set_kinematic_target and used up by step_frame.
    bool has_target = false;
    btTransform from, to;
    btVector3 terrain_impulse{0, 0, 0};  // N s, world: the heightfield's contacts in the frame so far
    std::unique_ptr<btCollisionShape> shape;
    std::unique_ptr<btTriangleMesh> mesh;  // mesh bodies keep their triangles alive
    std::unique_ptr<btDefaultMotionState> motion;
    std::unique_ptr<btRigidBody> body;     // null for an adopted body
    btRigidBody* rb = nullptr;             // the body Bullet steps: body.get(), or the game's
    // Adopted bodies (adopt_body): what release() gives back to the game.
    bool adopted = false;
    btVector3 game_gravity{0, 0, 0};       // m/s², the body's own gravity before it joined
  };
  std::vector<Body> bodies;
  std::vector<int> free_slots;
  float last_frame_dt = 0;  // s, the last step_frame's dt

  struct Joint {
    int generation = 0;
    RigidJointDef def;
    std::unique_ptr<btGeneric6DofSpring2Constraint> c;  // null: a free slot
    std::unique_ptr<btJointFeedback> fb;
    double turn_impulse = 0, slide_impulse = 0;  // N m s, N s: on body b about / along the axis, this frame so far
    float torque = 0, force = 0;                 // N m, N: the last frame's means
    // Wheel joints: the frame in body a at zero steering, the steering now, its target and speed.
    btTransform frame_a0;
    float steer = 0, steer_target = 0, steer_speed = 0;  // rad, rad, rad/s
  };
  std::vector<Joint> joints;
  std::vector<int> free_joints;

  // The moving body of a joint (Bullet's body B): b, or a when a is jointed to the world.
  btRigidBody* moving(const Joint& j) { return &j.c->getRigidBodyB(); }

  // After a Bullet step of `sub` seconds: each joint's push on its moving body about and along
  // its axis. btJointFeedback holds the constraint's whole force and torque on B over the
  // step (every row); the linear rows' force acts at the anchor, so their torque about B's
  // centre of mass, r × F, is taken out, and what is left about the axis is the motor's, the
  // spring's and the limit's (the locked rows are perpendicular to the axis).
  void gather_joint_impulses(float sub) {
    for (Joint& j : joints) {
      if (!j.c) continue;
      j.c->calculateTransforms();
      const btMatrix3x3& basis = j.c->getCalculatedTransformA().getBasis();
      const btVector3 axis = basis.getColumn(0);
      const btVector3 slide = j.def.kind == JointKind::Wheel ? basis.getColumn(1) : axis;
      const btVector3 r = j.c->getCalculatedTransformB().getOrigin() - moving(j)->getCenterOfMassPosition();
      const btVector3 t = j.fb->m_appliedTorqueBodyB - r.cross(j.fb->m_appliedForceBodyB);
      j.turn_impulse += double(t.dot(axis)) * sub;
      j.slide_impulse += double(j.fb->m_appliedForceBodyB.dot(slide)) * sub;
    }
  }

  // Before a Bullet substep of `sub` seconds: each steered wheel's axle a step towards its target.
  void steer_wheels(float sub) {
    for (Joint& j : joints) {
      if (!j.c || j.def.kind != JointKind::Wheel || j.steer == j.steer_target) continue;
      const float most = j.steer_speed * sub;
      j.steer += std::clamp(j.steer_target - j.steer, -most, most);
      btTransform fa = j.frame_a0;
      fa.setBasis(fa.getBasis() * btMatrix3x3(btQuaternion(btVector3(0, 1, 0), j.steer)));  // about the frame's y: `up`
      j.c->setFrames(fa, j.c->getFrameOffsetB());
      j.c->getRigidBodyA().activate(true);
      j.c->getRigidBodyB().activate(true);
    }
  }

  void drop_joint(int index) {
    Joint& j = joints[std::size_t(index)];
    world->removeConstraint(j.c.get());
    // A dynamic body with no joint left may sleep again (add_joint kept it awake).
    for (btRigidBody* rb : {&j.c->getRigidBodyA(), &j.c->getRigidBodyB()}) {
      if (rb->isStaticOrKinematicObject()) continue;
      bool jointed = false;
      for (const Joint& o : joints)
        jointed = jointed || (o.c && &o != &j && (&o.c->getRigidBodyA() == rb || &o.c->getRigidBodyB() == rb));
      if (!jointed) rb->forceActivationState(ACTIVE_TAG);
      rb->activate(true);
    }
    j.c.reset();
    j.fb.reset();
    free_joints.push_back(index);
  }

  // A body into a free slot (generation bumped) or a new one.
  RigidBodyId insert(Body&& b) {
    int index;
    if (!free_slots.empty()) {
      index = free_slots.back();
      free_slots.pop_back();
      b.generation = bodies[index].generation + 1;
      bodies[index] = std::move(b);
    } else {
      index = int(bodies.size());
      bodies.push_back(std::move(b));
    }
    return RigidBodyId{index, bodies[index].generation};
  }

  // Moves a body's transforms by `d` (m): world transform, interpolation and motion state.
  static void shift(btRigidBody& rb, const btVector3& d) {
    btTransform tr = rb.getWorldTransform();
    tr.setOrigin(tr.getOrigin() + d);
    rb.setWorldTransform(tr);
    btTransform it = rb.getInterpolationWorldTransform();
    it.setOrigin(it.getOrigin() + d);
    rb.setInterpolationWorldTransform(it);
    if (rb.getMotionState()) rb.getMotionState()->setWorldTransform(tr);
  }

  // An adopted body, already out of the world, back in the game's frame with its own gravity.
  void give_back(Body& b) {
    shift(*b.rb, btVector3(float(origin.x()), float(origin.y()), float(origin.z())));
    b.rb->setGravity(b.game_gravity);
  }

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
    t.edges.reset();  // rebuilt on demand for the new shape (ensure_edges)
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
      t.object->setCollisionFlags(t.object->getCollisionFlags() | btCollisionObject::CF_STATIC_OBJECT |
                                  btCollisionObject::CF_CUSTOM_MATERIAL_CALLBACK);
    }
    // Static and never active (what Bullet does to a static btRigidBody): with
    // setForceUpdateAllAabbs(false) Bullet then never recomputes the tile's bounds, and the
    // broadphase moves it to its fixed set, so a step costs nothing per idle tile.
    t.object->forceActivationState(ISLAND_SLEEPING);
    t.object->setCollisionShape(t.shape.get());
    btTransform tr;
    tr.setIdentity();
    tr.setOrigin(centre);
    t.object->setWorldTransform(tr);
  }

  // Adds the impulses (N s) the last Bullet step's contacts between a body and a terrain
  // tile applied to the body: Bullet's normal m_normalWorldOnB points from B to A, A gets
  // +n·j and B −n·j; the friction impulses along their own directions the same way.
  void gather_terrain_impulses() {
    const int nm = dispatcher->getNumManifolds();
    for (int k = 0; k < nm; ++k) {
      const btPersistentManifold* pm = dispatcher->getManifoldByIndexInternal(k);
      const btCollisionObject* a = pm->getBody0();
      const btCollisionObject* b = pm->getBody1();
      const bool a_terrain = a->getCollisionShape()->getShapeType() == TERRAIN_SHAPE_PROXYTYPE;
      const bool b_terrain = b->getCollisionShape()->getShapeType() == TERRAIN_SHAPE_PROXYTYPE;
      if (a_terrain == b_terrain) continue;
      const btCollisionObject* body = a_terrain ? b : a;
      const float sign = a_terrain ? -1.0f : 1.0f;  // the body is B: it gets −n·j
      Body* owner = nullptr;
      for (Body& x : bodies)
        if (x.rb == body) owner = &x;
      if (!owner) continue;
      btVector3 j(0, 0, 0);
      for (int c = 0; c < pm->getNumContacts(); ++c) {
        const btManifoldPoint& pt = pm->getContactPoint(c);
        j += pt.m_normalWorldOnB * pt.m_appliedImpulse + pt.m_lateralFrictionDir1 * pt.m_appliedImpulseLateral1 +
             pt.m_lateralFrictionDir2 * pt.m_appliedImpulseLateral2;
      }
      owner->terrain_impulse += sign * j;
    }
  }

  static constexpr std::size_t kEagerEdgeTiles = 64;  // at most about 1 s at start-up
  void build_edges(Tile& t) {
    t.edges = std::make_unique<btTriangleInfoMap>();
    btGenerateInternalEdgeInfo(t.shape.get(), t.edges.get());  // also hands the map to the shape
    ++edge_maps_built;
  }

  // Before a step: every tile a body may touch during it has its internal-edge info. The
  // body's bounds (m, local) grown by twice its travel in one step and kEdgeReach, mapped to
  // tile indices; O(bodies), whatever the terrain's size.
  void ensure_edges(float dt) {
    static constexpr float kEdgeReach = 1.0f;  // m, beyond Bullet's contact thresholds (cm)
    const Heightfield& hf = *terrain;
    const float sp = hf.spacing();
    const int cells = hf.tile_cells();
    for (const Body& b : bodies) {
      if (!b.rb || !b.terrain) continue;
      btVector3 lo, hi;
      b.rb->getCollisionShape()->getAabb(b.rb->getWorldTransform(), lo, hi);
      const float grow = kEdgeReach + 2.0f * dt * b.rb->getLinearVelocity().length();
      if (!std::isfinite(grow)) continue;  // a broken body: run.cpp reports it after the step
      // Tile t holds samples [t·cells, (t+1)·cells] (neighbours share the edge sample; the
      // last tile takes the rest): the samples under [a − grow, c + grow] (m, local).
      auto tile_range = [&](float a, float c, int samples, int count, int* t0, int* t1) {
        const float i0 = std::floor((a - grow) / sp), i1 = std::ceil((c + grow) / sp);
        if (i1 < 0 || i0 > float(samples - 1)) return false;  // off the terrain
        *t0 = std::min(std::max(0, int(i0)) / cells, count - 1);
        *t1 = std::min(std::min(samples - 1, int(i1)) / cells, count - 1);
        return true;
      };
      int tx0, tx1, tz0, tz1;
      if (!tile_range(lo.x(), hi.x(), hf.samples_x(), hf.tiles_x(), &tx0, &tx1) ||
          !tile_range(lo.z(), hi.z(), hf.samples_z(), hf.tiles_z(), &tz0, &tz1))
        continue;
      for (int tz = tz0; tz <= tz1; ++tz)
        for (int tx = tx0; tx <= tx1; ++tx) {
          Tile& t = tiles[std::size_t(tz) * hf.tiles_x() + tx];
          if (!t.edges) build_edges(t);
        }
    }
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

BulletWorld::Stats BulletWorld::stats() const {
  const auto& m = *impl_;
  Stats s;
  s.tiles = int(m.tiles.size());
  s.edge_maps = 0;
  for (const auto& t : m.tiles) s.edge_maps += t.edges != nullptr;
  s.edge_maps_built = m.edge_maps_built;
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

// ---- joints ----

const char* to_string(JointKind k) {
  switch (k) {
    case JointKind::Fixed: return "fixed";
    case JointKind::Hinge: return "hinge";
    case JointKind::Slider: return "slider";
    case JointKind::Cylindrical: return "cylindrical";
    case JointKind::Wheel: return "wheel";
  }
  return "?";
}

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kMaxJointForce = 1e9;   // N or N m: the largest motor force (as the loads' limit)
constexpr double kMaxSpring = 1e12;      // N/m or N m/rad, N s/m or N m s/rad
constexpr double kMaxJointSpeed = 1e4;   // rad/s or m/s: targets of velocity motors, servo speeds

std::string num(double v) { return format_number(v); }

bool turns(JointKind k) { return k == JointKind::Hinge || k == JointKind::Cylindrical || k == JointKind::Wheel; }
bool slides(JointKind k) { return k == JointKind::Slider || k == JointKind::Cylindrical || k == JointKind::Wheel; }

// A frame whose x is `axis` (unit), y and z any perpendicular pair.
btMatrix3x3 basis_along(const btVector3& axis) {
  btVector3 y, z;
  btPlaneSpace1(axis, y, z);
  return btMatrix3x3(axis.x(), y.x(), z.x(), axis.y(), y.y(), z.y(), axis.z(), y.z(), z.z());
}

}  // namespace

std::vector<Error> BulletWorld::check_motor(const JointMotor& m, bool turn, const std::string& field) {
  std::vector<Error> es;
  const char* unit = turn ? "rad" : "m";
  if (m.mode != MotorMode::Off && m.mode != MotorMode::Velocity && m.mode != MotorMode::Position)
    es.push_back({"", field + ".mode", std::to_string(int(m.mode)), "must be off, velocity or position"});
  if (m.mode == MotorMode::Velocity && (!std::isfinite(m.target) || std::abs(m.target) > kMaxJointSpeed))
    es.push_back({"", field + ".target", num(m.target),
                  "must be finite, |target| <= " + num(kMaxJointSpeed) + (turn ? " (rad/s)" : " (m/s)")});
  if (m.mode == MotorMode::Position) {
    const double lim = turn ? kPi : 1e4;
    if (!std::isfinite(m.target) || std::abs(m.target) > lim)
      es.push_back({"", field + ".target", num(m.target),
                    std::string("must be finite and in [-") + num(lim) + ", " + num(lim) + "] " + unit +
                        (turn ? " (a hinge's angle is measured in [-pi, pi])" : "")});
    if (!std::isfinite(m.servo_speed) || !(m.servo_speed > 0) || m.servo_speed > kMaxJointSpeed)
      es.push_back({"", field + ".servo_speed", num(m.servo_speed),
                    "must be in (0, " + num(kMaxJointSpeed) + "]" + (turn ? " rad/s" : " m/s")});
  }
  if (m.mode != MotorMode::Off && (!std::isfinite(m.max_force) || m.max_force < 0 || m.max_force > kMaxJointForce))
    es.push_back({"", field + ".max_force", num(m.max_force),
                  "must be in [0, " + num(kMaxJointForce) + "]" + (turn ? " N m (a torque)" : " N")});
  return es;
}

std::vector<Error> BulletWorld::check_joint(const RigidJointDef& d) const {
  std::vector<Error> es;
  auto who = [&](RigidBodyId id) {
    if (!alive(id)) return "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}";
    const std::string& n = definition(id).name;
    return n.empty() ? "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}" : "'" + n + "'";
  };
  if (!alive(d.a)) es.push_back({"", "body_a", who(d.a), "must be a live body (removed, or never added)"});
  if (d.b.valid() && !alive(d.b)) es.push_back({"", "body_b", who(d.b), "must be a live body, or none (the world)"});
  if (!es.empty()) return es;
  if (d.b.valid() && d.a.index == d.b.index && d.a.generation == d.b.generation)
    es.push_back({"", "body_b", who(d.b), "must not be body_a: a joint connects two bodies (or body_a and the world: no body_b)"});
  else if (motion(d.a) != RigidMotion::Dynamic && (!d.b.valid() || motion(d.b) != RigidMotion::Dynamic))
    es.push_back({"", d.b.valid() ? "body_b" : "body_a",
                  d.b.valid() ? who(d.a) + " (" + to_string(motion(d.a)) + ") and " + who(d.b) + " (" + to_string(motion(d.b)) + ")"
                              : who(d.a) + " (" + to_string(motion(d.a)) + ") and the world",
                  "at least one side of a joint must be a dynamic body: nothing a joint does moves a kinematic or static body"});
  if (!d.anchor.allFinite() || d.anchor.cwiseAbs().maxCoeff() > 1e7)
    es.push_back({"", "anchor", "[" + num(d.anchor.x()) + ", " + num(d.anchor.y()) + ", " + num(d.anchor.z()) + "]",
                  "must be finite, each coordinate within 1e7 (m, world)"});
  const std::string axis = "[" + num(d.axis.x()) + ", " + num(d.axis.y()) + ", " + num(d.axis.z()) + "]";
  if (!d.axis.allFinite() || !(d.axis.cast<double>().norm() > 1e-6))
    es.push_back({"", "axis", axis, "must be a finite, non-zero direction (world)"});
  if (d.kind != JointKind::Fixed && d.kind != JointKind::Hinge && d.kind != JointKind::Slider &&
      d.kind != JointKind::Cylindrical && d.kind != JointKind::Wheel)
    es.push_back({"", "type", std::to_string(int(d.kind)), "must be fixed, hinge or slider"});
  if (d.kind == JointKind::Wheel) {
    const Eigen::Vector3d u = d.up.cast<double>(), x = d.axis.cast<double>();
    if (!d.up.allFinite() || !(u.norm() > 1e-6) || (x.norm() > 1e-6 && std::abs(u.normalized().dot(x.normalized())) > 0.99))
      es.push_back({"", "up", "[" + num(d.up.x()) + ", " + num(d.up.y()) + ", " + num(d.up.z()) + "]",
                    "must be a finite direction across the axis (world)"});
    if (!std::isfinite(d.max_steer) || d.max_steer < 0 || d.max_steer > 1.2f)
      es.push_back({"", "max_steer", num(d.max_steer), "must be in [0, 1.2] rad"});
  }
  const bool two = d.kind == JointKind::Cylindrical || d.kind == JointKind::Wheel;
  auto dof = [&](const JointDof& f, bool turn) {
    const std::string pre = two ? (turn ? "turn." : "slide.") : "";
    const char* unit = turn ? "rad" : "m";
    if (f.limited) {
      const double lim = turn ? kPi : 1e4;
      if (!std::isfinite(f.lower) || !std::isfinite(f.upper) || std::abs(f.lower) > lim || std::abs(f.upper) > lim)
        es.push_back({"", pre + "limits", "[" + num(f.lower) + ", " + num(f.upper) + "]",
                      "must be finite, within [-" + num(lim) + ", " + num(lim) + "] " + unit});
      else if (f.lower > f.upper)
        es.push_back({"", pre + "limits", "[" + num(f.lower) + ", " + num(f.upper) + "]",
                      std::string("the lower limit must not be above the upper (") + unit + ")"});
    }
    for (Error& e : check_motor(f.motor, turn, pre + "motor")) es.push_back(std::move(e));
    if (!std::isfinite(f.stiffness) || f.stiffness < 0 || f.stiffness > kMaxSpring)
      es.push_back({"", pre + "spring.stiffness", num(f.stiffness),
                    "must be in [0, " + num(kMaxSpring) + "]" + (turn ? " N m/rad" : " N/m")});
    if (!std::isfinite(f.damping) || f.damping < 0 || f.damping > kMaxSpring)
      es.push_back({"", pre + "spring.damping", num(f.damping),
                    "must be in [0, " + num(kMaxSpring) + "]" + (turn ? " N m s/rad" : " N s/m")});
  };
  if (turns(d.kind)) dof(d.turn, true);
  if (slides(d.kind)) dof(d.slide, false);
  return es;
}

namespace {

// One degree of freedom of a Spring2 constraint (index 0 = sliding along x, 3 = turning about
// x). Bullet's velocity motors drive A relative to B (its rows' velocity is v_A − v_B: a
// target of +5 rad/s turned B at −5 rad/s about +x, +0.5 m/s moved B at −0.5 m/s), so every
// target velocity is negated. Its angle about x (Euler, RO_XYZ) is of the opposite sense to
// B's right-handed turn relative to A, so angles, servo targets and angular limits are
// negated (kTurnSign); its travel along x is B's relative to A, as the joint's.
constexpr float kTurnSign = -1.0f;
constexpr int kJointIterations = 40;
constexpr float kJointErp = 0.8f;

void apply_motor(btGeneric6DofSpring2Constraint& c, int index, const JointMotor& m) {
  c.enableMotor(index, m.mode != MotorMode::Off);
  c.setServo(index, m.mode == MotorMode::Position);
  c.setMaxMotorForce(index, m.max_force);
  if (m.mode == MotorMode::Velocity) c.setTargetVelocity(index, -m.target);
  if (m.mode == MotorMode::Position) {
    c.setServoTarget(index, (index >= 3 ? kTurnSign : 1.0f) * m.target);
    c.setTargetVelocity(index, m.servo_speed);
  }
}

void apply_dof(btGeneric6DofSpring2Constraint& c, int index, const JointDof& f) {
  apply_motor(c, index, f.motor);
  const bool spring = f.stiffness > 0 || f.damping > 0;
  c.enableSpring(index, spring);
  if (spring) {
    // Bullet softens a spring too stiff to be sampled by the step (its period under 4 steps):
    // the price of not blowing up.
    c.setStiffness(index, f.stiffness, true);
    c.setDamping(index, f.damping, true);
    c.setEquilibriumPoint(index, 0);
  }
}

}  // namespace

Result<JointId> BulletWorld::add_joint(const RigidJointDef& def) {
  if (auto es = check_joint(def); !es.empty()) return es;
  auto& m = *impl_;
  Impl::Joint j;
  j.def = def;
  j.def.axis.normalize();
  // The joint's frame in the world (Bullet-local), then in each body.
  const Eigen::Vector3d local = def.anchor - m.origin;
  btTransform frame(basis_along(bt(j.def.axis)), btVector3(float(local.x()), float(local.y()), float(local.z())));
  if (def.kind == JointKind::Wheel) {
    // x the axle, y the suspension's (and the steering's) axis `up` made square to it.
    const btVector3 x = bt(j.def.axis);
    btVector3 y = bt(def.up) - x * x.dot(bt(def.up));
    y.normalize();
    const btVector3 z = x.cross(y);
    frame.setBasis(btMatrix3x3(x.x(), y.x(), z.x(), x.y(), y.y(), z.y(), x.z(), y.z(), z.z()));
  }
  btRigidBody& a = *m.bodies[def.a.index].rb;
  if (def.b.valid()) {
    btRigidBody& b = *m.bodies[def.b.index].rb;
    j.c = std::make_unique<btGeneric6DofSpring2Constraint>(a, b, a.getCenterOfMassTransform().inverse() * frame,
                                                           b.getCenterOfMassTransform().inverse() * frame, RO_XYZ);
  } else {
    // Bullet's one-body form: the body is its B, the world its (fixed) A.
    j.c = std::make_unique<btGeneric6DofSpring2Constraint>(a, a.getCenterOfMassTransform().inverse() * frame, RO_XYZ);
  }
  btGeneric6DofSpring2Constraint& c = *j.c;
  // Locked: lower = upper = 0; free: lower > upper; limited: [lower, upper].
  c.setLinearLowerLimit(btVector3(0, 0, 0));
  c.setLinearUpperLimit(btVector3(0, 0, 0));
  c.setAngularLowerLimit(btVector3(0, 0, 0));
  c.setAngularUpperLimit(btVector3(0, 0, 0));
  j.frame_a0 = c.getFrameOffsetA();
  auto open = [&](int index, const JointDof& f) {
    if (!f.limited) c.setLimit(index, 1.0f, -1.0f);
    else if (index >= 3) c.setLimit(index, kTurnSign * f.upper, kTurnSign * f.lower);  // kTurnSign = -1
    else c.setLimit(index, f.lower, f.upper);
    apply_dof(c, index, f);
  };
  if (slides(def.kind)) open(def.kind == JointKind::Wheel ? 1 : 0, j.def.slide);  // a wheel slides along y: `up`
  if (turns(def.kind)) open(3, j.def.turn);
  // More solver iterations for joints than Bullet's 10 for contacts: a chain of bodies of very
  // different masses and inertias (a 1 kg bob 1 m from its pivot, a 1500 kg chassis on 30 kg
  // wheels) converges slowly, and the joint opens (5 mm at the pendulum's turning points
  // with 10).
  c.setOverrideNumSolverIterations(kJointIterations);
  for (int axis = 0; axis < 6; ++axis) c.setParam(BT_CONSTRAINT_STOP_ERP, kJointErp, axis);
  j.fb = std::make_unique<btJointFeedback>();
  c.setJointFeedback(j.fb.get());
  m.world->addConstraint(&c, /*disableCollisionsBetweenLinkedBodies=*/true);
  // A jointed body never sleeps in Bullet: a machine at rest must still answer its motors, and
  // a slow pendulum (under Bullet's 0.8 m/s sleeping threshold) must not stop at the top of
  // its swing.
  for (btRigidBody* rb : {&c.getRigidBodyA(), &c.getRigidBodyB()})
    if (!rb->isStaticOrKinematicObject()) rb->forceActivationState(DISABLE_DEACTIVATION);
  int index;
  if (!m.free_joints.empty()) {
    index = m.free_joints.back();
    m.free_joints.pop_back();
    j.generation = m.joints[std::size_t(index)].generation + 1;
    m.joints[std::size_t(index)] = std::move(j);
  } else {
    index = int(m.joints.size());
    m.joints.push_back(std::move(j));
  }
  return JointId{index, m.joints[std::size_t(index)].generation};
}

bool BulletWorld::joint_alive(JointId id) const {
  return id.index >= 0 && id.index < int(impl_->joints.size()) && impl_->joints[std::size_t(id.index)].c &&
         impl_->joints[std::size_t(id.index)].generation == id.generation;
}

void BulletWorld::remove_joint(JointId id) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  j.c->getRigidBodyA().activate(true);
  j.c->getRigidBodyB().activate(true);
  impl_->drop_joint(id.index);
}

void BulletWorld::set_joint_motor(JointId id, bool turn, const JointMotor& motor) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  (turn ? j.def.turn : j.def.slide).motor = motor;
  apply_motor(*j.c, turn ? 3 : (j.def.kind == JointKind::Wheel ? 1 : 0), motor);
  j.c->getRigidBodyA().activate(true);
  j.c->getRigidBodyB().activate(true);
}

void BulletWorld::set_joint_steering(JointId id, float angle, float speed) {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  if (j.def.kind != JointKind::Wheel) return;
  j.steer_target = std::clamp(angle, -j.def.max_steer, j.def.max_steer);
  j.steer_speed = speed;
}

float BulletWorld::joint_steering(JointId id) const {
  assert(joint_alive(id));
  return impl_->joints[std::size_t(id.index)].steer;
}

const RigidJointDef& BulletWorld::joint_definition(JointId id) const {
  assert(joint_alive(id));
  return impl_->joints[std::size_t(id.index)].def;
}

JointState BulletWorld::joint_state(JointId id) const {
  assert(joint_alive(id));
  auto& j = impl_->joints[std::size_t(id.index)];
  btGeneric6DofSpring2Constraint& c = *j.c;
  c.calculateTransforms();
  const btVector3 axis = c.getCalculatedTransformA().getBasis().getColumn(0);
  const btRigidBody& a = c.getRigidBodyA();
  const btRigidBody& b = c.getRigidBodyB();
  // Velocities of the anchor as a point of each body.
  const btVector3 pa = c.getCalculatedTransformA().getOrigin(), pb = c.getCalculatedTransformB().getOrigin();
  const btVector3 va = a.getLinearVelocity() + a.getAngularVelocity().cross(pa - a.getCenterOfMassPosition());
  const btVector3 vb = b.getLinearVelocity() + b.getAngularVelocity().cross(pb - b.getCenterOfMassPosition());
  JointState s;
  s.angle = kTurnSign * c.getAngle(0);
  s.angular_rate = (b.getAngularVelocity() - a.getAngularVelocity()).dot(axis);
  const bool wheel = j.def.kind == JointKind::Wheel;
  s.position = c.getRelativePivotPosition(wheel ? 1 : 0);
  s.rate = (vb - va).dot(wheel ? c.getCalculatedTransformA().getBasis().getColumn(1) : axis);
  s.torque = j.torque;
  s.force = j.force;
  if (!turns(j.def.kind)) s.angle = s.angular_rate = s.torque = 0;
  if (!slides(j.def.kind)) s.position = s.rate = s.force = 0;
  return s;
}

std::vector<std::int32_t> BulletWorld::joint_groups() const {
  // union-find over the slots, each root the lowest slot of its set
  const int n = int(impl_->bodies.size());
  std::vector<int> parent(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i) parent[std::size_t(i)] = i;
  auto root = [&](int i) {
    while (parent[std::size_t(i)] != i) i = parent[std::size_t(i)] = parent[std::size_t(parent[std::size_t(i)])];
    return i;
  };
  std::vector<char> jointed(std::size_t(n), 0);
  for (const auto& j : impl_->joints) {
    if (!j.c || !j.def.b.valid()) continue;
    const int a = root(j.def.a.index), b = root(j.def.b.index);
    jointed[std::size_t(j.def.a.index)] = jointed[std::size_t(j.def.b.index)] = 1;
    if (a != b) parent[std::size_t(std::max(a, b))] = std::min(a, b);
  }
  std::vector<std::int32_t> g(std::size_t(n), 0);
  for (int i = 0; i < n; ++i)
    if (jointed[std::size_t(i)]) g[std::size_t(i)] = std::int32_t(root(i) + 1);
  return g;
}

std::vector<JointId> BulletWorld::joints() const {
  std::vector<JointId> out;
  for (int i = 0; i < int(impl_->joints.size()); ++i)
    if (impl_->joints[std::size_t(i)].c) out.push_back({i, impl_->joints[std::size_t(i)].generation});
  return out;
}

}  // namespace sandpatch
