// Scene files: the plain definition of everything a run needs (terrain, materials, bodies,
// simulation, cameras, outputs), parsed from JSON and fully validated before anything runs.
//
// The format is documented field by field in docs/scene-format.md; this header is its
// single source of truth for names, units and defaults. Conventions: SI units, y up, the
// terrain grid in x–z, world positions double. Parsing never stops at the first mistake:
// every error found (unknown keys with a "did you mean", wrong types, missing fields,
// missing or unreadable files, non-finite or out-of-range values, broken cross references,
// open meshes, bodies below a flat bedrock) comes back as an Error naming the file, the
// field path (e.g. "bodies[1].shape.radius"), the value as written and what is allowed.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "common/error.hpp"
#include "common/knobs.hpp"
#include "sandpatch/sandpatch.hpp"

namespace sandpatch {

using Vec3d = std::array<double, 3>;  // x, y, z

// ---- terrain ----

enum class TerrainSourceKind { Png16, RawF32, EsriAscii, Procedural };
enum class ProceduralKind { Flat, Plane, Hills, Noise };

// The terrain of a scene: the library's TerrainDef as the scene gives it, filled by the
// parser as the library takes it (one chain, manager/definitions.hpp):
//   - the terrain section: the heightfield's source (file + file_type "png16" | "raw_f32" |
//     "esri_ascii", samples_x / samples_z of a raw file; or procedural "flat" | "plane" |
//     "hills" | "noise" with base_height ("height" in the file), slopes, amplitude,
//     wavelength, noise_seed ("seed"), octaves and its samples_x / samples_z, default 129),
//     spacing (spacing_overrides_file: "spacing" given with an esri_ascii file), vertical
//     scale and offset, origin, soil_depth (default knobs::kSoilDepth), patch_depth;
//   - `material`: the named one of the scene's materials (the first when none is named);
//   - the simulation section's knobs: pool (slots, granules_per_slot, shell_spheres_per_slot),
//     particle_scale, steps_per_contact, max_substeps, frame_budget_ms, lod (lod_horizon,
//     lod_margin, lod_apron), sleep (sleep_speed, sleep_time), idle_timeout,
//     granular_patches, gravity, seed, threads, backend.
// The generator's formulas are heightfield/procedural.hpp's. World height of sample s:
// y = origin[1] + vertical_offset + vertical_scale · s (s: the 16-bit value / 65535 for png16,
// the stored value for raw_f32 / esri_ascii, the generator's height); sample (i, j) sits at
// world x = origin[0] + i·spacing_x, z = origin[2] + j·spacing_z.
struct TerrainDef : api::TerrainDef {
  // What only scene files have:
  std::optional<std::array<double, 2>> size;   // m, total extent [x, z]; overrides spacing:
                                               //   spacing_x = size[0] / (samples_x − 1)
  std::optional<double> bedrock_height;        // m above origin[1], flat bedrock (instead of soil_depth)
  std::string material_name;                   // the name of the MaterialDef in `material`

  // The source's type as a scene file names it (procedural, or file_type).
  TerrainSourceKind source_kind() const;
  // Spacing along x and z (m) for a grid of nx × nz samples.
  std::array<double, 2> spacing_xz(int nx, int nz) const;
};

// ---- materials ----

// A material of the scene: the library's MaterialDef (density, friction, restitution,
// stiffnesses, granule radius: the parser fills it as the library takes it) with its name and
// what only scene files give.
struct MaterialDef : api::MaterialDef {
  std::string name;                            // unique, referenced by terrain.material
  // ζ in [0, 100] when the file gave damping_ratio instead of restitution (then `restitution`
  // holds the e it gives: e = clamped_restitution(ζ), particles/material.hpp).
  std::optional<double> damping_ratio;
  // φ, granule solid volume / bulk volume: validated, not used by the simulation (the
  // pre-settled tile measures its own φ; the report gives it as tile.packing_fraction).
  double packing_fraction = 0.6;

  // ζ from whichever was given: ζ = −ln e / sqrt(π² + ln² e).
  double damping_ratio_value() const;
};

// ---- bodies ----

// Shapes and motions are the library's (api::ShapeDef: centred on the body frame's origin,
// cylinders and capsules with their axis on y; a mesh is an OBJ file, mesh_file and mesh_scale).
using ShapeKind = api::ShapeKind;
using MotionKind = api::BodyMotion;

// A force and / or torque put on a body while the simulated time t of a step's start is in
// [from, until) (World::set_loads): a push, a wheel's traction, a thrust. Or an impulse, given
// once at the start of the first step that starts at or after `from`: a kick, a hammer blow.
enum class LoadFrame { World, Body };
inline constexpr int kMaxLoadsPerBody = 256;
inline constexpr double kMaxLoad = 1e9;        // N or N m: the largest |force| and |torque| (as the API's)
struct LoadDef {
  Vec3d force = {0.0, 0.0, 0.0};               // N, |force| <= kMaxLoad
  Vec3d torque = {0.0, 0.0, 0.0};              // N m, |torque| <= kMaxLoad
  std::optional<Vec3d> impulse;                // N s, |impulse| <= kMaxLoad; alone (no force, torque, until)
  std::optional<Vec3d> at;                     // m, the force's or impulse's point in the body frame (origin at the
                                               //   centre of mass); none: the centre of mass
  double from = 0.0;                           // s
  std::optional<double> until;                 // s, > from; none: to the end of the run
  LoadFrame frame = LoadFrame::World;          // body: force and torque turn with the body
};

// A kinematic body's pose at simulated time t; between keyframes the position is linear and
// the orientation a slerp, before the first and after the last they hold.
inline constexpr int kMaxKeyframesPerBody = 100000;
struct KeyframeDef {
  double t = 0.0;                              // s, strictly increasing
  Vec3d position = {0.0, 0.0, 0.0};            // m, world
  std::array<double, 4> orientation = {1.0, 0.0, 0.0, 0.0};  // unit quaternion [w, x, y, z] (or euler_deg in the file)
};

// A body of the scene: the library's BodyDef (name, shape, motion, mass, pose, velocities,
// friction, restitution, rolling friction: the parser fills it as the library takes it, so a
// run adds it as it is) and what only scene files give. The pose is the body's at spawn_time
// (a kinematic body's: its keyframes' there).
struct BodyDef : api::BodyDef {
  std::optional<double> density;               // kg/m³ when the file gave it instead of mass (mass = density × volume())
  double mesh_volume = 0.0;                    // m³, mesh: the signed volume of the OBJ, filled by the loader
  std::vector<KeyframeDef> keyframes;          // kinematic only; the pose comes from them
  double spawn_time = 0.0;                     // s, simulated time at which the body appears
  std::vector<LoadDef> loads;                  // at most kMaxLoadsPerBody

  // Volume of the shape (m³): analytic for primitives, mesh_volume for meshes.
  double volume() const;
};

// ---- joints (docs/scene-format.md "joints") ----

// A joint between two bodies (or a body and the world), made when both have spawned, with its
// frame from a world anchor and axis at that moment (BulletWorld's RigidJointDef).
enum class JointType { Fixed, Hinge, Slider };
inline constexpr int kMaxJoints = 4096;
inline constexpr int kMaxMotorPhases = 256;
// The motor while the time t of a step's start is in [from, until) (outside every phase: none).
struct MotorPhaseDef {
  double from = 0.0;                           // s
  std::optional<double> until;                 // s, > from; none: to the end of the run
  std::optional<double> target_velocity;       // rad/s or m/s    } exactly one
  std::optional<double> target_position;       // rad or m (servo) }
  double max_force = 0.0;                      // N m ("max_torque", hinge) or N ("max_force", slider)
  double servo_speed = 1.0;                    // rad/s or m/s (target_position)
};
struct JointDef {
  std::string name;                            // unique among joints
  JointType type = JointType::Hinge;
  std::string body_a;                          // a body's name (a vehicle's parts: "<vehicle>.chassis", ...)
  std::string body_b;                          // "" = the world
  Vec3d anchor = {0.0, 0.0, 0.0};              // m, world, when the joint is made
  Vec3d axis = {0.0, 0.0, 1.0};                // world, when the joint is made (hinge, slider)
  std::optional<std::array<double, 2>> limits; // rad (hinge, within [-pi, pi]) or m
  double spring_stiffness = 0.0;               // N m/rad or N/m (0: no spring)
  double spring_damping = 0.0;                 // N m s/rad or N s/m
  std::vector<MotorPhaseDef> motor;            // at most kMaxMotorPhases
};

// ---- vehicles (docs/scene-format.md "vehicles") ----

// A four-wheeled vehicle: the library's VehicleDef (scene/vehicle.hpp expands it into bodies
// and joints for both doors) and, over time, its throttle and steering.
struct ThrottlePhaseDef {
  double from = 0.0;                           // s
  std::optional<double> until;                 // s, > from
  double wheel_speed = 0.0;                    // rad/s, > 0 forward
  double max_torque = 0.0;                     // N m per driven wheel (0: no drive)
};
struct SteeringPhaseDef {
  double from = 0.0;                           // s
  std::optional<double> until;                 // s, > from
  double angle = 0.0;                          // rad, > 0 left, within ±max_steering_angle
};
struct VehicleSceneDef {
  api::VehicleDef def;                         // outside every phase: its wheel_speed, max_torque, steering_angle
  std::vector<ThrottlePhaseDef> throttle;
  std::vector<SteeringPhaseDef> steering;
};

// ---- simulation ----

enum class Backend { Cpu, Gl };

// Particle scale by distance from a camera (Leach & Marais §4.3, §6.3 scenario 2): a patch is
// promoted at the particle_scale of the first band whose max_distance reaches the distance from
// the camera (its position at the time of promotion) to the patch's centre on the surface;
// beyond the last band, the last band's. A live patch keeps its scale.
struct ScaleBandDef {
  double max_distance = 0;                     // m, strictly ascending over the bands
  double particle_scale = 1;                   // render size / simulated size in this band
};
struct ScaleByDistanceDef {
  std::string camera;                          // name of a CameraDef
  std::vector<ScaleBandDef> bands;             // 1 to 16
};

// The simulation section's fields that are not the terrain's knobs (those are in TerrainDef:
// pool, particle_scale, steps_per_contact, ... see there).
struct SceneSimulationDef {
  double dt = 1.0 / 60.0;                      // s, fixed step of bodies and the frame
  int substeps = 1;                            // substeps per step (the DEM may substep further)
  double duration = 10.0;                      // s, simulated time of a run
  std::optional<ScaleByDistanceDef> scale_by_distance;  // instead of one particle_scale for every patch
  std::string preset;                          // "" or the preset applied first (simulation_presets())
};

// ---- presets (docs/tradeoff.md) ----

// A named set of simulation knobs chosen from the Pareto front that `sandpatch bench tradeoff`
// measured (error against cost on a poured pile and a sphere's crater). "preset": NAME in the
// simulation section applies it before the section's other fields, so fields given beside it
// override it.
struct SimulationPreset {
  const char* name;
  double particle_scale;        // simulation.particle_scale: world granule size / the material's
  int granules_per_slot;        // simulation.pool.granules_per_slot: 32768 / particle_scale³
                                //   rounded up to a multiple of 1024 (a slot holds the same world volume)
  int steps_per_contact;        // simulation.steps_per_contact: the DEM's dt = t_c / N
  const char* measured;         // the sweep's setting behind it, its cost and error (docs/tradeoff.md)
};
const std::vector<SimulationPreset>& simulation_presets();
// nullptr when `name` is not a preset.
const SimulationPreset* find_simulation_preset(const std::string& name);

// ---- cameras ----

struct CameraKeyDef {
  double time = 0.0;                           // s
  Vec3d position = {0.0, 0.0, 0.0};            // m, world
  Vec3d target = {0.0, 0.0, 0.0};              // m, world point looked at
};

struct CameraDef {
  std::string name;                            // unique, referenced by outputs.frames[].camera
  Vec3d position = {0.0, 10.0, 20.0};          // m, world (fixed camera)
  Vec3d target = {0.0, 0.0, 0.0};              // m, world (fixed camera)
  std::vector<CameraKeyDef> path;              // keyframes, times ascending; non-empty = animated
                                               //   (linear interpolation, held outside the range)
  double fov_deg = 60.0;                       // vertical field of view, degrees
  int width = 1280;                            // pixels
  int height = 720;                            // pixels
};

// ---- outputs ----

// File name patterns are relative to the run's output directory. Placeholders:
// {camera} (frames only), {frame} (step index, 6 digits), {time_ms} (simulated ms, 8 digits),
// {ext} (heightfield: png, raw or asc).
struct FrameOutputDef {
  std::string camera;                          // name of a CameraDef
  std::vector<double> times;                   // s, ascending   } exactly one of the two
  int every_k_frames = 0;                      // > 0 when used  }
  std::string file = "{camera}_{frame}.png";
};

enum class HeightfieldFormat { Png16, RawF32, EsriAscii };

struct HeightfieldOutputDef {
  HeightfieldFormat format = HeightfieldFormat::Png16;
  std::vector<double> times;                   // s, ascending
  bool at_end = false;                         // also (or only) at the end of the run
  std::string file = "heightfield_{frame}.{ext}";
};

struct OutputsDef {
  std::vector<FrameOutputDef> frames;
  std::vector<HeightfieldOutputDef> heightfields;
  bool report = true;                          // write report.json
  // The run's time series (docs/cli.md "CSV"): one row per frame per body in this file, one
  // per frame per live patch in its stem + "_patches.csv"; "" = none.
  std::string csv;
};

// ---- the scene ----

struct SceneDef {
  std::string name;                            // default: the file's stem
  std::string description;
  std::string source_path;                     // the file it came from ("<embedded default>" if none)
  std::string hash;                            // 16 hex digits: canonical JSON + referenced files' bytes
  TerrainDef terrain;
  std::vector<MaterialDef> materials;
  std::vector<BodyDef> bodies;
  std::vector<JointDef> joints;
  std::vector<VehicleSceneDef> vehicles;
  SceneSimulationDef simulation;
  std::vector<CameraDef> cameras;
  OutputsDef outputs;

  const MaterialDef* find_material(const std::string& n) const;  // by name
  const CameraDef* find_camera(const std::string& n) const;
};

// The version of the format this library reads (the optional top-level "version" key).
inline constexpr int kSceneFormatVersion = 1;
// The most fixed steps one run may take (duration / dt, or the CLI's --seconds / --frames):
// 10^8 steps is 19 days at 1/60 s. More is refused before anything runs, naming the field.
inline constexpr double kMaxRunFrames = 1e8;

// Reads and validates a scene file; relative paths inside resolve against its directory.
Result<SceneDef> load_scene_file(const std::string& path);

// Validates JSON text. `source_name` is the file name used in errors; `base_dir` resolves
// relative paths (empty = the current directory).
Result<SceneDef> parse_scene(const std::string& json_text, const std::string& source_name,
                             const std::string& base_dir);

// The embedded default scene: the bytes of scenes/default.json, compiled in at build time.
const char* default_scene_json();
// parse_scene(default_scene_json(), "<embedded default>", "").
Result<SceneDef> load_default_scene();

// Canonical JSON of a scene with every default filled in: resolved paths, orientations as
// quaternions; derived values (masses from densities, mesh volumes) are not added. Parsing
// it again gives a scene with the same canonical JSON (its hash differs: the text does).
nlohmann::json scene_to_json(const SceneDef& scene);

// Lowest point of a body below its position (m, ≥ 0), for its pose's orientation. Meshes
// are reloaded from shape.mesh_file; if that fails the mesh's bounds are unknown and 0 is returned.
double body_extent_below(const BodyDef& body);

// The check only the terrain can answer: a body whose lowest point starts below the
// bedrock (world y) under its position. Called after the terrain is loaded.
std::vector<Error> check_bodies_against_terrain(
    const SceneDef& scene, const std::function<float(double x, double z)>& bedrock_world_height);

// Names used in files and errors.
const char* to_string(TerrainSourceKind k);
const char* to_string(ProceduralKind k);
const char* to_string(ShapeKind k);
const char* to_string(Backend b);
const char* to_string(HeightfieldFormat f);
const char* to_string(LoadFrame f);
const char* to_string(MotionKind m);
const char* to_string(JointType t);
const char* to_string(api::DriveWheels d);

}  // namespace sandpatch
