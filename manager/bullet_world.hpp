// The one place Sandpatch wraps Bullet (Bullet's global
// state and its hidden time accumulator). Bodies outside active patches collide with the
// heightfield through one btHeightfieldTerrainShape per heightfield tile, reading Sandpatch's
// own tile arrays (no copy). Tiles are static, asleep collision objects and Bullet updates
// only active objects' bounds, so an idle tile costs a step nothing; a tile's internal-edge
// info (btTriangleInfoMap) is built the first time a body comes within ~1 m of it, so set-up
// is O(tiles), not O(samples). step(dt) advances exactly dt: stepSimulation(dt, 0) makes Bullet
// take one step of dt with no accumulator and no interpolation.
//
// Precision boundary: Bullet runs in float, relative to the terrain's
// world origin; world positions given to and returned from this class are double.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "common/knobs.hpp"
#include "heightfield/heightfield.hpp"

class btRigidBody;

namespace sandpatch {

class Heightfield;

enum class RigidShapeKind { Sphere, Box, Cylinder, Capsule, Mesh };

struct RigidShape {
  RigidShapeKind kind = RigidShapeKind::Sphere;
  float radius = 0.5f;                                   // m (sphere, cylinder, capsule)
  float height = 1.0f;                                   // m, full length along local y (cylinder, capsule: of the straight part)
  Eigen::Vector3f half_extents = Eigen::Vector3f::Constant(0.5f);  // m (box)
  std::vector<Eigen::Vector3f> vertices;                 // m, body frame (mesh)
  std::vector<std::array<int, 3>> triangles;             // indices into vertices (mesh, closed)
};

// How a body moves: by the forces on it (dynamic), along a pose prescribed every frame
// (kinematic: it pushes what it meets and nothing pushes it back), or not at all (static).
enum class RigidMotion { Dynamic, Kinematic, Static };
const char* to_string(RigidMotion m);  // "dynamic", "kinematic", "static"

struct RigidBodyDef {
  std::string name;
  RigidShape shape;
  RigidMotion motion = RigidMotion::Dynamic;
  float mass = 1.0f;                                     // kg (> 0; dynamic only, ignored otherwise)
  Eigen::Vector3d position = Eigen::Vector3d::Zero();    // m, world
  Eigen::Quaternionf orientation = Eigen::Quaternionf::Identity();
  Eigen::Vector3f linear_velocity = Eigen::Vector3f::Zero();   // m/s
  Eigen::Vector3f angular_velocity = Eigen::Vector3f::Zero();  // rad/s
  float friction = float(knobs::kBodyFriction.def);      // Coulomb μ against the heightfield
  float restitution = float(knobs::kBodyRestitution.def);  // against the heightfield
  float rolling_friction = float(knobs::kBodyRollingFriction.def);  // rolling resistance (dimensionless torque arm / radius);
                                                         // soil resists rolling, and it damps the sideways kicks
                                                         // Bullet gives a body landing on triangle edges
};

struct BodyState {
  Eigen::Vector3d position;          // m, world
  Eigen::Quaternionf orientation;
  Eigen::Vector3f linear_velocity;   // m/s
  Eigen::Vector3f angular_velocity;  // rad/s
};

// Handle of a body in a BulletWorld: index + generation (stale handles are detected).
struct RigidBodyId {
  int index = -1;
  int generation = 0;
  bool valid() const { return index >= 0; }
};

// ---- joints (Bullet constraints between two bodies, or a body and the world) ----
//
// Every joint is one btGeneric6DofSpring2Constraint whose frame is built at creation from a
// world anchor point and a world axis at the bodies' poses then: the frame's x is the axis,
// and it is fixed in each body from then on. A joint's position (angle about the axis, rad,
// or travel along it, m) is 0 at creation and is that of body b relative to body a (with no
// body b, of body a relative to the world), right-handed about the axis.
enum class JointKind {
  Fixed,        // no relative motion
  Hinge,        // turns about the axis (rad)
  Slider,       // slides along the axis (m), no turning
  Cylindrical,  // turns about and slides along the axis
  Wheel,        // a vehicle's wheel on its chassis: turns about the axis (the axle), slides along
                // `up` (the suspension), and the axle is steered about `up` (set_joint_steering)
};
const char* to_string(JointKind k);  // "fixed", "hinge", "slider", "cylindrical", "wheel"

enum class MotorMode {
  Off,       // no motor
  Velocity,  // drive the rate (rad/s, m/s) towards `target`
  Position,  // a servo: move towards the position `target` (rad, m) at up to servo_speed, and hold it
};
struct JointMotor {
  MotorMode mode = MotorMode::Off;
  float target = 0;          // rad/s or m/s (velocity); rad or m (position)
  float max_force = 0;       // N m (turning) or N (sliding): the most the motor applies, >= 0
  float servo_speed = 1.0f;  // rad/s or m/s (position), > 0
};
// One free degree of freedom of a joint: turning about the axis or sliding along it.
struct JointDof {
  bool limited = false;
  float lower = 0, upper = 0;  // rad or m, lower <= upper (hinges: within [-pi, pi])
  JointMotor motor;
  float stiffness = 0;         // N m/rad or N/m: a spring towards position 0 (0 = none)
  float damping = 0;           // N m s/rad or N s/m
};
struct RigidJointDef {
  std::string name;
  JointKind kind = JointKind::Hinge;
  RigidBodyId a, b;            // b invalid: a is jointed to the world
  Eigen::Vector3d anchor = Eigen::Vector3d::Zero();  // m, world, at creation
  Eigen::Vector3f axis = Eigen::Vector3f::UnitZ();   // world, at creation (normalised here)
  JointDof turn;               // hinge, cylindrical, wheel
  JointDof slide;              // slider, cylindrical; wheel: along `up`
  Eigen::Vector3f up = Eigen::Vector3f::UnitY();  // wheel: the suspension's and the steering's axis (world, across `axis`)
  float max_steer = 0;         // wheel: rad, the steering's limit (0: not steered), [0, 1.2]
};
struct JointId {
  int index = -1;
  int generation = 0;
  bool valid() const { return index >= 0; }
};
// A joint after the last step (positions now; rates now; forces mean over the last step).
struct JointState {
  float angle = 0;             // rad, in [-pi, pi] (hinge, cylindrical)
  float angular_rate = 0;      // rad/s, of b relative to a about the axis
  float torque = 0;            // N m: motor + spring + limit on b about the axis, mean over the last step
  float position = 0;          // m (slider, cylindrical)
  float rate = 0;              // m/s along the axis
  float force = 0;             // N: motor + spring + limit on b along the axis, mean over the last step
};

class BulletWorld {
 public:
  // `terrain` must outlive the world: its tile arrays are read in place by Bullet.
  static Result<std::unique_ptr<BulletWorld>> create(const Heightfield& terrain, const Eigen::Vector3f& gravity);
  ~BulletWorld();
  BulletWorld(const BulletWorld&) = delete;
  BulletWorld& operator=(const BulletWorld&) = delete;

  Result<RigidBodyId> add_body(const RigidBodyDef& def);
  // Adopts a dynamic btRigidBody the caller owns (with its shape and motion state), in place:
  // this world steps that very object. It must not be in another Bullet world. Its transform
  // moves into this world's frame (world − terrain origin) while adopted; gravity becomes this
  // world's; inertia, damping, CCD, flags and user pointers stay the game's. Shapes: sphere,
  // box, y-axis cylinder and capsule, convex hull (the shell's RigidShape comes from them).
  // Errors name btRigidBody, btRigidBody.mass or btRigidBody.shape.
  Result<RigidBodyId> adopt_body(btRigidBody* body, const std::string& name);
  bool adopted(RigidBodyId id) const;
  // The Bullet this library was built with: sizeof(btScalar), BT_BULLET_VERSION,
  // sizeof(btRigidBody) (a caller handing over its own btRigidBody must match them).
  static void bullet_abi(int* scalar_bytes, int* version, std::size_t* rigid_body_bytes);
  // Owned bodies are destroyed; adopted ones are given back: out of this world, transform back
  // in world coordinates, the game's gravity restored; the object is not touched otherwise.
  // The destructor gives back every adopted body the same way.
  void remove_body(RigidBodyId id);
  bool alive(RigidBodyId id) const;
  BodyState state(RigidBodyId id) const;
  // Axis-aligned bounds of the body's collision shape (m, world).
  void bounds(RigidBodyId id, Eigen::Vector3d* lo, Eigen::Vector3d* hi) const;
  int body_count() const;
  // Handles of the live bodies, in slot order (deterministic).
  std::vector<RigidBodyId> bodies() const;

  // Advances every body by exactly dt seconds (one Bullet step, no accumulator).
  void step(float dt);
  // One frame of dt seconds in `substeps` equal Bullet steps of dt / substeps. Forces and
  // torques given by apply_force (or to an adopted btRigidBody directly) before the call act
  // over every substep, i.e. over the whole frame: Bullet's stepSimulation clears applied
  // forces after each call, so a loop of step(dt / substeps) would give a body only
  // 1 / substeps of the impulse. step_frame(dt, 1) is step(dt).
  void step_frame(float dt, int substeps);

  // After the heightfield was edited: re-reads the heights of the tiles that hold a changed
  // sample and updates their vertical bounds where the heights left them. Their internal-edge
  // info around the change (not the whole tile's) is renewed later: before a body comes within
  // reach of it (the step's ensure_edges: a body never touches a triangle whose info is stale),
  // or by renew_edges. No argument: every sample.
  void terrain_changed();
  void terrain_changed(const GridRegion& changed);  // samples
  // Renews stale internal-edge info (terrain_changed): the first stale region's next strip of
  // whole sample columns or rows (across its longer side) of about `max_cells` cells, at least
  // one; max_cells <= 0: every stale region. Returns the samples still stale.
  int renew_edges(int max_cells);
  int stale_edge_samples() const;  // changed samples whose internal-edge info waits (Stats)

  int terrain_tile_count() const;

  // A tile's internal-edge info as Bullet holds it (tests and diagnostics): one entry per
  // triangle that has one, sorted by key; empty while the tile has none.
  struct EdgeInfo {
    int key = 0;           // Bullet's (part, triangle) hash
    int flags = 0;         // TRI_INFO_* bits
    float angles[3] = {};  // rad, edges v0v1, v1v2, v2v0
  };
  std::vector<EdgeInfo> tile_edge_info(int tile) const;

  // What a step costs Bullet, as counts (tests and `bench lod`): none of them grows with the
  // terrain's size while nothing touches the terrain.
  struct Stats {
    int tiles = 0;                  // heightfield tiles (one btHeightfieldTerrainShape each)
    int aabb_updates_per_step = 0;  // objects whose bounds Bullet recomputes each step (active ones)
    int dynamic_proxies = 0;        // proxies in the broadphase's dynamic tree (moved in the last few steps)
    int fixed_proxies = 0;          // proxies in its fixed tree (not moved lately: idle tiles, sleeping bodies)
    int pairs = 0;                  // overlapping pairs in the broadphase
    int edge_maps = 0;              // tiles with internal-edge info now (built when a body first comes near)
    int edge_maps_built = 0;        // internal-edge infos built over the world's life (rebuilds included)
    int edge_maps_refreshed = 0;    // partial renewals after terrain_changed (around the change only)
    int stale_edge_samples = 0;     // changed samples whose internal-edge info waits to be renewed
  };
  Stats stats() const;

  // ---- coupling with granular patches ----
  // Adds a force (N, world, through the centre of mass) and a torque (N m, world) for the next
  // step() only, or for every substep of the next step_frame().
  void apply_force(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3f& torque);
  // Whether the body collides with the heightfield (off while granules carry it).
  void set_terrain_collision(RigidBodyId id, bool enabled);
  bool terrain_collision(RigidBodyId id) const;
  float mass(RigidBodyId id) const;                   // kg
  Eigen::Vector3f principal_inertia(RigidBodyId id) const;  // kg m², body frame (Bullet's shape axes)
  const RigidBodyDef& definition(RigidBodyId id) const;
  // Overwrites the body's state (after a patch integrated it). Wakes the body. A kinematic
  // body is teleported (its velocities are the prescribed ones until the next target).
  void set_state(RigidBodyId id, const BodyState& state);

  // ---- kinematic and static bodies ----
  RigidMotion motion(RigidBodyId id) const;
  // The pose (m, world) a kinematic body reaches at the end of the next step_frame(dt, n):
  // its velocities become (target − now) / dt and the angle of the rotation between the two
  // over dt, at once (contact prediction and the patches read them in the same frame), and
  // each of the n substeps moves it along the straight line and the slerp between the two
  // poses, so Bullet's contacts see it move (Bullet derives a kinematic body's velocity from
  // its motion state's change over the substep). Without a target a kinematic body holds still.
  void set_kinematic_target(RigidBodyId id, const Eigen::Vector3d& position, const Eigen::Quaternionf& orientation,
                            float dt);

  // ---- contact with the heightfield ----
  // Mean force (N, world) the heightfield's contacts applied to the body over the last step()
  // or step_frame(): the normal and friction impulses of Bullet's contact points between the
  // body and the terrain tiles, summed and divided by the step's duration. Zero off the
  // heightfield (and always for kinematic and static bodies, which Bullet does not collide
  // with the static terrain).
  Eigen::Vector3f terrain_force(RigidBodyId id) const;

  // ---- joints ----
  // Checks a joint's definition against this world's bodies: errors name the field relative to
  // the joint ("body_b", "axis", "limits", "motor.max_force", "spring.stiffness", ...); the
  // callers put the joint's own path in front.
  std::vector<Error> check_joint(const RigidJointDef& def) const;
  // Adds a joint (check_joint first). Bullet stops colliding the two bodies with each other.
  Result<JointId> add_joint(const RigidJointDef& def);
  void remove_joint(JointId id);
  bool joint_alive(JointId id) const;
  // A new motor for the joint's turning (turn = true) or sliding degree of freedom, from the
  // next step on; wakes both bodies. Checked by the caller (check_motor).
  void set_joint_motor(JointId id, bool turn, const JointMotor& motor);
  static std::vector<Error> check_motor(const JointMotor& m, bool turn, const std::string& field);
  // A wheel joint's steering: its axle turns about `up` towards `angle` (rad, within
  // ±max_steer) at up to `speed` (rad/s), a step of the joint's frame in body a at every
  // Bullet substep (kinematic: no torque limit).
  void set_joint_steering(JointId id, float angle, float speed);
  float joint_steering(JointId id) const;  // rad, now
  JointState joint_state(JointId id) const;
  const RigidJointDef& joint_definition(JointId id) const;
  // Live joints in slot order.
  std::vector<JointId> joints() const;
  // The joint groups, by body slot (RigidBodyId::index): bodies connected by joints, directly
  // or through other bodies, share one group (1 + the lowest slot among them); a body with no
  // joint to another body has 0 (joints to the world do not group). Bullet does not collide
  // jointed bodies; the terrain manager hands these groups to the DEM so their shells do not
  // touch either.
  std::vector<std::int32_t> joint_groups() const;

 private:
  BulletWorld() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandpatch
