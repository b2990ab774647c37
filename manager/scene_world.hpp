// A scene file's world: its heightfield, bodies and terrain manager made into a World
// (manager/world.hpp), for `sandpatch run`, `sandpatch bench lod` and the tests. A scene's
// terrain, material, simulation settings and bodies (scene/scene.hpp) are mapped onto the
// library's public definitions (TerrainDef, BodyDef) here, and from there go the one way the
// library's do (manager/definitions.hpp): the same validation, the same heightfield builder,
// the same manager and Bullet definitions. What only scene files have (named materials,
// densities, loads, keyframes, spawn times, scale bands, a flat bedrock, a size instead of a
// spacing) is added around that chain here.
#pragma once

#include <functional>
#include <memory>
#include <string>

#include "common/error.hpp"
#include "manager/bullet_world.hpp"
#include "manager/definitions.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/world.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"
#include "scene/vehicle.hpp"

namespace sandpatch {

// The library's TerrainDef of a scene: the one the parser filled (scene.terrain: its
// heightfield source, material and every setting both doors share) with the run's thread
// count and `backend` ("cpu" or "gl"), and the demotion's depth rendered on GL when it can.
api::TerrainDef terrain_def(const SceneDef& scene, int threads, const std::string& backend);

// The terrain manager's definition of a scene: manager_def(terrain_def(...))
// (manager/definitions.hpp), then what only scene files have: the scale bands (camera at
// t = 0) and the flat bedrock, which need the heightfield.
TerrainManagerDef manager_def(const SceneDef& scene, const Heightfield& hf, int threads, const std::string& backend);

// Scene body `index` as the library's BodyDef: the one the parser filled (mass given or
// density × volume, pose, velocities, shape with a mesh's resolved OBJ path, contact
// settings). Its keyframes, loads and spawn time stay with the scene (make_world schedules them).
api::BodyDef body_def(const SceneDef& scene, std::size_t index);

// rigid_body_def(body_def(scene, index)), errors named after the scene's field
// ("bodies[2].shape.radius").
Result<RigidBodyDef> to_rigid_body(const SceneDef& scene, std::size_t index);

// A scene body's loads as the World applies them (World::set_loads).
std::vector<World::Load> to_loads(const BodyDef& body);

// A scene joint as Bullet's definition, its bodies left unset (the World fills them when both
// have spawned), and its motor phases as the World applies them (World::set_motor_phases).
RigidJointDef to_rigid_joint(const JointDef& joint);
std::vector<World::MotorPhase> to_motor_phases(const JointDef& joint);

// The library's joint motor as Bullet's.
JointMotor core_motor(const api::JointMotor& motor);
// A vehicle's wheel joint with the bodies left unset (scene/vehicle.hpp); its bodies (the
// api::BodyDefs expand_vehicle makes) go through rigid_body_def like every body.
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
