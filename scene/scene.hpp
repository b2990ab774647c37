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

// A generated elevation grid (the generator is heightfield/procedural.hpp's make_procedural,
// which documents the exact formulas). Local heights before vertical_scale/offset:
//   flat:  height
//   plane: height + slope_x·x + slope_z·z                   (x, z in m from sample (0, 0))
//   hills: height + amplitude·c(x)·c(z), c a smooth periodic wave of period `wavelength`
//   noise: height + amplitude·(fractal value noise, coarsest feature `wavelength`, `octaves`)
struct ProceduralDef {
  ProceduralKind kind = ProceduralKind::Flat;
  double height = 0.0;         // m, base height
  double slope_x = 0.0;        // m/m, dh/dx (plane)
  double slope_z = 0.0;        // m/m, dh/dz (plane)
  double amplitude = 1.0;      // m, peak height variation (hills, noise)
  double wavelength = 32.0;    // m, hills period / noise coarsest feature
  std::uint64_t seed = 1;      // noise lattice seed, in [0, 2^32 − 1]
  int octaves = 4;             // noise octaves, each half the wavelength and amplitude
  int samples_x = 129;         // grid samples along x
  int samples_z = 129;         // grid samples along z
};

struct TerrainSourceDef {
  TerrainSourceKind kind = TerrainSourceKind::Procedural;
  std::string file;            // resolved path of the heightmap (png16, raw_f32, esri_ascii)
  int samples_x = 0;           // raw_f32 only: samples along x (row length, x fastest)
  int samples_z = 0;           // raw_f32 only: samples along z (rows)
  ProceduralDef procedural;    // procedural only
};

// World height of sample s:  y = origin[1] + vertical_offset + vertical_scale · s, where s is
// the 16-bit value / 65535 for png16 and the stored value for raw_f32 / esri_ascii.
// Sample (i, j) sits at world x = origin[0] + i·spacing_x, z = origin[2] + j·spacing_z.
struct TerrainDef {
  TerrainSourceDef source;
  double spacing = 1.0;                        // m between samples in x and z (when size is not given)
  bool spacing_given = false;                  // "spacing" was in the file (esri_ascii: overrides cellsize)
  std::optional<std::array<double, 2>> size;   // m, total extent [x, z]; overrides spacing:
                                               //   spacing_x = size[0] / (samples_x − 1)
  double vertical_scale = 1.0;                 // m per sample unit (png16: m for the full 0..65535 range)
  double vertical_offset = 0.0;                // m, added after scaling
  Vec3d origin = {0.0, 0.0, 0.0};              // m, world position of sample (0, 0) at height 0
  std::optional<double> soil_depth;            // m, bedrock = surface − soil_depth (default knobs::kSoilDepth, 2 m)
  double patch_depth = knobs::kPatchDepth.def; // m of granules under a patch's lowest surface point (<= soil depth)
  std::optional<double> bedrock_height;        // m above origin[1], flat bedrock (instead of soil_depth)
  std::string material;                        // name of a MaterialDef (default: the first material)

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
// [from, until) (World::set_loads): a push, a wheel's traction, a thrust.
enum class LoadFrame { World, Body };
inline constexpr int kMaxLoadsPerBody = 256;
inline constexpr double kMaxLoad = 1e9;        // N or N m: the largest |force| and |torque| (as the API's)
struct LoadDef {
  Vec3d force = {0.0, 0.0, 0.0};               // N, |force| <= kMaxLoad
  Vec3d torque = {0.0, 0.0, 0.0};              // N m, |torque| <= kMaxLoad
  std::optional<Vec3d> at;                     // m, the force's point in the body frame (origin at the
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

struct PoolDef {
  int slots = int(knobs::kSlots.def);          // simulations kept ready (active patches at once)
  int granules_per_slot = int(knobs::kGranulesPerSlot.def);  // capacity of each slot
  int shell_spheres_per_slot = int(knobs::kShellSpheresPerSlot.def);  // body-shell spheres each slot holds
};

struct SleepDef {
  double speed_threshold = knobs::kSleepSpeed.def;  // m/s, every granule slower than this ...
  double hold_time = knobs::kSleepTime.def;    // s, ... for this long puts a patch to sleep
};

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

// Contact prediction (manager/lod.hpp): a patch is requested when a body's ballistic path
// comes within `margin` of the terrain inside `horizon`.
struct LodSectionDef {
  double horizon = knobs::kLodHorizon.def;     // s
  double margin = knobs::kLodMargin.def;       // m
  double apron = knobs::kLodApron.def;         // m, around a contact's footprint on every side
};

struct SceneSimulationDef {
  double dt = 1.0 / 60.0;                      // s, fixed step of bodies and the frame
  int substeps = 1;                            // substeps per step (the DEM may substep further)
  double duration = 10.0;                      // s, simulated time of a run
  Backend backend = Backend::Cpu;              // DEM backend
  int threads = 0;                             // worker threads, 0 = all hardware threads
  PoolDef pool;
  double particle_scale = knobs::kParticleScale.def;  // render size / simulated size (Leach §4.3)
  int steps_per_contact = int(knobs::kStepsPerContact.def);  // N: the DEM substeps at dt <= t_c / N (t_c: contact time)
  int max_substeps = int(knobs::kMaxSubsteps.def);  // most DEM substeps per frame, 0 = max(64, 64 N / 20)
  // ms of wall time a frame's patches may take (docs/manager.md "Frame budget"); absent: half
  // of dt; "off" (infinity here): none.
  std::optional<double> frame_budget_ms;
  LodSectionDef lod;
  std::optional<ScaleByDistanceDef> scale_by_distance;  // instead of one particle_scale for every patch
  SleepDef sleep;
  double idle_timeout = knobs::kIdleTimeout.def;  // s asleep and untouched before demotion (Leach & Marais)
  bool granular_patches = true;                // false: no patches, bodies meet the heightfield only (LOD off the other way)
  Vec3d gravity = {0.0, -9.81, 0.0};           // m/s²
  std::uint64_t seed = 1;                      // all randomness of a run
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

  const MaterialDef* find_material(const std::string& n) const;
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
