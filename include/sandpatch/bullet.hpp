// Optional: hand over a Bullet body the game already owns (docs/api.md "Bullet bodies").
//
// In place (adopt): Sandpatch's Bullet world steps the game's own btRigidBody object; the game
// keeps owning it (and its shape and motion state) and reads it as usual:
//
//   game_world->removeRigidBody(rb);                                 // not in two worlds
//   auto h = sandpatch::api::bullet::adopt(terrain, *rb, "barrel");  // Sandpatch steps *rb now
//   ... each frame: terrain.step(dt); draw from rb->getWorldTransform() or its motion state
//   terrain.remove_body(*h);                                         // *rb is the game's again
//   game_world->addRigidBody(rb);
//
// Lifetime: the body, its collision shape and its motion state must outlive the adoption (until
// remove_body, or the Terrain's destruction, which gives every adopted body back the same way).
// While adopted, the body's gravity is the terrain's and its transform is relative to
// Terrain::origin() (world − origin; the same as world with the default origin 0, 0, 0);
// giving it back restores the game's gravity and world coordinates and changes nothing else.
// Shapes: sphere, box, y-axis cylinder and capsule, convex hull; static and kinematic bodies
// (copy those with body_def, which maps them to BodyMotion) and other shapes are refused
// naming btRigidBody.shape / btRigidBody.mass. The game must use the same
// Bullet as libsandpatch (Debian's libbullet-dev, float): adopt() checks sizeof(btScalar),
// BT_BULLET_VERSION and sizeof(btRigidBody) and refuses a mismatch (btRigidBody.abi).
//
// By copy (body_def / pull / push), for a game that keeps stepping its own world:
//
//   auto def = sandpatch::api::bullet::body_def(*rb, "barrel");   // shape, mass, pose, velocity
//   auto h = terrain.add_body(*def);                                // Sandpatch simulates a copy
//   ... each frame: terrain.step(dt); sandpatch::api::bullet::pull(terrain, *h, *rb);
//
// pull() writes Sandpatch's pose and velocities into the game's body, so the game keeps
// drawing it and querying it as before; the game must not also step it in its own world (make
// it kinematic there, or remove it, while Sandpatch has it). push() goes the other way, for a
// game that moved the body itself (a teleport, a thrown object).
//
// Header-only: these functions compile in the game's code, which includes and links Bullet
// itself; libsandpatch's interface has no Bullet type. Positions are world coordinates
// (Sandpatch's world frame is the game's world frame); Bullet's are float.
#pragma once

#include <LinearMath/btConvexHullComputer.h>
#include <btBulletDynamicsCommon.h>

#include <sandpatch/sandpatch.hpp>
#include <string>

namespace sandpatch::api::bullet {

// The BodyDef of a Bullet body: sphere, box, cylinder (y axis), capsule (y axis) or convex
// hull (as a mesh: its triangles are computed by Bullet's btConvexHullComputer; like every
// mesh it is re-centred on its centroid, so give hulls centred on the body's origin); mass from the
// inverse mass (inverse mass 0: BodyMotion::Kinematic for a CF_KINEMATIC_OBJECT body, else
// BodyMotion::Static), pose, velocities, friction, restitution, rolling friction. Other
// shapes are refused with an error naming the shape. (adopt() takes dynamic bodies only.)
inline Result<BodyDef> body_def(const btRigidBody& rb, const std::string& name = "") {
  BodyDef d;
  d.name = name;
  const btCollisionShape* shape = rb.getCollisionShape();
  if (!shape) return Error{"", "btRigidBody.shape", "null", "the body needs a collision shape", ""};
  const btVector3 scale = shape->getLocalScaling();
  switch (shape->getShapeType()) {
    case SPHERE_SHAPE_PROXYTYPE:
      d.shape.kind = ShapeKind::Sphere;
      d.shape.radius = static_cast<const btSphereShape*>(shape)->getRadius();
      break;
    case BOX_SHAPE_PROXYTYPE: {
      const btVector3 h = static_cast<const btBoxShape*>(shape)->getHalfExtentsWithMargin();
      d.shape.kind = ShapeKind::Box;
      d.shape.half_extents = {h.x(), h.y(), h.z()};
      break;
    }
    case CYLINDER_SHAPE_PROXYTYPE: {
      const auto* c = static_cast<const btCylinderShape*>(shape);
      if (c->getUpAxis() != 1)
        return Error{"", "btRigidBody.shape", "cylinder on axis " + std::to_string(c->getUpAxis()),
                     "cylinders must have their axis on y (btCylinderShape, not btCylinderShapeX/Z)", ""};
      const btVector3 h = c->getHalfExtentsWithMargin();
      d.shape.kind = ShapeKind::Cylinder;
      d.shape.radius = h.x();
      d.shape.height = 2.0 * h.y();
      break;
    }
    case CAPSULE_SHAPE_PROXYTYPE: {
      const auto* c = static_cast<const btCapsuleShape*>(shape);
      if (c->getUpAxis() != 1)
        return Error{"", "btRigidBody.shape", "capsule on axis " + std::to_string(c->getUpAxis()),
                     "capsules must have their axis on y (btCapsuleShape, not btCapsuleShapeX/Z)", ""};
      d.shape.kind = ShapeKind::Capsule;
      d.shape.radius = c->getRadius();
      d.shape.height = 2.0 * c->getHalfHeight();
      break;
    }
    case CONVEX_HULL_SHAPE_PROXYTYPE: {
      const auto* hull = static_cast<const btConvexHullShape*>(shape);
      btConvexHullComputer ch;
      const btVector3* pts = hull->getUnscaledPoints();
      if (ch.compute(&pts[0].getX(), sizeof(btVector3), hull->getNumPoints(), 0, 0) < 0 || ch.faces.size() < 4)
        return Error{"", "btRigidBody.shape", "convex hull of " + std::to_string(hull->getNumPoints()) + " points",
                     "the hull must enclose a volume", ""};
      d.shape.kind = ShapeKind::Mesh;
      for (int k = 0; k < ch.vertices.size(); ++k) {
        const btVector3 v = ch.vertices[k] * scale;
        d.shape.vertices.insert(d.shape.vertices.end(), {float(v.x()), float(v.y()), float(v.z())});
      }
      // Each face is a convex polygon: a fan of triangles from its first vertex.
      for (int f = 0; f < ch.faces.size(); ++f) {
        const btConvexHullComputer::Edge* first = &ch.edges[ch.faces[f]];
        const int v0 = first->getSourceVertex();
        const btConvexHullComputer::Edge* e = first->getNextEdgeOfFace();
        for (const btConvexHullComputer::Edge* n = e->getNextEdgeOfFace(); n != first; e = n, n = n->getNextEdgeOfFace())
          d.shape.triangles.insert(d.shape.triangles.end(), {v0, e->getSourceVertex(), n->getSourceVertex()});
      }
      break;
    }
    default:
      return Error{"", "btRigidBody.shape", shape->getName(),
                   "must be a btSphereShape, btBoxShape, btCylinderShape, btCapsuleShape or btConvexHullShape", ""};
  }
  if (rb.getInvMass() > 0) {
    d.mass = 1.0 / rb.getInvMass();
  } else {
    // Inverse mass 0: a kinematic body (CF_KINEMATIC_OBJECT) or a static one.
    d.motion = rb.isKinematicObject() ? BodyMotion::Kinematic : BodyMotion::Static;
  }
  const btTransform& tr = rb.getWorldTransform();
  d.position = {tr.getOrigin().x(), tr.getOrigin().y(), tr.getOrigin().z()};
  const btQuaternion q = tr.getRotation();
  d.orientation = {float(q.w()), float(q.x()), float(q.y()), float(q.z())};
  const btVector3 v = rb.getLinearVelocity(), w = rb.getAngularVelocity();
  d.linear_velocity = {float(v.x()), float(v.y()), float(v.z())};
  d.angular_velocity = {float(w.x()), float(w.y()), float(w.z())};
  d.friction = rb.getFriction();
  d.restitution = rb.getRestitution();
  d.rolling_friction = rb.getRollingFriction();
  return d;
}

// Sandpatch's state of `h` → the game's body (world transform, motion state, velocities).
inline Status pull(const Terrain& terrain, BodyHandle h, btRigidBody& rb) {
  auto s = terrain.body_state(h);
  if (!s) return s.errors();
  btTransform tr;
  tr.setOrigin(btVector3(btScalar(s->position[0]), btScalar(s->position[1]), btScalar(s->position[2])));
  tr.setRotation(btQuaternion(s->orientation[1], s->orientation[2], s->orientation[3], s->orientation[0]));
  rb.setWorldTransform(tr);
  if (rb.getMotionState()) rb.getMotionState()->setWorldTransform(tr);
  rb.setLinearVelocity(btVector3(s->linear_velocity[0], s->linear_velocity[1], s->linear_velocity[2]));
  rb.setAngularVelocity(btVector3(s->angular_velocity[0], s->angular_velocity[1], s->angular_velocity[2]));
  return Ok{};
}

// The game's body → Sandpatch's state of `h` (after the game moved it itself).
inline Status push(Terrain& terrain, BodyHandle h, const btRigidBody& rb) {
  const btTransform& tr = rb.getWorldTransform();
  const btQuaternion q = tr.getRotation();
  Status s = terrain.set_body_transform(h, {tr.getOrigin().x(), tr.getOrigin().y(), tr.getOrigin().z()},
                                        {float(q.w()), float(q.x()), float(q.y()), float(q.z())});
  if (!s) return s;
  const btVector3 v = rb.getLinearVelocity(), w = rb.getAngularVelocity();
  return terrain.set_body_velocity(h, {float(v.x()), float(v.y()), float(v.z())}, {float(w.x()), float(w.y()), float(w.z())});
}

// Hands the game's body over in place (see the top of this file). The handle works with every
// Terrain body call; terrain.remove_body(handle) gives the body back.
inline Result<BodyHandle> adopt(Terrain& terrain, btRigidBody& rb, const std::string& name = "") {
  Terrain::BulletAbi abi;
  abi.scalar_bytes = int(sizeof(btScalar));
  abi.version = BT_BULLET_VERSION;
  abi.rigid_body_bytes = sizeof(btRigidBody);
  return terrain.adopt_bullet_body(&rb, name, abi);
}

}  // namespace sandpatch::api::bullet
