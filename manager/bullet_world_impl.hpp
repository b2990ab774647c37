// BulletWorld's state, shared by its source files (bullet_world.cpp: bodies, terrain, the step;
// bullet_joints.cpp: joints). Private to manager/.
#pragma once

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
#include "manager/bullet_world.hpp"
#include "scene/mesh.hpp"

namespace sandpatch {

inline btVector3 bt(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }
inline Eigen::Vector3f eig(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

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
    // Regions of changed samples (whole terrain) whose internal-edge info is renewed later
    // (terrain_changed): before a body comes near one (ensure_edges) or by renew_edges.
    std::vector<GridRegion> stale;
    std::unique_ptr<btCollisionObject> object;
  };
  std::vector<Tile> tiles;
  int edge_maps_built = 0;  // tiles whose internal-edge info was built, over the world's life
  int edge_maps_refreshed = 0;  // partial renewals of a tile's internal-edge info (refresh_edges)

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

  // `keep_edges`: the tile's internal-edge info outlives the shape (the grid and its triangle
  // indices do not change, only the vertical range); refresh_edges then renews what moved.
  void build_tile(Tile& t, bool keep_edges = false) {
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
    if (keep_edges && t.edges) t.shape->setTriangleInfoMap(t.edges.get());
    else t.edges.reset();  // rebuilt on demand for the new shape (ensure_edges)
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
    t.stale.clear();
    t.edges = std::make_unique<btTriangleInfoMap>();
    t.shape->setTriangleInfoMap(nullptr);  // btGenerateInternalEdgeInfo skips a shape that has one
    btGenerateInternalEdgeInfo(t.shape.get(), t.edges.get());  // also hands the map to the shape
    ++edge_maps_built;
  }

  // The key of a triangle's entry in a btTriangleInfoMap: Bullet's internal-edge utility
  // hashes (part, index) as part << (31 - MAX_NUM_PARTS_IN_BITS) | index, and a heightfield
  // names the two triangles of cell (x, z) part 2x and 2x + 1, index z.
  static int edge_key(int part, int index) { return (part << (31 - MAX_NUM_PARTS_IN_BITS)) | index; }

  // After the heights of `changed` (samples, whole terrain) were written: the internal-edge
  // info of the tile's triangles that touch a changed sample, or share an edge with one that
  // does, computed again on a sub-heightfield of those cells and one more cell around (so
  // every renewed triangle sees all its neighbours) and copied into the tile's map. Its cost
  // follows the changed area, not the tile's (a whole 128 × 128-cell map is about 15 ms;
  // rebuilt at every demotion that left the tile's height range, it was the longest frame of
  // a car driving across patches).
  void refresh_edges(Tile& t, const GridRegion& changed) {
    const Heightfield& hf = *terrain;
    const GridRegion tr = hf.tile_region(t.tx, t.tz);
    const GridRegion c = intersect(changed, tr);
    if (c.empty() || !t.edges) return;
    const int w = tr.ni, l = tr.nj;
    // Cells (named by their lowest sample) to renew, in tile samples.
    const int x0 = std::max(0, c.i0 - tr.i0 - 2), x1 = std::min(w - 2, c.i0 - tr.i0 + c.ni);
    const int z0 = std::max(0, c.j0 - tr.j0 - 2), z1 = std::min(l - 2, c.j0 - tr.j0 + c.nj);
    // The sub-heightfield's samples: those cells and one cell more on each side.
    const int s0 = std::max(0, x0 - 1), s1 = std::min(w - 1, x1 + 2);
    const int r0 = std::max(0, z0 - 1), r1 = std::min(l - 1, z1 + 2);
    if (s0 == 0 && r0 == 0 && s1 == w - 1 && r1 == l - 1) {
      build_edges(t);  // the whole tile
      return;
    }
    const int sw = s1 - s0 + 1, sl = r1 - r0 + 1;
    const float* data = hf.tile_data(t.tx, t.tz);
    std::vector<float> h(std::size_t(sw) * sl);
    for (int j = 0; j < sl; ++j)
      for (int i = 0; i < sw; ++i) h[std::size_t(j) * sw + i] = data[std::size_t(r0 + j) * w + (s0 + i)];
    btHeightfieldTerrainShape sub(sw, sl, h.data(), 1.0f, t.min_h, t.max_h, 1, PHY_FLOAT, false);
    sub.setLocalScaling(t.shape->getLocalScaling());
    btTriangleInfoMap fresh;
    btGenerateInternalEdgeInfo(&sub, &fresh);
    for (int z = z0; z <= z1; ++z)
      for (int x = x0; x <= x1; ++x)
        for (int k = 0; k < 2; ++k) {
          const int key = edge_key(2 * x + k, z);
          if (const btTriangleInfo* info = fresh.find(edge_key(2 * (x - s0) + k, z - r0))) t.edges->insert(key, *info);
          else t.edges->remove(key);
        }
    ++edge_maps_refreshed;
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
      if (!std::isfinite(grow + lo.x() + lo.z() + hi.x() + hi.z())) continue;  // a broken body: run.cpp reports it after the step
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
      // (the samples under the same window, for the stale regions it reaches)
      const int si0 = int(std::floor((lo.x() - grow) / sp)), si1 = int(std::ceil((hi.x() + grow) / sp));
      const int sj0 = int(std::floor((lo.z() - grow) / sp)), sj1 = int(std::ceil((hi.z() + grow) / sp));
      const GridRegion window{si0, sj0, si1 - si0 + 1, sj1 - sj0 + 1};
      for (int tz = tz0; tz <= tz1; ++tz)
        for (int tx = tx0; tx <= tx1; ++tx) {
          Tile& t = tiles[std::size_t(tz) * hf.tiles_x() + tx];
          if (!t.edges) {
            build_edges(t);
            continue;
          }
          // (the part of a stale region within the window now; the rest, up to four
          // rectangles around it, stays stale)
          for (std::size_t k = 0; k < t.stale.size();) {
            const GridRegion r = t.stale[k], c = intersect(r, window);
            if (c.empty()) {
              ++k;
              continue;
            }
            t.stale.erase(t.stale.begin() + std::ptrdiff_t(k));
            const GridRegion rest[4] = {{r.i0, r.j0, r.ni, c.j0 - r.j0},
                                        {r.i0, c.j0 + c.nj, r.ni, r.j0 + r.nj - (c.j0 + c.nj)},
                                        {r.i0, c.j0, c.i0 - r.i0, c.nj},
                                        {c.i0 + c.ni, c.j0, r.i0 + r.ni - (c.i0 + c.ni), c.nj}};
            for (const GridRegion& q : rest)
              if (!q.empty()) t.stale.push_back(q);
            refresh_edges(t, c);  // (a whole tile's renewal clears the rest: build_edges)
          }
        }
    }
  }
};

}  // namespace sandpatch
