// The one table of the terrain's knobs: every setting that both doors take (a scene file and
// the library's TerrainDef / BodyDef), with its default, allowed range and unit. The scene
// parser (scene/scene.cpp) and the API (api/sandpatch.cpp) validate with these entries, the
// internal definitions (TerrainManagerDef, RigidBodyDef) and the public ones take their
// defaults from them (the public header, which includes only the standard library, repeats
// the numbers; tests/common/knobs_test.cpp checks that every copy agrees, and that the field
// tables in docs/scene-format.md and docs/api.md are the ones `knob_table_markdown` prints).
//
// A setting only one door has is listed with the reason in `one_door`. The limits of the
// terrain's source, shapes, cameras and outputs (kLimits) are a second table of the same form, printed after the first.
#pragma once

#include <array>
#include <cmath>
#include <limits>
#include <string>

#include "common/error.hpp"

namespace sandpatch::knobs {

struct Knob {
  const char* scene;     // path in a scene file ("" = none: see one_door)
  const char* api;       // field of the public definitions ("" = none: see one_door)
  double def;            // default
  double lo, hi;         // allowed range ...
  bool lo_open, hi_open; // ... with open ends where true
  bool integer;          // whole numbers only
  const char* unit;      // SI unit ("" = dimensionless)
  const char* what;      // one line for the docs
  const char* one_door = "";  // why only one door has it
  // True when v is finite, inside the range and (for integers) whole.
  bool allows(double v) const {
    if (!std::isfinite(v)) return false;
    if (lo_open ? !(v > lo) : !(v >= lo)) return false;
    if (hi_open ? !(v < hi) : !(v <= hi)) return false;
    return !integer || v == std::floor(v);
  }
};

// ---- the granular material (Bell et al. 2005 granules of 4 spheres) ----
inline constexpr Knob kGranuleRadius{"materials[].granule_radius", "TerrainDef.material.granule_radius", 0.025, 1e-5, 10, false, false, false, "m", "radius of each of the 4 spheres of a granule"};
inline constexpr Knob kDensity{"materials[].density", "TerrainDef.material.density", 2650, 0, 1e5, true, false, false, "kg/m^3", "density of the grain solid"};
inline constexpr Knob kFriction{"materials[].friction", "TerrainDef.material.friction", 0.5, 0, 10, false, false, false, "", "Coulomb friction μ between spheres"};
inline constexpr Knob kRestitution{"materials[].restitution", "TerrainDef.material.restitution", 0.3, 0, 1, true, false, false, "", "coefficient of restitution e of a sphere pair (or damping_ratio in scene files)"};
inline constexpr Knob kStiffness{"materials[].stiffness", "TerrainDef.material.stiffness", 2.0e4, 1, 1e12, false, false, false, "N/m", "normal contact stiffness k_n"};
inline constexpr Knob kTangentialRatio{"materials[].tangential_stiffness_ratio", "TerrainDef.material.tangential_stiffness_ratio", 2.0 / 7.0, 0, 1, false, false, false, "", "k_t / k_n"};
inline constexpr Knob kUnloadingRatio{"materials[].unloading_stiffness_ratio", "TerrainDef.material.unloading_stiffness_ratio", 1, 1, 100, false, false, false, "", "hysteretic normal spring (Walton & Braun): unloading / loading stiffness; 1 = linear (docs/dem.md)"};

// ---- the patches ----
inline constexpr Knob kSlots{"simulation.pool.slots", "TerrainDef.slots", 2, 1, 1024, false, false, true, "", "simulations in the pool (patches live at once)"};
inline constexpr Knob kGranulesPerSlot{"simulation.pool.granules_per_slot", "TerrainDef.granules_per_slot", 16384, 64, 16777216, false, false, true, "", "granule capacity of each slot"};
inline constexpr Knob kShellSpheresPerSlot{"simulation.pool.shell_spheres_per_slot", "TerrainDef.shell_spheres_per_slot", 8192, 64, 1048576, false, false, true, "", "body-shell sphere capacity of each slot: a body's surface sampled every 1.5 granule radii (a body needing more is refused when it is added)"};
inline constexpr Knob kParticleScale{"simulation.particle_scale", "TerrainDef.particle_scale", 1, 1e-3, 1e3, false, false, false, "", "world size / simulated size of granules (Leach & Marais §4.3)"};
inline constexpr Knob kStepsPerContact{"simulation.steps_per_contact", "TerrainDef.steps_per_contact", 20, 2, 1000, false, false, true, "", "N: the DEM substeps at dt <= t_c / N (t_c the contact time)"};
inline constexpr Knob kMaxSubsteps{"simulation.max_substeps", "TerrainDef.max_substeps", 0, 0, 100000, false, false, true, "", "most DEM substeps per frame before a frame is refused; 0 = max(64, 64 N / 20)"};
inline constexpr Knob kPatchDepth{"terrain.patch_depth", "TerrainDef.patch_depth", 0.4, 0, 1e4, true, false, false, "m", "granules under a patch's lowest surface point (at most soil_depth)"};
inline constexpr Knob kSoilDepth{"terrain.soil_depth", "TerrainDef.soil_depth", 2.0, 0, 1e4, true, false, false, "m", "bedrock = surface − soil_depth"};
inline constexpr Knob kSleepSpeed{"simulation.sleep.speed_threshold", "TerrainDef.sleep_speed", 0.01, 0, 100, false, false, false, "m/s", "a patch sleeps when every granule is slower ..."};
inline constexpr Knob kSleepTime{"simulation.sleep.hold_time", "TerrainDef.sleep_time", 0.5, 0, 1e4, false, false, false, "s", "... for this long"};
inline constexpr Knob kRegionSleepTime{"simulation.sleep.region_hold_time", "TerrainDef.region_sleep_time", 0, 0, 1e4, false, false, false, "s", "a still part of an awake patch sleeps once its granules have stayed within 0.1 sphere radii of one place this long (CPU backend; 0: hold_time)"};
inline constexpr Knob kIdleTimeout{"simulation.idle_timeout", "TerrainDef.idle_timeout", 120, 0, 1e6, false, false, false, "s", "asleep and untouched this long, a patch turns back into heightfield"};
inline constexpr Knob kThreads{"simulation.threads", "TerrainDef.threads", 0, 0, 1024, false, false, true, "", "DEM threads, 0 = all hardware threads"};
inline constexpr Knob kLodHorizon{"simulation.lod.horizon", "TerrainDef.lod_horizon", 0.5, 0, 10, true, false, false, "s", "how far ahead a body's path (ballistic, keyframed, or a game-driven tool's motion held) is checked for contact"};
inline constexpr Knob kLodMargin{"simulation.lod.margin", "TerrainDef.lod_margin", 0.05, 0, 100, false, false, false, "m", "clearance that already counts as contact"};
inline constexpr Knob kLodApron{"simulation.lod.apron", "TerrainDef.lod_apron", 1.0, 0, 1000, false, false, false, "m", "added around a contact's footprint on every side of a patch"};

// ---- bodies ----
inline constexpr Knob kBodyFriction{"bodies[].friction", "BodyDef.friction", 0.5, 0, 10, false, false, false, "", "Coulomb μ against the heightfield and other bodies"};
inline constexpr Knob kBodyRestitution{"bodies[].restitution", "BodyDef.restitution", 0.1, 0, 1, false, false, false, "", "restitution against the heightfield and other bodies"};
inline constexpr Knob kBodyRollingFriction{"bodies[].rolling_friction", "BodyDef.rolling_friction", 0.05, 0, 10, false, false, false, "", "rolling resistance (torque arm / radius)"};

// Every entry, in the order of the docs' tables.
inline constexpr std::array<const Knob*, 26> kAll = {
    &kGranuleRadius, &kDensity, &kFriction, &kRestitution, &kStiffness, &kTangentialRatio, &kUnloadingRatio,
    &kSlots, &kGranulesPerSlot, &kShellSpheresPerSlot, &kParticleScale, &kStepsPerContact, &kMaxSubsteps, &kPatchDepth,
    &kSoilDepth, &kSleepSpeed, &kSleepTime, &kRegionSleepTime, &kIdleTimeout, &kThreads, &kLodHorizon, &kLodMargin,
    &kLodApron, &kBodyFriction, &kBodyRestitution, &kBodyRollingFriction};

// ---- limits: the ranges of the terrain's source, shapes, cameras and outputs ----
// The same form as the knobs, for fields that are sizes and times rather than tuning: the
// parser, the API's validation (manager/definitions.cpp) and the docs read these numbers. A
// NaN default: none (the field is required, or absent means unused).
inline constexpr double kNoDefault = std::numeric_limits<double>::quiet_NaN();
// The terrain's source: a generator's parameters (heightfield/procedural.hpp), the grid and the
// heights' scale. The sample counts are also capped together (limits::check_grid_size).
inline constexpr Knob kBaseHeight{"terrain.source.height", "TerrainDef.base_height", 0, -1e5, 1e5, false, false, false, "m", "procedural: the surface's height at the origin (every kind)"};
inline constexpr Knob kSlopeX{"terrain.source.slope_x", "TerrainDef.slope_x", 0, -100, 100, false, false, false, "m/m", "plane: dh/dx"};
inline constexpr Knob kSlopeZ{"terrain.source.slope_z", "TerrainDef.slope_z", 0, -100, 100, false, false, false, "m/m", "plane: dh/dz"};
inline constexpr Knob kAmplitude{"terrain.source.amplitude", "TerrainDef.amplitude", 1, 0, 1e5, false, false, false, "m", "hills, noise: height amplitude"};
inline constexpr Knob kWavelength{"terrain.source.wavelength", "TerrainDef.wavelength", 32, 0, 1e7, true, false, false, "m", "hills, noise: horizontal wavelength"};
inline constexpr Knob kOctaves{"terrain.source.octaves", "TerrainDef.octaves", 4, 1, 16, false, false, true, "", "noise: octaves summed"};
inline constexpr Knob kSamplesX{"terrain.source.samples_x", "TerrainDef.samples_x", kNoDefault, 2, 1048577, false, false, true, "", "grid samples along x (raw_f32, procedural, an array); a scene's procedural source: 129 when absent"};
inline constexpr Knob kSamplesZ{"terrain.source.samples_z", "TerrainDef.samples_z", kNoDefault, 2, 1048577, false, false, true, "", "grid samples along z, as samples_x"};
inline constexpr Knob kSpacing{"terrain.spacing", "TerrainDef.spacing", 1, 1e-4, 1e4, false, false, false, "m", "between samples in x and z (esri_ascii: overrides the file's cellsize when given)"};
inline constexpr Knob kVerticalScale{"terrain.vertical_scale", "TerrainDef.vertical_scale", 1, 0, 1e5, true, false, false, "m", "height per unit of a sample's value"};
inline constexpr Knob kVerticalOffset{"terrain.vertical_offset", "TerrainDef.vertical_offset", 0, -1e6, 1e6, false, false, false, "m", "added to every sample's height"};
// Shapes: Bullet keeps sizes as float; below 1e-6 m a shape is a point to it.
inline constexpr Knob kShapeRadius{"bodies[].shape.radius", "BodyDef.shape.radius", 0.5, 1e-6, 1e4, false, false, false, "m", "radius of a sphere, cylinder or capsule"};
inline constexpr Knob kShapeHalfExtent{"bodies[].shape.half_extents", "BodyDef.shape.half_extents", 0.5, 1e-6, 1e4, false, false, false, "m", "each half extent of a box"};
inline constexpr Knob kCylinderHeight{"bodies[].shape.height", "BodyDef.shape.height", 1, 1e-6, 1e4, false, false, false, "m", "cylinder: total height"};
inline constexpr Knob kCapsuleHeight{"bodies[].shape.height", "BodyDef.shape.height", 1, 0, 1e4, false, false, false, "m", "capsule: distance between the cap centres (total height + 2 radius)"};
inline constexpr Knob kMeshScale{"bodies[].shape.scale", "BodyDef.shape.mesh_scale", 1, 1e-6, 1e4, false, false, false, "m per OBJ unit", "mesh: OBJ units to m"};
// Cameras and outputs: a scene run renders and writes files; a game does that itself.
inline constexpr const char* kRunOnly = "a scene run renders and writes files; a game does that itself";
inline constexpr Knob kCameraFov{"cameras[].fov_deg", "", 60, 1, 179, false, false, false, "deg", "vertical field of view", kRunOnly};
inline constexpr Knob kCameraWidth{"cameras[].width", "", 1280, 16, 16384, false, false, true, "px", "image width", kRunOnly};
inline constexpr Knob kCameraHeight{"cameras[].height", "", 720, 16, 16384, false, false, true, "px", "image height", kRunOnly};
inline constexpr Knob kCameraKeyTime{"cameras[].path[].time", "", kNoDefault, 0, 1e6, false, false, false, "s", "time of a camera keyframe (strictly ascending)", kRunOnly};
inline constexpr Knob kOutputTime{"outputs.frames[].times", "", kNoDefault, 0, 1e6, false, false, false, "s", "each time an image is written (strictly ascending); outputs.heightfields[].times the same", kRunOnly};
inline constexpr Knob kEveryKFrames{"outputs.frames[].every_k_frames", "", kNoDefault, 1, 1e6, false, false, true, "", "an image every k fixed steps (instead of times)", kRunOnly};
inline constexpr Knob kVideoFps{"", "", 30, 0, 1e6, true, false, false, "1/s", "video frames per simulated second; also at most 1 / simulation.dt",
                                "`sandpatch run --video-fps` (a command-line option)"};

inline constexpr std::array<const Knob*, 23> kLimits = {
    &kBaseHeight, &kSlopeX, &kSlopeZ, &kAmplitude, &kWavelength, &kOctaves, &kSamplesX, &kSamplesZ,
    &kSpacing, &kVerticalScale, &kVerticalOffset, &kShapeRadius, &kShapeHalfExtent, &kCylinderHeight, &kCapsuleHeight, &kMeshScale, &kCameraFov,
    &kCameraWidth, &kCameraHeight, &kCameraKeyTime, &kOutputTime, &kEveryKFrames, &kVideoFps};

// Every other setting: not a number with a range, or in one door only (then `note` says why).
// Scene paths name a field or a whole section ("cameras" covers everything under it).
struct Field {
  const char* scene;  // "" = the library only
  const char* api;    // "" = scene files only
  const char* note;
};
inline constexpr std::array<Field, 36> kOtherFields = {{
    {"terrain.source", "TerrainDef.file + file_type, TerrainDef.procedural (+ noise_seed)", "a heightmap file or a generator (its numbers are limits above); the scene's source.type is file_type (the library may leave it to the extension)"},
    {"", "TerrainDef.heights", "an array from the game; scene files name a heightmap file instead"},
    {"", "TerrainDef.spacing_overrides_file", "with an esri_ascii source, a scene's terrain.spacing given overrides the file's cellsize"},
    {"terrain.size", "", "the library gives spacing and the sample count"},
    {"terrain.origin", "TerrainDef.origin", ""},
    {"terrain.bedrock_height", "", "a flat bedrock; the library's bedrock is surface − soil_depth"},
    {"terrain.material", "", "a scene names one of its materials; a TerrainDef has one material"},
    {"materials[].name", "", "as terrain.material"},
    {"materials[].damping_ratio", "", "the library takes the restitution e, from which ζ follows"},
    {"materials[].packing_fraction", "", "validated, not used: the pre-settled tile measures its own φ"},
    {"bodies[].name", "BodyDef.name", ""},
    {"bodies[].shape", "BodyDef.shape", "mesh: an OBJ file (file, scale, solid) in both; the library also takes vertices and triangles"},
    {"bodies[].motion", "BodyDef.motion", "not a number: dynamic, kinematic or static (BodyMotion in the library)"},
    {"bodies[].keyframes", "Terrain::set_keyframes, set_kinematic_target", "a kinematic body's poses over time; a game may also give one target pose per step"},
    {"bodies[].mass", "BodyDef.mass", "dynamic bodies only"},
    {"bodies[].density", "", "the library takes the mass"},
    {"bodies[].pose", "BodyDef.position, BodyDef.orientation", "[w, x, y, z] in both; scene files also take euler_deg"},
    {"bodies[].linear_velocity", "BodyDef.linear_velocity", ""},
    {"bodies[].angular_velocity", "BodyDef.angular_velocity", ""},
    {"bodies[].spawn_time", "", "a game adds a body when it is due (Terrain::add_body)"},
    {"bodies[].loads", "Terrain::apply_force, apply_torque, apply_impulse", "a game calls these before each step; a scene lists forces and torques with the times they act, and impulses with the time each is given"},
    {"vehicles", "VehicleDef, Terrain::add_vehicle, drive_vehicle", "the same fields, one expansion (scene/vehicle.hpp); a scene gives throttle and steering phases over time, a game calls drive_vehicle before each step"},
    {"joints", "JointDef, Terrain::add_joint, set_joint_motor", "bodies by name in a scene, by handle in the library; a scene's motor is a list of phases over time (joints[].motor), a game calls set_joint_motor before each step"},
    {"simulation.dt", "Terrain::step(dt, substeps)", "the step's arguments"},
    {"simulation.substeps", "Terrain::step(dt, substeps)", "the step's arguments"},
    {"simulation.duration", "", "a game steps for as long as it runs"},
    {"simulation.backend", "TerrainDef.backend", "cpu or gl"},
    {"simulation.granular_patches", "TerrainDef.granular_patches", ""},
    {"simulation.sleep.regions", "TerrainDef.sleep_regions", ""},
    {"simulation.lod.travel", "TerrainDef.lod_travel", ""},
    {"simulation.gravity", "TerrainDef.gravity", ""},
    {"simulation.seed", "TerrainDef.seed", ""},
    {"simulation.preset", "", "a named set of knobs; a game sets the knobs themselves"},
    {"simulation.frame_budget_ms", "TerrainDef.frame_budget_ms", "ms > 0, or \"off\" (+infinity in the library); absent: half of each frame's dt"},
    {"simulation.scale_by_distance", "", "bands around a scene camera; a game sets particle_scale"},
    {"", "TerrainDef.gl_depth_render", "a scene run renders the demotion's depth on GL on a GPU or with the GL backend, else on the CPU"},
}};
// Scene-file sections that describe a run, not the terrain (what it writes, what it is called).
inline constexpr std::array<const char*, 5> kRunSections = {"name", "description", "version", "cameras", "outputs"};

// "(0, 1e+05] kg/m^3"; integers: "[1, 1024] (whole number)".
inline std::string describe_range(const Knob& k) {
  std::string s = std::string(k.lo_open ? "(" : "[") + format_number(k.lo) + ", " + format_number(k.hi) + (k.hi_open ? ")" : "]");
  if (*k.unit) s += std::string(" ") + k.unit;
  if (k.integer) s += " (whole number)";
  return s;
}

// The markdown table of every knob (scene field, API field, default, range, meaning), as
// docs/scene-format.md and docs/api.md hold it between "<!-- knobs:begin -->" and
// "<!-- knobs:end -->" (`sandpatch info --knobs` prints it).
inline std::string knob_table_markdown() {
  auto cell = [](const char* field, const char* why) {
    return *field ? std::string("`") + field + "`" : std::string("— (") + why + ")";
  };
  auto rows = [&](const auto& table) {
    std::string r = "| scene file | library | default | allowed | meaning |\n|---|---|---|---|---|\n";
    for (const Knob* k : table)
      r += "| " + cell(k->scene, k->one_door) + " | " + cell(k->api, k->one_door) + " | " +
           (std::isnan(k->def) ? std::string("—") : format_number(k->def) + (*k->unit ? std::string(" ") + k->unit : "")) +
           " | " + describe_range(*k) + " | " + k->what + " |\n";
    return r;
  };
  std::string t = rows(kAll);
  t += "\nThe limits of the terrain's source, shapes, cameras and outputs:\n\n" + rows(kLimits);
  t += "\nThe other settings, and those only one door has:\n\n| scene file | library | note |\n|---|---|---|\n";
  auto plain = [](const char* field) { return *field ? std::string("`") + field + "`" : std::string("—"); };
  for (const Field& f : kOtherFields) t += "| " + plain(f.scene) + " | " + plain(f.api) + " | " + f.note + " |\n";
  t += "\nScene files also describe the run (";
  for (std::size_t i = 0; i < kRunSections.size(); ++i) t += std::string(i ? ", " : "") + "`" + kRunSections[i] + "`";
  t += "): what it writes and what it is called; a game renders and names things itself.\n";
  return t;
}

}  // namespace sandpatch::knobs
