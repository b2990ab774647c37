// Sandpatch as a library for games (docs/api.md).
//
// A game creates a Terrain from a TerrainDef (heights from an array, a heightmap file or a
// generator), adds bodies from BodyDefs, and calls step(dt) once per fixed frame. Between
// steps it reads body states, terrain heights and normals, the granules of live patches and
// the heightfield regions that changed (for its own renderer), and polls the patch events
// (promoted, ready, asleep, woke, demoted).
//
// Rules of the API:
//   - Definition, validation, handle: every object comes from a plain definition struct with
//     defaults; creation validates it and returns a Result holding either the object / handle
//     or errors that name the field ("TerrainDef.material.granule_radius"), the value given
//     and what is allowed. Nothing is thrown across the API for bad input.
//   - Fixed step: step(dt, substeps) advances exactly dt seconds; there is no accumulator.
//   - Units: SI (m, kg, s, N), y up, the terrain grid in the x–z plane.
//   - Precision: world positions are double; arrays handed to renderers (particles, heights)
//     are float and relative to the terrain's origin (Terrain::origin()).
//   - Threads: a Terrain is used from one thread at a time; it may use OpenMP threads inside
//     step() (TerrainDef::threads).
//
// This header includes only the C++ standard library: no Eigen, Bullet or JSON types.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#if defined(_WIN32)
#if defined(SANDPATCH_API_BUILD)
#define SANDPATCH_API __declspec(dllexport)
#else
#define SANDPATCH_API __declspec(dllimport)
#endif
#else
#define SANDPATCH_API __attribute__((visibility("default")))
#endif

namespace sandpatch::api {

inline constexpr const char* kVersion = "0.1.0";  // the library's version (also SandpatchConfigVersion.cmake)

// ---------------------------------------------------------------------------------------
// Errors and results

struct Error {
  std::string file;     // file the bad input came from ("" for a definition struct)
  std::string field;    // "TerrainDef.material.granule_radius", "BodyDef.mass", "step.dt"
  std::string value;    // the offending value
  std::string allowed;  // what would have been accepted
  std::string detail;   // optional extra sentence

  // "TerrainDef.slots = 0: must be in [1, 1024]"
  std::string message() const {
    std::string m;
    if (!file.empty()) m += file + ": ";
    if (!field.empty()) m += field;
    if (!value.empty()) m += (field.empty() ? "" : " = ") + value;
    if (!allowed.empty()) m += (m.empty() || m.ends_with(": ") ? "" : ": ") + allowed;
    if (!detail.empty()) m += (m.empty() ? "" : "; ") + detail;
    return m;
  }
};

struct Ok {};

// A value or the errors that prevented it (at least one).
template <class T>
class Result {
 public:
  Result(T value) : v_(std::move(value)) {}                  // NOLINT: implicit on purpose
  Result(Error e) : v_(std::vector<Error>{std::move(e)}) {}  // NOLINT
  Result(std::vector<Error> es) : v_(std::move(es)) {}       // NOLINT (es non-empty)

  bool ok() const { return v_.index() == 0; }
  explicit operator bool() const { return ok(); }
  T& value() & { return std::get<0>(v_); }
  const T& value() const& { return std::get<0>(v_); }
  T&& value() && { return std::move(std::get<0>(v_)); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }
  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  // Empty when ok().
  const std::vector<Error>& errors() const {
    static const std::vector<Error> none;
    return ok() ? none : std::get<1>(v_);
  }
  // All error messages, one a line ("" when ok()).
  std::string message() const {
    std::string m;
    for (const auto& e : errors()) m += e.message() + "\n";
    return m;
  }

 private:
  std::variant<T, std::vector<Error>> v_;
};

using Status = Result<Ok>;

using Vec3 = std::array<double, 3>;   // m (world positions)
using Vec3f = std::array<float, 3>;   // m/s, rad/s, unit normals
using Quat = std::array<float, 4>;    // unit quaternion [w, x, y, z]

// ---------------------------------------------------------------------------------------
// Terrain definition

// The granular material of the patches (one per terrain). Ranges as in scene files
// (docs/scene-format.md "materials").
struct MaterialDef {
  double granule_radius = 0.025;               // m, radius of each of the 4 spheres of a granule, [1e-5, 10]
  double density = 2650.0;                     // kg/m³ of the grain solid, (0, 1e5]
  double friction = 0.5;                       // μ between spheres, [0, 10]
  double restitution = 0.3;                    // e, (0, 1]
  double stiffness = 2.0e4;                    // k_n, N/m, [1, 1e12]
  double tangential_stiffness_ratio = 2.0 / 7.0;  // k_t / k_n, [0, 1]
  // Hysteretic normal spring (Walton & Braun 1986): contacts unload along this many times
  // k_n, so a bed loses energy however slowly it moves (a ball dropped into it stays down;
  // docs/validation.md). 1 = the linear spring. Both backends. [1, 100]
  double unloading_stiffness_ratio = 1.0;
};

// Where the heights come from: exactly one of `heights` (non-empty), `file` (non-empty) or
// `procedural` (non-empty) is used.
struct TerrainDef {
  // -- heights from an array: samples_x * samples_z floats, row-major with x fastest
  //    (sample (i, j) = heights[j * samples_x + i]), m relative to origin[1]
  std::vector<float> heights;
  int samples_x = 0;                           // [2, 1048577] (array, raw file, procedural)
  int samples_z = 0;                           // [2, 1048577]; samples_x · samples_z <= 268435456
  // -- or from a heightmap file: .png (16-bit greyscale), .raw (little-endian float32, needs
  //    samples_x / samples_z), .asc (ESRI ASCII grid; its cellsize is the spacing unless
  //    spacing_overrides_file). height = vertical_offset + vertical_scale * value for every
  //    source (png: value = v / 65535; a generator's or the array's heights are values too).
  std::string file;
  std::string file_type;                       // "" = from the extension; or "png16" | "raw_f32" | "esri_ascii"
                                               //   (scene files' terrain.source.type: any extension)
  double vertical_scale = 1.0;                 // m per unit, (0, 1e5]
  double vertical_offset = 0.0;                // m, [-1e6, 1e6]
  bool spacing_overrides_file = false;         // .asc: use `spacing` instead of the file's cellsize
  // -- or generated: "flat" | "plane" | "hills" | "noise" (docs/heightfield.md)
  std::string procedural;
  float base_height = 0.0f;                    // m (every kind)
  float slope_x = 0.0f, slope_z = 0.0f;        // plane: dh/dx, dh/dz, each [-100, 100]
  float amplitude = 1.0f;                      // m, hills / noise (>= 0)
  float wavelength = 32.0f;                    // m, hills / noise (> 0)
  std::uint32_t noise_seed = 1;                // noise
  int octaves = 4;                             // noise, [1, 16]

  double spacing = 1.0;                        // m between samples in x and z, [1e-4, 1e4]
  Vec3 origin = {0.0, 0.0, 0.0};               // m, world position of sample (0, 0) at height 0
  double soil_depth = 2.0;                     // m, bedrock = surface − soil_depth, (0, 1e4]

  // -- granular patches
  bool granular_patches = true;                // false: bodies meet the heightfield only
  MaterialDef material;
  int slots = 2;                               // simulations in the pool (patches at once), [1, 1024]
  int granules_per_slot = 16384;               // capacity of each slot, [64, 16777216]
  int shell_spheres_per_slot = 8192;           // body-shell spheres each slot holds (a body's surface every
                                               //   1.5 granule radii; add_body refuses a body needing more), [64, 1048576]
  double patch_depth = 0.4;                    // m of granules under a patch's lowest surface point, (0, soil_depth]
  double particle_scale = 1.0;                 // world size / simulated size, [1e-3, 1e3]
  int steps_per_contact = 20;                  // N: the DEM substeps at dt <= t_c / N (t_c the contact time), [2, 1000]
  int max_substeps = 0;                        // most DEM substeps in one step() before it is refused; 0 = max(64, 64 N / 20), [0, 100000]
  double sleep_speed = 0.01;                   // m/s: a patch sleeps when every granule is slower ... [0, 100]
  double sleep_time = 0.5;                     // s ... for this long, [0, 1e4]
  bool sleep_regions = true;                   // the still parts of an awake patch sleep too (CPU backend;
                                               //   docs/dem.md "Sleeping regions")
  double region_sleep_time = 0.0;              // s a part's granules stay still before it sleeps; 0: sleep_time, [0, 1e4]
  double idle_timeout = 120.0;                 // s asleep before it is turned back into heightfield, [0, 1e6]
  std::string backend = "cpu";                 // DEM backend: "cpu" (OpenMP) | "gl" (compute shaders)
  bool gl_depth_render = false;                // demotion renders on GL (true) or ray casts on the CPU (false)
  int threads = 0;                             // DEM threads, 0 = OpenMP default, [0, 1024]
  // -- contact prediction (docs/manager.md "The frame", lod): a patch is requested when a
  //    body's path reaches the terrain within lod_horizon (its ballistic path; a kinematic
  //    body's keyframes, or the motion the game gives it held for twice lod_horizon)
  double lod_horizon = 0.5;                    // s, how far ahead, (0, 10]
  double lod_margin = 0.05;                    // m, clearance that already counts as contact, [0, 100]
  double lod_apron = 1.0;                      // m, added around the contact footprint on every side, [0, 1000]
  bool lod_travel = true;                      // a body carried toward its patch's edge takes the patch along (the
                                               //   patch moved ahead by whole tile periods, its granules kept; docs/manager.md
                                               //   "A patch that travels with its body"); false: a patch abutting it ahead
  // -- the frame budget (docs/manager.md "Frame budget"): wall-clock ms a step's patches may
  //    take; new patches are promoted coarser or smaller, or wait, to keep within it (the
  //    report's "budget" says what it chose). Unset: half of each step's dt. +infinity: none
  //    (every patch at particle_scale and the full apron). Otherwise > 0.
  std::optional<double> frame_budget_ms;
  Vec3 gravity = {0.0, -9.81, 0.0};            // m/s², finite
  std::uint64_t seed = 1;                      // all randomness
};

// ---------------------------------------------------------------------------------------
// Bodies

enum class ShapeKind { Sphere, Box, Cylinder, Capsule, Mesh };

// Shapes are centred on the body's centre of mass; cylinders and capsules have their axis on
// the body's y.
struct ShapeDef {
  ShapeKind kind = ShapeKind::Sphere;
  double radius = 0.5;                         // m (sphere, cylinder, capsule), [1e-6, 1e4]
  double height = 1.0;                         // m, cylinder: total height, [1e-6, 1e4];
                                               //    capsule: between the cap centres, [0, 1e4]
  Vec3 half_extents = {0.5, 0.5, 0.5};         // m (box), each [1e-6, 1e4]
  // Mesh: a closed triangle mesh from an OBJ file, or given here (vertices: x, y, z per
  // vertex, m; triangles: 3 indices each, counter-clockwise seen from outside). The mesh is
  // re-centred on its centroid. Bullet collides with its convex hull, with the mesh's exact
  // inertia about its own axes; patches see the mesh (a shell from its signed distance field).
  // No degenerate (zero-area) triangles.
  std::string mesh_file;
  double mesh_scale = 1.0;                     // OBJ units → m, [1e-6, 1e4]
  // true: a closed solid (checked: every edge shared by two triangles, outward winding), with
  // an inside for the particle shell; false: a thin surface (a shell of its own), taken as is.
  bool solid = true;
  std::vector<float> vertices;
  std::vector<int> triangles;
};

// How a body moves (docs/api.md "Kinematic and static bodies"):
//   Dynamic    by gravity, contacts, the soil and the loads put on it
//   Kinematic  along the pose prescribed each step (set_kinematic_target, set_body_velocity,
//              set_keyframes): it pushes bodies and granules, nothing pushes it back
//   Static     never moves (it still holds up bodies and granules)
enum class BodyMotion { Dynamic, Kinematic, Static };

struct BodyDef {
  std::string name;                            // for messages and the report
  ShapeDef shape;
  BodyMotion motion = BodyMotion::Dynamic;
  double mass = 1.0;                           // kg, [1e-6, 1e9] (dynamic; ignored for kinematic and static)
  Vec3 position = {0.0, 0.0, 0.0};             // m, world (centre at or above the surface)
  Quat orientation = {1.0f, 0.0f, 0.0f, 0.0f}; // [w, x, y, z], normalised on creation (norm > 0)
  Vec3f linear_velocity = {0.0f, 0.0f, 0.0f};  // m/s, world, |v| <= 1000
  Vec3f angular_velocity = {0.0f, 0.0f, 0.0f}; // rad/s, world, |w| <= 1e4
  double friction = 0.5;                       // μ against the heightfield, [0, 10]
  double restitution = 0.1;                    // against the heightfield, [0, 1]
  double rolling_friction = 0.05;              // rolling resistance, [0, 10]
};

// A body of a Terrain: index + generation, so a removed body's handle is detected as stale.
struct BodyHandle {
  int index = -1;
  int generation = 0;
  bool valid() const { return index >= 0; }
  friend bool operator==(const BodyHandle&, const BodyHandle&) = default;
};

struct BodyState {
  Vec3 position{};                             // m, world (centre of mass)
  Quat orientation{1.0f, 0.0f, 0.0f, 0.0f};    // [w, x, y, z]
  Vec3f linear_velocity{};                     // m/s
  Vec3f angular_velocity{};                    // rad/s
};

// The granular soil's push on a body (Terrain::granular_force): the mean contact force and
// torque the patch carrying it applied over the last step.
struct BodyForces {
  Vec3f force{};                               // N, world
  Vec3f torque{};                              // N m, world, about the centre of mass
  bool carried = false;                        // a patch carried the body in the last step (else zeros)
};

// What the ground did to a body in the last step (Terrain::body_contact).
struct BodyContact {
  Vec3f granular_force{};                      // N, world: the granules' contact force on its shell, mean over the step
  Vec3f granular_torque{};                     // N m, world, about the centre of mass
  bool on_particles = false;                   // a patch carried the body in the last step (else the two above are 0)
  Vec3f heightfield_force{};                   // N, world: Bullet's heightfield contacts (normal + friction), mean over the step
  // m: the original surface height under the centre of mass (the heightfield before any patch
  // wrote it, bilinear at the centre's x, z) minus the body's lowest point; > 0 below that
  // surface, < 0 the clearance above it.
  double sinkage = 0;
  double lowest_y = 0;                         // m, world: the lowest point of the body's shape
  double original_surface_y = 0;               // m, world: the original surface under its centre
};

// A pose of a kinematic body at simulated time t (Terrain::set_keyframes).
struct Keyframe {
  double t = 0;                                // s, >= 0, strictly increasing over the list
  Vec3 position{};                             // m, world (centre of mass)
  Quat orientation{1.0f, 0.0f, 0.0f, 0.0f};    // [w, x, y, z], normalised (norm > 0)
};

// ---------------------------------------------------------------------------------------
// Joints (docs/api.md "Joints")
//
// A joint connects two bodies, or a body and the world. Its frame is given once, at creation,
// as a world anchor point and a world axis at the bodies' poses then; from then on it is fixed
// in each body. Its position (the angle about the axis, rad, or the travel along it, m) is 0 at
// creation and is that of body_b relative to body_a (with no body_b, of body_a relative to the
// world), right-handed about the axis.

enum class JointKind {
  Fixed,   // no relative motion
  Hinge,   // turns about the axis
  Slider,  // slides along the axis, no turning
};

enum class MotorMode {
  Off,       // no motor
  Velocity,  // drives the joint's rate towards `target` (rad/s, m/s)
  Position,  // a servo: moves to the position `target` (rad, m) at up to servo_speed, and holds it
};

struct JointMotor {
  MotorMode mode = MotorMode::Off;
  double target = 0;           // rad/s or m/s (Velocity), |target| <= 1e4; rad or m (Position; a hinge's in [-pi, pi])
  double max_force = 0;        // the most the motor applies: N m for a hinge, N for a slider, [0, 1e9]
  double servo_speed = 1;      // rad/s or m/s (Position), (0, 1e4]
};

// A spring towards position 0 (the pose at creation) with a damper: a suspension.
struct JointSpring {
  double stiffness = 0;        // N/m (slider) or N m/rad (hinge), [0, 1e12]; 0 = none
  double damping = 0;          // N s/m or N m s/rad, [0, 1e12]
};

struct JointDef {
  std::string name;            // for messages and the report
  JointKind kind = JointKind::Hinge;
  BodyHandle body_a;           // a live body
  BodyHandle body_b;           // another live body, or invalid (the default): body_a to the world
                               //   at least one of the two must be dynamic
  Vec3 anchor{};               // m, world, at creation
  Vec3 axis = {0.0, 0.0, 1.0}; // world, at creation (hinge, slider), non-zero; normalised
  std::optional<std::array<double, 2>> limits;  // [lower, upper], rad (hinge, within [-pi, pi]) or m; lower <= upper
  JointMotor motor;            // hinge, slider
  JointSpring spring;          // hinge, slider
};

struct JointHandle {
  int index = -1;
  int generation = 0;
  bool valid() const { return index >= 0; }
  friend bool operator==(const JointHandle&, const JointHandle&) = default;
};

// A joint after the last step.
struct JointState {
  double position = 0;         // rad (hinge, in [-pi, pi]) or m (slider), 0 at creation
  double rate = 0;             // rad/s or m/s: of body_b relative to body_a
  double force = 0;            // N m (hinge) or N (slider): what the motor, the spring and the limits
                               //   applied to body_b about / along the axis, mean over the last step
};

// ---------------------------------------------------------------------------------------
// Vehicles (docs/api.md "Vehicles")
//
// A four-wheeled vehicle made of bodies and joints: a box chassis and four cylinder wheels,
// each on one wheel joint to the chassis: it turns about the axle (motorised on the driven
// wheels), slides along the vehicle's up axis on the suspension's spring (rigid without one),
// and the front wheels' axles are steered about the up axis. Vehicle frame: x forward, y up,
// z to the right.

enum class DriveWheels { Rear, Front, All };

struct VehicleDef {
  std::string name;                            // its parts are "<name>.chassis", "<name>.wheel_fl", ...
  Vec3 position{};                             // m, world: the chassis' centre
  Quat orientation{1.0f, 0.0f, 0.0f, 0.0f};    // [w, x, y, z]: the vehicle frame in the world (norm > 0)
  Vec3 chassis_half_extents = {2.0, 0.3, 0.6}; // m (x, y, z), each (0, 1e4]
  double chassis_mass = 1500.0;                // kg, [1e-6, 1e9]
  double wheel_radius = 0.4;                   // m, (0, 1e4]
  double wheel_width = 0.3;                    // m, (0, 1e4]
  double wheel_mass = 30.0;                    // kg, [1e-6, 1e9]
  double wheel_friction = 0.9;                 // μ against the heightfield and bodies, [0, 10]
  double wheel_rolling_friction = 0.05;        // [0, 10]
  double wheelbase = 2.7;                      // m between the front and rear axles, (0, 1e4]
  double track = 1.9;                          // m between the left and right wheels' centres, (0, 1e4]
  double axle_height = -0.3;                   // m: the wheels' centres above the chassis' centre, [-1e4, 1e4]
  DriveWheels drive = DriveWheels::Rear;       // which wheels the motors turn
  double wheel_speed = 0.0;                    // rad/s: the driven wheels' target (> 0: forward), [-1e4, 1e4]
  double max_torque = 0.0;                     // N m per driven wheel, [0, 1e9]; 0: no drive (the wheels roll free)
  double steering_angle = 0.0;                 // rad of the front wheels (> 0: left), within ±max_steering_angle
  double max_steering_angle = 0.5;             // rad, [0, 1.2]
  double steering_speed = 1.0;                 // rad/s the steering turns at, (0, 1e4]
  double suspension_stiffness = 0.0;           // N/m per wheel, [0, 1e12]; 0: no suspension (rigid struts)
  double suspension_damping = 0.0;             // N s/m per wheel, [0, 1e12]
  double suspension_travel = 0.1;              // m each way from the unloaded pose, [0, 10]
};

struct VehicleHandles {
  BodyHandle chassis;
  std::array<BodyHandle, 4> wheels{};          // front left, front right, rear left, rear right
  std::array<JointHandle, 4> axles{};          // the wheels' joints: set_joint_motor drives one wheel, joint_state
                                               //   reads its spin (rad/s) and drive torque (N m)
  VehicleDef def;                              // as added
};

// ---------------------------------------------------------------------------------------
// Events, particles, heightfield data for renderers

enum class EventKind {
  Requested,  // a contact was predicted; a patch was asked for (patch = -1 until promoted)
  Promoted,   // heightfield → granules began in a pool slot (wall_ms: the fill)
  Ready,      // every granule of the patch is simulating
  Asleep,     // the patch came to rest and stopped stepping
  Woke,       // a moving body woke it
  Demoted,    // granules → heightfield; the slot is free again (wall_ms: render + write)
  // Warnings about a body (`body` names it; docs/api.md "Events"):
  TooFastToFollow,     // it crossed more than lod_apron in one step: value its speed, limit lod_apron / dt (m/s);
                       //   where it meets the ground the heightfield, not granules, may take the contact
  TooFastForGranules,  // a kinematic or static body moved into a patch faster than its granules can be
                       //   stopped: value its speed, limit 2 r sqrt(k_n / m_pt) (m/s)
  SoilDropped          // a tool a patch carried left it with granules in it (lifted more than `limit` m above
                       //   the patch's highest surface point, or out over its side): value its lowest point's
                       //   height above that point (m), granules and volume (m³, at the bed's packing) what fell
};
SANDPATCH_API const char* to_string(EventKind k);  // "promoted", ...

struct Event {
  EventKind kind = EventKind::Requested;
  int patch = -1;         // patch number, unique over the terrain's life (-1: not yet a patch)
  double time = 0;        // s, simulated time of the step it happened in
  double wall_ms = 0;     // conversion cost (promoted, demoted)
  int granules = 0;       // granules of the patch (SoilDropped: the granules the tool let go of)
  std::string body;       // the body a warning is about (its name, or "body N"); empty for the patch events
  double value = 0;       // a warning's measure: m/s (too fast), m (SoilDropped)
  double limit = 0;       // and its limit, in the same unit
  double volume = 0;      // m³ (SoilDropped)
};

// A rectangle of heightfield samples [i0, i0 + ni) × [j0, j0 + nj).
struct GridRegion {
  int i0 = 0, j0 = 0, ni = 0, nj = 0;
  bool empty() const { return ni <= 0 || nj <= 0; }
};

struct HeightfieldInfo {
  int samples_x = 0, samples_z = 0;
  double spacing = 0;     // m
  Vec3 origin{};          // m, world position of sample (0, 0) at height 0
  double min_height = 0, max_height = 0;  // m, relative to origin[1]
};

// The spheres of one live patch in the buffer particles() fills: [first, first + count).
struct ParticleGroup {
  std::size_t first = 0, count = 0;
  float fade = 1;         // fade-in in [0, 1] (Leach & Marais §5.1): 1 once the patch has run 30 frames
};

// Geometry-clipmap level selection for a terrain renderer (render/clipmap.hpp, docs/rendering.md):
// which nested grids to draw around the viewer. Pure CPU, no GL.
struct ClipmapDef {
  int n = 255;              // vertices per ring side, 2^k − 1 with k in [3, 12]
  int levels = 10;          // nested levels, [1, 24]
  float base_spacing = 1;   // m, vertex spacing of level 0 (> 0)
  int transition = 0;       // vertices over which a level morphs into the next (0 = n / 10)
  float height_factor = 2.5f;  // skip levels finer than height_factor × viewer height (0 = never)
};
struct ClipmapView {
  Vec3 viewer{};            // m, world position of the camera
  std::array<float, 16> view_proj{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};  // column-major, local → clip
                            //   (OpenGL convention; local = world − Terrain::origin()); used when cull is true
  bool cull = false;        // skip pieces outside the view frustum
};
struct ClipmapLevel {
  int level = 0;
  float spacing = 0;        // m
  int origin_x = 0, origin_z = 0;  // level coordinates of the level's min corner vertex
  int n = 0;                // vertices per side
  bool active = false, finest = false;
};
struct ClipmapPiece {
  int level = 0;
  int kind = 0;             // 0 block, 1 fix-up x, 2 fix-up z, 3 trim x, 4 trim z, 5 degenerate x, 6 degenerate z
  int gx = 0, gz = 0;       // level coordinates of the piece's min corner vertex: local (gx, gz) · spacing
  int cells_x = 0, cells_z = 0;
};
struct ClipmapSelection {
  std::vector<ClipmapLevel> levels;  // finest first
  std::vector<ClipmapPiece> pieces;  // to draw, finest level first
  std::int64_t triangles = 0;
};

// ---------------------------------------------------------------------------------------
// The terrain

class SANDPATCH_API Terrain {
 public:
  // Validates `def`, builds the heightfield, the rigid-body world and the patch pool (with the
  // pre-settled granule tile: this can take a second). Errors name TerrainDef fields.
  static Result<Terrain> create(const TerrainDef& def);

  // Movable, not copyable. A moved-from Terrain may only be destroyed or assigned to.
  Terrain(Terrain&&) noexcept;
  Terrain& operator=(Terrain&&) noexcept;
  ~Terrain();

  // ---- bodies ----
  Result<BodyHandle> add_body(const BodyDef& def);
  // The handle is stale at once; with patches the body leaves the simulation in the next step.
  // An adopted body (adopt_bullet_body) leaves at once and is given back to the game.
  Status remove_body(BodyHandle h);
  bool alive(BodyHandle h) const;
  Result<BodyState> body_state(BodyHandle h) const;
  // Teleports the body (wakes it). Position m world, orientation [w, x, y, z] (normalised).
  // Refused for a static body.
  Status set_body_transform(BodyHandle h, const Vec3& position, const Quat& orientation);
  // A dynamic body's velocities now; a kinematic body's prescribed velocities, held for every
  // following step until changed (its pose advances by them). Refused for a static body.
  Status set_body_velocity(BodyHandle h, const Vec3f& linear, const Vec3f& angular);
  // ---- kinematic bodies ----
  // The pose (m, world; [w, x, y, z]) a kinematic body reaches at the end of the next step();
  // it moves there in a straight line and a slerp over the step, at the velocities that takes,
  // which bodies and granules it meets see. Used once; the body then holds still, moves by its
  // set_body_velocity, or follows its keyframes (which take precedence over both).
  // Refused, naming the argument: a body that is not kinematic, non-finite values, a zero
  // quaternion, a lowest point below the bedrock (surface − soil_depth) at the target.
  Status set_kinematic_target(BodyHandle h, const Vec3& position, const Quat& orientation);
  // Keyframes of a kinematic body (replacing any before): its pose at simulated time t is
  // linear in the position and slerp in the orientation between the keyframes around t, the
  // first's before them and the last's after them; the next step() puts it at the pose of the
  // current time and it follows them from there. Refused, naming keyframes[k].t / .position /
  // .orientation: none given, non-finite values, times not strictly increasing or < 0, a zero
  // quaternion, a lowest point below the bedrock.
  Status set_keyframes(BodyHandle h, const std::vector<Keyframe>& keyframes);
  std::vector<BodyHandle> bodies() const;

  // ---- driving bodies ----
  // A force (N, world) at the centre of mass, or at `world_point` (m, world), which adds the
  // torque (p − c) × F; a torque (N m, world). They add up until the next step(), act over the
  // whole of it (every rigid-body substep, beside the granular patches' forces) and are then
  // cleared: call them every step for a lasting push. An impulse (N s, world) changes the
  // velocities at once: Δv = J / m, and at a world point Δω = I⁻¹ ((p − c) × J).
  // Refused, naming the argument ("apply_force.force") and its value: a stale handle,
  // a kinematic or static body ("apply_force.body"), non-finite values, a magnitude above 1e9
  // (N, N m, N s), a point farther than 1e4 m from the centre of mass.
  Status apply_force(BodyHandle h, const Vec3f& force, const Vec3* world_point = nullptr);
  Status apply_torque(BodyHandle h, const Vec3f& torque);
  Status apply_impulse(BodyHandle h, const Vec3f& impulse, const Vec3* world_point = nullptr);
  // What the granular soil did to the body in the last step: the mean contact force and
  // torque of the patch carrying it (a sleeping patch: the body's weight back); zeros and
  // carried = false when no patch carried it (on the heightfield, in the air, before the
  // first step).
  Result<BodyForces> granular_force(BodyHandle h) const;
  // Everything the ground did to the body in the last step: the granules' force and torque,
  // the heightfield's contact force, and the sinkage below the original surface (BodyContact).
  Result<BodyContact> body_contact(BodyHandle h) const;

  // ---- joints (docs/api.md "Joints") ----
  // Refused, naming the field ("JointDef.axis") and its value: a stale body handle, body_b the
  // same as body_a, no dynamic body on either side, a non-finite anchor, a zero or non-finite
  // axis, limits with lower > upper (a hinge's outside [-pi, pi]), non-finite targets, a
  // negative max_force, a negative spring. Bullet stops colliding the two bodies with each other.
  Result<JointHandle> add_joint(const JointDef& def);
  // A joint also goes when one of its bodies is removed.
  Status remove_joint(JointHandle h);
  bool alive(JointHandle h) const;
  // The joint's motor from the next step on (call it every step to drive a machine); refused
  // for a fixed joint and for the values add_joint refuses ("set_joint_motor.motor.target").
  Status set_joint_motor(JointHandle h, const JointMotor& motor);
  Result<JointState> joint_state(JointHandle h) const;

  // ---- vehicles (docs/api.md "Vehicles") ----
  // Adds the vehicle's five bodies and four joints (the same expansion as a scene file's
  // `vehicles`), driving at def.wheel_speed / max_torque and steered to def.steering_angle.
  // Refused, naming the field ("VehicleDef.wheel_radius") and its value: the ranges above,
  // wheels that would touch the chassis ("VehicleDef.track") or each other
  // ("VehicleDef.wheelbase"), a part below the bedrock or inside the terrain
  // ("VehicleDef.position"); nothing is added then.
  Result<VehicleHandles> add_vehicle(const VehicleDef& def);
  // From the next step on: the driven wheels' target speed (rad/s, > 0 forward) with at most
  // max_torque (N m each; 0: no drive), the front wheels' steering angle (rad, > 0 left, within
  // ±max_steering_angle). Refused naming "drive_vehicle.<argument>".
  Status drive_vehicle(const VehicleHandles& v, double wheel_speed, double max_torque, double steering_angle);

  // Low-level entry of sandpatch::api::bullet::adopt (include/sandpatch/bullet.hpp): use that.
  // `bt_rigid_body` is a btRigidBody*; `abi` describes the Bullet the caller was compiled
  // against and must match the library's (else an error naming btRigidBody.abi).
  struct BulletAbi {
    int scalar_bytes = 0;           // sizeof(btScalar)
    int version = 0;                // BT_BULLET_VERSION
    std::size_t rigid_body_bytes = 0;  // sizeof(btRigidBody)
  };
  Result<BodyHandle> adopt_bullet_body(void* bt_rigid_body, const std::string& name, const BulletAbi& abi);

  // ---- the step ----
  // Advances exactly dt seconds: lod, activation, dem, `substeps` rigid-body steps of
  // dt / substeps (a granular patch's force on a body acts over all of them), sleep, demotion. dt in (0, 0.1] s, substeps in [1, 1000] (the scene-file
  // rules); the DEM substeps itself below its critical step. A non-finite body state is an
  // error naming the body.
  Status step(double dt, int substeps = 1);
  // Optional, once, before the first step() (e.g. while the level loads), with the dt the
  // steps will use: the patches that bodies rest on or meet within the first frames are
  // promoted whole now, so the first frames do not pay for them. Later calls do nothing.
  Status prepare(double dt);
  double time() const;                         // s, simulated so far
  // Asks for a patch over the world rectangle [x0, x1] × [z0, z1] now (e.g. a digging tool).
  Status request_patch(double x0, double z0, double x1, double z1);
  // Turns every live patch back into heightfield now (e.g. before saving the terrain).
  Status demote_all();

  // ---- queries ----
  // Surface height (m, world) at world (x, z): bilinear in the heightfield (docs/heightfield.md),
  // clamped to the grid's edge outside it. Granules of live patches are not included.
  double height_at(double x, double z) const;
  // Unit surface normal at world (x, z) (the exact derivative of the bilinear surface).
  Vec3f normal_at(double x, double z) const;

  // ---- patches and events ----
  // Events since the last call, in the order they happened.
  std::vector<Event> poll_events();
  int active_patches() const;                  // patches holding a slot
  int granules() const;                        // live granules over all patches
  // Sphere centres and radii of every live patch: x, y, z, r per sphere (m, relative to origin()).
  void particles(std::vector<float>& xyzr) const;
  // The same spheres grouped by patch, in particles() order.
  std::vector<ParticleGroup> particle_groups() const;

  // ---- heightfield data for the game's renderer ----
  HeightfieldInfo heightfield() const;
  Vec3 origin() const;                         // m, world position of sample (0, 0) at height 0
  // Heights of `r` (m, relative to origin()[1]), nj rows of ni values, x fastest. Errors if `r`
  // is not inside the grid.
  Status read_heights(GridRegion r, std::vector<float>& out) const;
  // Regions written by demotions since the last call (redraw / re-upload these).
  std::vector<GridRegion> take_dirty_regions();
  // Clipmap levels and pieces for a viewer (errors name ClipmapDef fields).
  Status select_clipmap(const ClipmapDef& def, const ClipmapView& view, ClipmapSelection& out) const;

  // ---- report ----
  // JSON: time, bodies, patch ledger, conversions, pool, stage profile (docs/api.md).
  std::string report_json() const;
  // FNV-1a over the simulated time, every body's state, the heightfield and every patch's
  // granules: equal for two terrains made and driven the same way (determinism checks,
  // replays). Not stable across library versions.
  std::uint64_t state_hash() const;

 private:
  struct Impl;
  explicit Terrain(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandpatch::api
