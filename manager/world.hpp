// The one owner of the frame. A World holds the heightfield, the Bullet world over it and,
// when granular patches are on, the terrain manager over both, and advances them together:
//
//   World::step(dt, substeps) runs, in order, each stage timed in the World's Profile:
//     spawn      bodies scheduled for this time enter the Bullet world; scene loads due now are
//                added to the callers' forces (apply_force, apply_torque)
//     lod        contact prediction, patch requests            (TerrainManager::before_bodies)
//     activation pool slots filled from the heightfield         (TerrainManager::before_bodies)
//     dem        coupled granule substeps, forces to the bodies (TerrainManager::before_bodies)
//     bodies     `substeps` Bullet steps of dt / substeps; the patches' forces and the callers'
//                act over all
//     sleep      sleep / wake bookkeeping                       (TerrainManager::after_bodies)
//     demotion   particles back to heightfield                  (TerrainManager::after_bodies)
//   After each stage that can move a body (dem, bodies, demotion) every body's state is
//   checked finite once; a non-finite one stops the step with an error naming the body and
//   the stage.
//
// Every caller steps the terrain through this class: the public API (api/sandpatch.cpp),
// `sandpatch run` (manager/run.cpp), the benches and the test rig. It also owns the one state
// hash and the one report schema all of them share.
//
// Time: the simulated time after n steps of the same dt is t0 + n·dt (computed, not summed,
// so it does not drift and equals frame·dt for a fixed-step run); a change of dt starts a new
// base t0.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <map>
#include <set>
#include <unordered_map>
#include <vector>

#include "common/error.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain_manager.hpp"

namespace sandpatch {

class World {
 public:
  // Takes the heightfield; makes the Bullet world over it. No patches until enable_patches.
  static Result<std::unique_ptr<World>> create(Heightfield terrain, const Eigen::Vector3f& gravity);
  ~World();
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  // Makes the terrain manager (granular patches) over the heightfield and the Bullet world.
  // At most once; bodies may be added before or after. Errors are the manager's.
  Status enable_patches(const TerrainManagerDef& def);

  // ---- bodies ----
  // Adds a body now.
  Result<RigidBodyId> add_body(const RigidBodyDef& def);
  // What add_body checks beyond Bullet's own rules: with patches, that the body's particle
  // shell fits a slot (TerrainManager::check_shell). schedule_body's caller checks it first.
  Status check_body(const RigidBodyDef& def) const;
  // Adopts a game's btRigidBody now (BulletWorld::adopt_body).
  Result<RigidBodyId> adopt_body(btRigidBody* body, const std::string& name);
  // A body that enters the world in the spawn stage of the first step that starts at or after
  // spawn_time (s) (bodies due in the same step enter in the order they were scheduled).
  // Returns its entry index (entry(index).id once spawned).
  std::size_t schedule_body(const RigidBodyDef& def, double spawn_time);
  // Every body added, adopted or scheduled, in that order (removed ones stay, marked): the
  // report's body list.
  struct Entry {
    std::string name;
    double spawn_time = 0;  // s (the time it was added, for add_body / adopt_body)
    RigidBodyId id;         // invalid until spawned
    bool removed = false;
    bool spawned() const { return id.valid(); }
  };
  const std::vector<Entry>& entries() const { return entries_; }
  // Removes a body. An owned body a patch may carry still has a shell in that patch's DEM,
  // which the manager lets go of only when it sees the body leave, so it is moved far above
  // the terrain, at rest, and leaves the Bullet world in the next step after the dem stage;
  // to callers it is gone at once (alive() is false). An adopted body, or any body without
  // patches, leaves at once (an adopted one is given back to the game).
  void remove_body(RigidBodyId id);
  // Removes a body no step has seen yet at once (a body refused right after it was added).
  void discard_body(RigidBodyId id);
  // Bodies scheduled and not spawned yet: (entry index, definition), in schedule order (a
  // renderer shows those due at the current time at their starting pose).
  const std::vector<std::pair<std::size_t, RigidBodyDef>>& pending() const { return pending_; }
  // Live and not being removed.
  bool alive(RigidBodyId id) const;
  // Live bodies (not being removed), in slot order.
  std::vector<RigidBodyId> bodies() const;

  // ---- driving bodies ----
  // Loads a caller puts on a body (N, N m, N s; world). Forces and torques accumulate until
  // the next step and act over the whole of it, over every Bullet substep, beside the forces
  // the patches hand Bullet in the dem stage; then they are cleared. An impulse changes the
  // velocities at once. Each is refused, naming the argument and its value, when it is not
  // finite, when its magnitude is above kMaxLoad, when a world point is more than kMaxArm from
  // the centre of mass, or when the body is not alive ("body").
  static constexpr double kMaxLoad = 1e9;  // N, N m or N s: the largest |force|, |torque|, |impulse|
  static constexpr double kMaxArm = 1e4;   // m: the farthest a world point may be from the centre of mass
  // At the centre of mass, or at `world_point` (m, world), which adds (p − c) × F.
  Status apply_force(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3d* world_point = nullptr);
  Status apply_torque(RigidBodyId id, const Eigen::Vector3f& torque);
  // Δv = J / m; at a world point also Δω = I⁻¹ ((p − c) × J) (I the world inertia tensor).
  Status apply_impulse(RigidBodyId id, const Eigen::Vector3f& impulse, const Eigen::Vector3d* world_point = nullptr);
  // A scene file's load on a body (docs/scene-format.md "loads"): validated by the scene
  // parser, applied by step() to every frame that starts at a time t with from <= t < until.
  struct Load {
    Eigen::Vector3f force = Eigen::Vector3f::Zero();   // N
    Eigen::Vector3f torque = Eigen::Vector3f::Zero();  // N m
    bool at_centre = true;                             // the force acts at the centre of mass ...
    Eigen::Vector3f at = Eigen::Vector3f::Zero();      // ... or at this point (m, body frame)
    double from = 0;                                   // s
    double until = std::numeric_limits<double>::infinity();  // s
    bool body_frame = false;  // force, torque and `at` in the body frame (they turn with it)
    // An impulse instead (N s): given once, by apply_impulse at the start of the first step
    // that starts at or after `from` (the body spawned), at `at` when given.
    bool is_impulse = false;
    Eigen::Vector3f impulse = Eigen::Vector3f::Zero();
    bool given = false;  // the impulse was given
  };
  // The loads of the body at entry `entry` (entries()), from its spawn on; replaces any before.
  void set_loads(std::size_t entry, std::vector<Load> loads);

  // ---- kinematic and static bodies (RigidBodyDef::motion) ----
  // A kinematic body moves along what is prescribed for each frame, in this order of
  // precedence: its keyframes (set_keyframes), a target pose for the end of the next step
  // (set_kinematic_target, used once), a velocity held until changed (set_kinematic_velocity);
  // with none it holds still. Each is refused, naming the argument, for a body that is not
  // alive or not kinematic ("body") and for non-finite values.
  struct Keyframe {
    double t = 0;                                                 // s, simulated time
    Eigen::Vector3d position = Eigen::Vector3d::Zero();           // m, world (centre of mass)
    Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();  // normalised here
  };
  // The pose at time t (s) of keyframes `keys` (non-empty, times increasing): linear in the
  // position and slerp in the orientation between the keyframes around t, the first before
  // them, the last after them.
  static Keyframe keyframe_at(const std::vector<Keyframe>& keys, double t);
  // Checks keyframes: at least one; t finite, >= 0 and strictly increasing; positions finite
  // and within 1e7 m; orientations finite with a norm > 0. Errors name `field`[k].t/.position/.orientation.
  static std::vector<Error> check_keyframes(const std::vector<Keyframe>& keys, const std::string& field);
  // The keyframes of the kinematic body at entry `entry` (entries()): it is placed at the
  // pose of the time it enters, then follows them (set_kinematic_target every frame).
  Status set_keyframes(std::size_t entry, std::vector<Keyframe> keys);
  // The pose (m, world) the body reaches at the end of the next step.
  Status set_kinematic_target(RigidBodyId id, const Eigen::Vector3d& position, const Eigen::Quaternionf& orientation);
  // m/s and rad/s (world), |v| <= 1000, |w| <= 1e4, held for every following step.
  Status set_kinematic_velocity(RigidBodyId id, const Eigen::Vector3f& linear, const Eigen::Vector3f& angular);

  // ---- joints (docs/api.md "Joints") ----
  // A joint between live bodies now (BulletWorld::add_joint: its errors name fields relative
  // to the joint).
  Result<JointId> add_joint(const RigidJointDef& def);
  // A joint between the bodies at entries a_entry and b_entry (b_entry = kWorld: a and the
  // world), made in the spawn stage of the first step at which both have spawned (its anchor
  // and axis are world ones at that moment). Returns its joint entry index. For scene files,
  // whose bodies spawn in that stage; the definition's a and b are filled then.
  static constexpr std::size_t kWorld = std::size_t(-1);
  std::size_t schedule_joint(const RigidJointDef& def, std::size_t a_entry, std::size_t b_entry);
  // Motor phases of the joint at entry `joint_entry`: in a frame starting at t with
  // from <= t < until the phase's motor drives the degree of freedom (turn or slide) it
  // names; outside every phase the definition's motor does. Applied by step() to Bullet only
  // when they change.
  struct MotorPhase {
    double from = 0;                                        // s
    double until = std::numeric_limits<double>::infinity();  // s
    bool turn = true;                                       // the turning (hinge) or sliding degree of freedom
    bool steer = false;                                     // a wheel joint's steering instead: motor.target (rad)
                                                            //   at motor.servo_speed (rad/s)
    JointMotor motor;
  };
  // `steer_default`: a wheel joint's steering outside every steering phase (target rad,
  // servo_speed rad/s), also set when the joint is made.
  void set_motor_phases(std::size_t joint_entry, std::vector<MotorPhase> phases, const JointMotor& steer_default = {});
  struct JointEntry {
    std::string name;
    JointId id;                 // invalid until made
    std::size_t a = 0, b = 0;   // body entries (scheduled joints; b = kWorld: the world)
    RigidJointDef def;          // as given (motors: the ones outside every phase)
    std::vector<MotorPhase> phases;
    JointMotor steer_default;   // a wheel joint's steering outside every phase (target rad, servo_speed rad/s)
    int applied[3] = {-2, -2, -2};  // phase applied to (turn, slide, steer): -1 the definition's, -2 none yet
    bool removed = false;
  };
  const std::vector<JointEntry>& joint_entries() const { return joints_; }
  void remove_joint(JointId id);
  bool joint_alive(JointId id) const;
  // A new motor from the next step on (BulletWorld::set_joint_motor), checked: errors name
  // `field`.motor_field.
  Status set_joint_motor(JointId id, bool turn, const JointMotor& motor);

  // ---- the soil's force ----
  struct SoilForce {
    Eigen::Vector3f force = Eigen::Vector3f::Zero();   // N, world: mean contact force of the granules over the last step
    Eigen::Vector3f torque = Eigen::Vector3f::Zero();  // N m, world, about the centre of mass
    bool carried = false;                              // a patch carried the body in the last step (else zeros)
  };
  // What the granular patch carrying the body did to it in the last step (zeros, not carried,
  // when none did, before the first step, or when the body is not alive).
  SoilForce soil_force(RigidBodyId id) const;

  // What the ground did to a body in the last step (docs/api.md "Reading the soil").
  struct Contact {
    SoilForce granular;                                        // the patch's granules on its shell
    Eigen::Vector3f heightfield_force = Eigen::Vector3f::Zero();  // N, world: Bullet's heightfield contacts, mean over the step
    // Sinkage (m): the original surface height under the centre of mass (the heightfield as it
    // was before any patch wrote it, bilinear at the centre's x, z) minus the body's lowest
    // point (world y). > 0: the body is that deep below where the surface was; < 0: its
    // clearance above it.
    double sinkage = 0;
    double lowest_y = 0;                                       // m, world: the lowest point of its shape
    double original_surface_y = 0;                             // m, world
  };
  Contact contact(RigidBodyId id) const;
  // The heightfield's height (m, world) at world (x, z) as it was before any demotion wrote
  // it (the tiles a patch may write are copied first), bilinear like Heightfield::sample.
  double original_height(double x, double z) const;
  // The lowest point (world y, m) of the body's shape at its current pose.
  double lowest_point(RigidBodyId id) const;
  // How far (m, >= 0) a shape at orientation q reaches below its centre of mass.
  static double extent_below(const RigidShape& shape, const Eigen::Quaternionf& q);
  // How far (m, >= 0) a shape at orientation q reaches from its centre of mass along the
  // unit world direction `dir` (its support function; extent_below is dir = -y).
  static double extent_along(const RigidShape& shape, const Eigen::Quaternionf& q, const Eigen::Vector3d& dir);

  // ---- the frame ----
  // Moves the camera the manager's scale bands are measured from (m, world).
  void set_camera(const Eigen::Vector3d& position);
  // One frame of dt seconds (dt > 0, substeps >= 1): the stages above. On an error the frame
  // is abandoned and failed_stage() names where.
  Status step(double dt, int substeps = 1);
  // Start-up before the first step (optional; e.g. while a level loads): bodies due now enter,
  // and the patches that bodies rest on or meet within the first frames are promoted whole
  // now (TerrainManager::prepare) instead of in the first frames. Its wall time is
  // prepare_ms(); it is not a frame. Once, before step(): later calls do nothing.
  Status prepare(double dt);
  double prepare_ms() const { return prepare_ms_; }
  // Every live patch back into heightfield now (the final terrain of a run, a save).
  Status demote_all();
  const char* failed_stage() const { return failed_stage_; }

  double time() const { return time_base_ + double(steps_at_dt_) * dt_; }  // s, simulated
  long long steps() const { return steps_; }

  // ---- per-frame measurements ----
  struct FrameRecord {
    double wall_ms = 0;    // the step, all stages (a caller's outputs are not in it)
    bool conversion = false;  // a part of a promotion or a demotion ran in it (TerrainManager::FrameWork)
    bool patch_awake = false;  // a patch was simulating (filling, or ready and not asleep)
    double budget_ms = 0;      // the frame budget (infinity: none)
    std::array<double, int(Stage::Count)> stage_ms{};  // wall, each stage's part of it
  };
  const FrameRecord& last_frame() const { return last_frame_; }
  // The longest frames of the run (kWorstFrames, longest first): when, their wall ms, each
  // stage's ms and the manager's counted work in them (the report's frames.worst).
  static constexpr std::size_t kWorstFrames = 5;
  struct WorstFrame {
    double t = 0;          // s, simulated time of the frame's start
    double total_ms = 0;   // wall, the step
    std::array<double, int(Stage::Count)> stage_ms{};  // wall, per stage
    TerrainManager::FrameWork work;
  };
  const std::vector<WorstFrame>& worst_frames() const { return worst_; }
  // The report's median is over the last kFrameWindow steps (memory stays bounded in a game
  // that runs for hours); the maxima and counts are over every step.
  static constexpr std::size_t kFrameWindow = 1 << 16;
  int peak_granules() const { return peak_granules_; }

  // ---- parts ----
  Heightfield& heightfield() { return *hf_; }
  const Heightfield& heightfield() const { return *hf_; }
  BulletWorld& bullet() { return *bullet_; }
  const BulletWorld& bullet() const { return *bullet_; }
  TerrainManager* manager() { return manager_.get(); }           // null without patches
  const TerrainManager* manager() const { return manager_.get(); }
  Profile& profile() { return profile_; }
  const Profile& profile() const { return profile_; }
  // Heightfield regions written by demotions and not yet taken.
  std::vector<GridRegion> take_dirty_regions();

  // ---- results ----
  // FNV-1a over the simulated time, every live body in slot order (index, position,
  // orientation, velocities), the heightfield and every patch's DEM state: equal for two
  // worlds made and driven the same way, whichever door (API, scene run, bench) drove them.
  std::uint64_t state_hash() const;
  // The report sections every caller shares: simulated_s, steps, stages, frames, bodies,
  // patches_live, granules_live, the manager's ledger / conversions / pool / tile, terrain,
  // final_state_hash (docs/cli.md "report.json").
  nlohmann::ordered_json report() const;

 private:
  World() = default;
  Status check_bodies(const char* stage);
  Status check_body(RigidBodyId id) const;
  void accumulate(RigidBodyId id, const Eigen::Vector3f& force, const Eigen::Vector3f& torque);
  void apply_scene_loads(double t);

  Status spawn_due(double t);
  void place_keyframed(std::size_t entry, double t);
  Status fail(const char* stage, Status s);
  std::size_t entry_of(RigidBodyId id) const;  // entries_.size() when none
  Status check_dynamic(RigidBodyId id) const;
  Status check_kinematic(RigidBodyId id, const char* field) const;
  void drive_kinematic(double t, double dt);
  void enter_kinematic(std::size_t entry, const RigidBodyDef& def);
  static std::vector<TerrainManager::PathPose> planned_path(const RigidShape& shape, const std::vector<Keyframe>& keys, double t);
  void look_ahead(std::size_t entry, const BodyState& st, const Eigen::Vector3d& p, const Eigen::Quaternionf& q, double t, double dt);
  void keep_original_heights();
  void make_due_joints();
  void drive_motors(double t);


  // Declaration order is destruction order reversed: the manager refers to the Bullet world
  // and the heightfield, the Bullet world reads the heightfield's tiles in place.
  std::unique_ptr<Heightfield> hf_;
  std::unique_ptr<BulletWorld> bullet_;
  std::unique_ptr<TerrainManager> manager_;
  Profile profile_;
  std::vector<Entry> entries_;
  std::vector<std::pair<std::size_t, RigidBodyDef>> pending_;  // scheduled, not yet spawned (entry, definition)
  std::vector<RigidBodyId> removing_;  // removed, leaving the Bullet world in the next step
  std::vector<GridRegion> dirty_;
  struct Held {               // a caller's force and torque on a body until the next step
    RigidBodyId id;
    Eigen::Vector3f force, torque;  // N, N m, world
  };
  std::vector<Held> held_;    // in the order bodies were first loaded
  std::vector<std::vector<Load>> loads_;  // by entry index (scene loads)
  std::vector<JointEntry> joints_;        // added or scheduled, in that order
  struct Kinematic {                      // what drives a kinematic body, by entry index
    std::vector<Keyframe> keys;
    bool placed = false;                  // put at its keyframes' pose when it entered
    bool has_target = false;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();
    Eigen::Quaternionf target_q = Eigen::Quaternionf::Identity();
    Eigen::Vector3f v = Eigen::Vector3f::Zero(), w = Eigen::Vector3f::Zero();
    bool looked_ahead = false;            // the manager holds a path extrapolated from its motion (look_ahead)
  };
  std::vector<Kinematic> kinematic_;
  // Elevation tiles as they were before a demotion first wrote them (tile index -> samples).
  std::unordered_map<std::size_t, std::vector<float>> original_tiles_;
  std::vector<double> frame_ms_;       // ring of the last kFrameWindow steps' wall ms
  std::vector<WorstFrame> worst_;      // the longest frames, longest first
  FrameRecord last_frame_;
  double frame_max_ms_ = 0, conversion_max_ms_ = 0;
  double frame_max_at_ = 0;            // s, simulated time of the longest frame's start
  long long conversion_frames_ = 0;
  std::vector<double> awake_ms_;       // ring of the last kFrameWindow steps with a patch awake
  long long awake_frames_ = 0;
  double budget_ms_ = std::numeric_limits<double>::infinity();  // of the last frame
  double prepare_ms_ = 0;  // ms, the wall time of prepare()
  bool prepared_ = false;
  long long over_budget_ = 0;          // frames longer than their budget
  double max_over_budget_ = 0;         // the longest frame / its budget
  int peak_granules_ = 0;
  double time_base_ = 0, dt_ = 0;      // s
  long long steps_at_dt_ = 0, steps_ = 0;
  const char* failed_stage_ = "";
  // Bodies that outran the patch machinery (a frame's travel over the LOD apron): name (or
  // "body N") → the fastest speed seen, m/s; the report's warnings.
  double follow_apron_ = 0;            // m, the manager's lod.apron
  double look_ahead_s_ = 0;            // s, the manager's lod.horizon: how far a game-driven tool's motion is extrapolated
  std::map<std::string, double> too_fast_;
  std::set<std::pair<int, int>> over_follow_;  // bodies (index, generation) over that speed in the last frame
};

}  // namespace sandpatch
