// A scene file's world: its heightfield, bodies and terrain manager made into a World
// (manager/world.hpp), for `sandpatch run`, `sandpatch bench lod` and the tests. The scene's
// definitions (scene/scene.hpp) are turned into the manager's and Bullet's here, in one place.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "common/error.hpp"
#include "manager/bullet_world.hpp"
#include "manager/terrain_def.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/world.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "scene/vehicle.hpp"

namespace sandpatch {

// The library's TerrainDef for a scene's terrain material and simulation section
// (docs/scene-format.md): the settings both doors share. `backend`: "cpu" or "gl".
api::TerrainDef terrain_def(const SceneDef& scene, int threads, const std::string& backend);

// The terrain manager's definition of a scene: manager_def(terrain_def(...))
// (manager/terrain_def.hpp), then what only scene files have: the scale bands (camera at
// t = 0) and the flat bedrock, which need the heightfield.
TerrainManagerDef manager_def(const SceneDef& scene, const Heightfield& hf, int threads, const std::string& backend);

// Scene body `index` as a Bullet body definition (meshes are read again from their validated
// OBJ, centred on their centroid).
Result<RigidBodyDef> to_rigid_body(const SceneDef& scene, std::size_t index);

// A scene body's loads as the World applies them (World::set_loads).
std::vector<World::Load> to_loads(const BodyDef& body);

// A scene joint as Bullet's definition, its bodies left unset (the World fills them when both
// have spawned), and its motor phases as the World applies them (World::set_motor_phases).
RigidJointDef to_rigid_joint(const JointDef& joint);
std::vector<World::MotorPhase> to_motor_phases(const JointDef& joint);

// The library's joint motor as Bullet's.
JointMotor core_motor(const api::JointMotor& motor);
// A vehicle's wheel (a primitive api::BodyDef from expand_vehicle) as Bullet's definition, and
// its wheel joint with the bodies left unset (scene/vehicle.hpp).
RigidBodyDef vehicle_body_def(const api::BodyDef& part);
RigidJointDef vehicle_joint_def(const VehicleJoint& joint);

// Camera pose at simulated time t: fixed, or linear between path keyframes (held outside).
render::CameraView camera_at(const CameraDef& camera, double t);

// The scene's world, ready for its first frame: the heightfield loaded, every body checked
// against it (none may start below the bedrock or with its centre inside the terrain) and
// scheduled at its spawn time, the terrain manager made unless the scene turns patches off.
// Errors are bad input (they name the scene file and field) found before anything runs;
// `stage` (if given) is set to the part that refused: terrain, bodies or activation.
// `patches` false builds everything but the patch pool (its settings were checked with the
// scene file): `sandpatch check` runs this, so it refuses what run would before frame 0.
// `on_settle` (if given) is told how far the start-up's tile settling is (TerrainManagerDef).
Result<std::unique_ptr<World>> make_world(const SceneDef& scene, int threads, const std::string& backend,
                                          std::string* stage = nullptr, bool patches = true,
                                          const std::function<void(const std::string&, double, double, double)>& on_settle = {});

}  // namespace sandpatch
