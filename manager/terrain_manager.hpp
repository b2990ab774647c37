// The terrain manager (Leach & Marais §3, §5; docs/manager.md "The frame"): granular
// patches that come and go around bodies that touch the terrain.
//
// Per frame, around the Bullet step (World::step, manager/world.hpp, calls them in this order):
//   lod         predict contacts of every body within a horizon (manager/lod.hpp); requests
//               that overlap merge; a request not covered by a patch takes a pool slot, or
//               waits in a queue ordered by time to contact, then speed
//   activation  a new patch is filled from the heightfield with a pre-settled granule tile
//               (manager/granule_tile.hpp), uploaded to its slot in chunks of at most
//               fill_granules_per_frame (more when a body would land before it is ready)
//   dem         each body over an active patch has a dynamic shell in the patch; the shell
//               starts the frame with the body's Bullet state, the DEM substeps, and the mean
//               contact force and torque over the frame, m Δv/dt − m g and I Δω/dt, go to the
//               Bullet body; bodies wholly over a patch stop colliding with the heightfield
//   (bodies)    Bullet steps
//   sleep       a patch whose granules and bodies are at rest sleeps (its DEM stops)
//   demotion    a patch asleep for idle_timeout is rendered top-down into the heightfield
//               (manager/depth_conversion.hpp) and its slot returns to the pool
//
// Slots are created at start-up with fixed capacity; memory does not grow with particles.
// Coordinates: a patch's simulation runs at unit particle scale, relative to the patch
// origin (its world corner at the floor height): x_world = origin + scale · x_sim, with the
// patch's own scale (one per patch, chosen at promotion: TerrainManagerDef::scale_bands).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <nlohmann/json.hpp>
#include <vector>

#include "common/error.hpp"
#include "common/knobs.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/lod.hpp"
#include "manager/profile.hpp"

namespace sandpatch {
namespace gl {
class Context;
}

struct GranularMaterial {
  float radius = float(knobs::kGranuleRadius.def);  // m, sphere radius r of the 4 spheres of a granule (simulated)
  float density = float(knobs::kDensity.def);  // kg/m³ of the grain solid
  float friction = float(knobs::kFriction.def);  // μ
  float restitution = float(knobs::kRestitution.def);  // e
  float stiffness = float(knobs::kStiffness.def);  // k_n, N/m
  float tangential_stiffness_ratio = float(knobs::kTangentialRatio.def);  // k_t / k_n
  // Hysteretic normal spring of the patches (Material::unloading_stiffness_ratio; 1 = linear;
  // both backends; its tiles are poured with the linear spring, filling.cpp, under their own
  // cache keys).
  float unloading_stiffness_ratio = float(knobs::kUnloadingRatio.def);
};

struct TerrainManagerDef {
  GranularMaterial material;
  double particle_scale = knobs::kParticleScale.def;  // world size / simulated size (Leach & Marais §4.3)
  // N: every slot's DEM substeps at dt <= t_c / N, t_c the contact time of the lightest pair
  // (SimulationDef.accuracy_steps_per_contact; docs/dem.md: stable to about t_c / 1.7,
  // accurate from t_c / 20). Scene simulation.steps_per_contact; docs/tradeoff.md measures it.
  int steps_per_contact = int(knobs::kStepsPerContact.def);
  // Most DEM substeps per frame before the frame is refused (0 = max(64, 64 N / 20)).
  int max_substeps = int(knobs::kMaxSubsteps.def);
  // Particle scale by distance from the camera (Leach & Marais §4.3, §6.3 scenario 2: finer
  // granules near the observer, coarser far away). Empty: every patch at particle_scale.
  // Otherwise a patch is promoted at the particle_scale of the first band whose max_distance
  // (m) reaches the 3-D distance from `camera` to the centre of its request on the surface
  // (beyond the last band: the last band's), and keeps it while it lives (Leach & Marais: the
  // resolution is locked at initialisation); a patch asked for ahead of a body keeps the scale of the one it is in.
  // max_distance strictly ascending. Each scale settles its own tile at start-up.
  struct ScaleBand {
    double max_distance = 0;                   // m
    double particle_scale = 1;
  };
  std::vector<ScaleBand> scale_bands;
  Eigen::Vector3d camera = Eigen::Vector3d::Zero();  // m, world; TerrainManager::set_camera moves it
  int slots = int(knobs::kSlots.def);          // simulations in the pool
  int granules_per_slot = int(knobs::kGranulesPerSlot.def);  // capacity of each slot (granules)
  int shell_particles_per_slot = 8192;         // capacity of each slot for body-shell spheres
  double patch_depth = knobs::kPatchDepth.def; // m of granules under the lowest surface point of a patch
  double soil_depth = knobs::kSoilDepth.def;   // m, bedrock = surface − soil_depth (patches stop there)
  // m, heightfield-local: a flat bedrock (scene terrain.bedrock_height; -inf = none). The
  // bedrock under a sample is the higher of surface − soil_depth and min(surface, this): a
  // surface below it is bare rock. A patch's floor is at or above the bedrock everywhere in
  // its region, and a region with no soil above it gets no patch (docs/extremes.md).
  double bedrock_height = -std::numeric_limits<double>::infinity();
  double sleep_speed = knobs::kSleepSpeed.def; // m/s, a patch sleeps when everything is slower ...
  double sleep_time = knobs::kSleepTime.def;   // s, ... for this long
  // The still parts of an awake patch sleep by the same rule, column by column of the bed (the
  // CPU backend's SimulationDef::sleep_regions; the GL backend steps every granule).
  bool sleep_regions = true;
  double region_sleep_time = knobs::kRegionSleepTime.def;  // s, still this long a region may sleep (0: sleep_time)
  double idle_timeout = knobs::kIdleTimeout.def;  // s asleep before demotion (Leach & Marais: two minutes)
  LodDef lod;                                  // contact prediction
  // The frame budget (docs/manager.md "Frame budget"): wall-clock ms a frame's patches may
  // take. A new patch is promoted at the finest particle scale and widest extent (its scale
  // × 1, 1.5, 2, 3, 4; the apron ×1 or ×½) whose predicted DEM cost, with the patches already
  // awake, fits in 80 % of it (the rest is the frame's other stages); a request that fits
  // nowhere waits in the queue while other patches live, and goes ahead at the coarsest rung
  // when none does (counted as an overrun). Infinity: no budget (every patch as requested).
  // frame_budget_fraction > 0 sets the budget to that fraction of each frame's dt instead.
  double frame_budget_ms = std::numeric_limits<double>::infinity();
  double frame_budget_fraction = 0;
  // The budget's cost model pinned (both > 0): a DEM frame costs n_sub (substep_ms + sphere_ns
  // 1e-6 × spheres) ms, never measured, so its choices are the same on every machine (tests,
  // replays). 0: measured at creation and followed while running (budget.cpp).
  double budget_substep_ms = 0, budget_sphere_ns = 0;
  int fill_granules_per_frame = 4096;          // upload bound per frame
  int fade_frames = 30;                        // frames over which a new patch fades in
  int depth_resolution = 1024;                 // most texels per side of the demotion depth render ...
  // ... which takes this many texels per granule sphere radius over the patch's apron (a
  // sphere's cap is 8 texels across; the heightfield sample's hat mean averages thousands):
  // a 5 m apron of r = 4 cm granules renders 500² texels, not 1024². 0: always depth_resolution.
  double depth_texels_per_radius = 4;
  double surface_probe = 2.0;                  // probe radius of the rendered surface, × sphere radius (depth_conversion.hpp)
  bool use_gl = true;                          // depth render on GL (else, or if no context, on the CPU)
  // On-disk cache of pre-settled granule tiles (manager/tile_cache.hpp): "" = the default
  // ($SANDPATCH_TILE_CACHE, else $XDG_CACHE_HOME/sandpatch/tiles, else ~/.cache/sandpatch/tiles),
  // "off" = none, anything else = that directory. A tile read back is bit-identical to a settled one.
  std::string tile_cache;
  // Told what start-up (and a deeper tile later) is settling and how far: `what` names the
  // tile, done_s of at most max_s simulated seconds (settling stops earlier once at rest),
  // wall_s since it began. The run's progress line prints it (docs/cli.md).
  std::function<void(const std::string& what, double done_s, double max_s, double wall_s)> on_settle;
  std::string backend = "cpu";                 // DEM backend of the pool: cpu (OpenMP) or gl (compute shaders)
  int threads = int(knobs::kThreads.def);      // DEM threads, 0 = OpenMP default
  Eigen::Vector3d gravity{0.0, -9.81, 0.0};    // m/s²
  std::uint64_t seed = 1;
};

// The patches' events, and three warnings about a body (docs/api.md "Events"):
//   TooFastToFollow     a body crossed more than lod.apron in one frame (World::step): value its
//                       speed, limit lod.apron / dt (m/s); once each time it goes over
//   TooFastForGranules  a kinematic or static body moved into a patch faster than its granules
//                       can be stopped (coupling.cpp): value its speed, limit 2 r sqrt(k_n / m_pt)
//                       (m/s); once each time it goes over
//   SoilDropped         a tool a patch carried left it with granules in it (lifted above
//                       carry_height, or out over the patch's side): value the height (m) of its
//                       lowest point above the patch's highest surface point, limit carry_height
//                       (m), granules the granules it held, volume their bulk volume (m³) at the
//                       bed's packing
enum class PatchEventKind { Requested, Promoted, Ready, Asleep, Woke, Demoted, TooFastToFollow, TooFastForGranules, SoilDropped };
const char* to_string(PatchEventKind k);

struct PatchEvent {
  PatchEventKind kind;
  int patch = -1;
  double time = 0;        // s, simulated
  double wall_ms = 0;     // conversion cost (promotion: fill; demotion: render + write)
  int granules = 0;
  std::string body;       // the body a warning is about (its name, or "body N")
  double value = 0, limit = 0;  // a warning's measure and its limit (above)
  double volume = 0;      // m³ (SoilDropped)
};

// A body's particle shell at particle scale `scale` (sim units): its surface sampled every
// 1.5 granule radii, at most def.shell_particles_per_slot spheres (else an error naming
// simulation.pool.shell_spheres_per_slot and the count needed).
Result<std::vector<Eigen::Vector3f>> scaled_shell(const TerrainManagerDef& def, RigidShape shape, double scale);
// Whether a body of this shape fits a slot's shell capacity at the finest particle scale a
// patch may have (particle_scale, or the finest scale band).
Status check_shell(const TerrainManagerDef& def, const RigidShape& shape);

class TerrainManager {
 public:
  // `hf` and `world` must outlive the manager. Builds the pre-settled granule tile and the
  // pool; errors name the TerrainManagerDef field or the capacity.
  static Result<std::unique_ptr<TerrainManager>> create(const TerrainManagerDef& def, Heightfield& hf,
                                                        BulletWorld& world);
  ~TerrainManager();

  // Before the Bullet step: lod, activation, dem (forces handed to the bodies).
  Status before_bodies(double time, double dt, Profile& profile);
  // After the Bullet step: sleep, demotion.
  Status after_bodies(double time, double dt, Profile& profile);
  // Before the first frame (start-up, e.g. while a game loads a level): the lod and activation
  // stages at `time`, repeated while a body needs a patch at once, so the patches bodies rest
  // on or are about to meet are ready and the first frames do not promote them. Optional.
  Status prepare(double time, double dt, Profile& profile);
  // Requests a patch over the world rectangle [x0, x1] × [z0, z1] now, whether or not a body
  // is coming (e.g. a digging tool about to act); it is queued like a predicted contact.
  void request_patch(double x0, double z0, double x1, double z1, double time);
  // A kinematic body's planned path, known ahead (World hands over its keyframes' when it
  // enters): its world bounds (m) at times t (s, increasing). The lod stage asks for one patch
  // over the stretch of the path that works the ground, instead of predicting the body's
  // contacts ballistically, so the granules it carries never cross a patch's edge
  // (docs/manager.md "Tools on a planned path"). An empty path forgets the body's.
  // `extrapolated`: the path is a game-driven tool's motion held for lod.horizon, handed
  // over again every frame (World look_ahead), not keyframes known ahead.
  struct PathPose {
    double t = 0;
    Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  };
  void set_planned_path(RigidBodyId body, std::vector<PathPose> path, bool extrapolated = false);
  // Appends an event (World's warnings about bodies, TooFastToFollow) to events().
  void add_event(PatchEvent e);
  // Moves the camera the scale bands are measured from (m, world); patches already live keep
  // their scale.
  void set_camera(const Eigen::Vector3d& position);
  // ms the frame budget allows a frame of dt seconds (infinity: no budget).
  double budget_ms(double dt) const;
  // Whether a body of this shape fits a slot's shell capacity at the finest particle scale
  // a patch may have (particle_scale, or the finest scale band): an error naming
  // simulation.pool.shell_spheres_per_slot and the spheres it needs, else Ok. Checked when a
  // body is added, so a body too big for the pool is bad input, not a failure mid-run.
  Status check_shell(const RigidShape& shape) const;
  // Demotes every patch now (end of a run that wants the final terrain).
  Status demote_all(double time, Profile& profile);

  // The soil's force on a body in the last frame's dem stage: the mean contact force (N,
  // world) and torque (N m about its centre of mass, world) its carrying patch handed Bullet
  // (a sleeping patch: the body's weight back). False, and nothing written, when no patch
  // carried it.
  bool soil_force(RigidBodyId body, Eigen::Vector3f* force, Eigen::Vector3f* torque) const;

  int active_patches() const;
  int ready_patches() const;                   // filled and simulating (or asleep)
  int granules() const;                        // live granules over all patches
  int queued_requests() const;
  int filling_patches() const;                 // promoted, granules still uploading
  int asleep_patches() const;                  // filled and asleep (DEM stopped)
  // Bytes of the pool's fixed DEM capacity, allocated at start-up and constant for the run:
  // slots × (max_particles × per-particle bytes + max_bodies × per-body bytes), the per-item
  // bytes summed over particles/fields.hpp's field lists (4-byte components); with
  // max_particles = 4 granules_per_slot + shell_particles_per_slot and max_bodies =
  // granules_per_slot + 64, plus the fills' spheres (16 floats a granule of capacity, reserved
  // at start-up). An estimate of the state arrays only: the neighbour grid, contact
  // history and backend scratch buffers are not counted.
  std::int64_t pool_bytes() const;
  std::uint64_t state_hash() const;            // over every patch's DEM state
  // Every live patch (promoted, not yet demoted), in slot order.
  struct PatchInfo {
    int patch = -1;                            // id (PatchEvent::patch)
    GridRegion region;                         // heightfield samples it covers
    GridRegion apron;                          // region + the band its demotion may write
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();  // m, world: its simulation's (0, 0, 0)
    double particle_scale = 1;                 // world size / simulated size, fixed while it lives
    double granule_radius_world = 0;           // m, sphere radius of its granules as the world sees them
    int steps_per_contact = 20;                // N of its DEM (dt <= t_c / N)
    int granules = 0;                          // uploaded
    bool ready = false;                        // filled (simulating or asleep)
    bool asleep = false;
    // Its DEM's last step call (0 when it has not stepped since its promotion): substeps,
    // spheres (granules' and enabled shells') and wall ms; `stepped`: that call was in the last
    // frame (false for a patch asleep, filling, or held by the frame budget).
    int last_substeps = 0, last_spheres = 0;
    int last_rebuilds = 0;  // its grid sorts + neighbour-list rebuilds in that call
    double last_step_ms = 0;
    bool stepped = false;
  };
  std::vector<PatchInfo> patches() const;
  const std::vector<PatchEvent>& events() const;
  // The work of the last frame (before_bodies + after_bodies), counted, not timed: what
  // the per-frame caps bound (docs/manager.md "No frame does a whole patch's work").
  struct FrameWork {
    int conversion_parts = 0;   // parts of promotions and demotions run (slot reset, fill cut,
                                // upload chunk, demotion part): at most 1 but for urgent_fills
    int urgent_fills = 0;       // patches finished at once because a body would reach them within two frames
    int promotions = 0;         // fills cut from a tile (a promotion's second part)
    int granules_filled = 0;    // granules cut from a tile into a patch's fill (pending)
    int granules_uploaded = 0;  // granules added to a slot's DEM
    int ready = 0;              // patches whose upload completed
    int demotion_parts = 0;     // parts of a demotion run (render of the fill, render now, write)
    int depth_renders = 0;      // depth renders (of the two renders a demotion makes)
    int demotions = 0;          // patches demoted (slot freed)
    int wakes = 0;              // patches that woke
    int patches_stepped = 0;    // DEM step calls
    int side_by_side = 0;       // of those, stepped side by side, one thread each (0: one after another)
    std::int64_t substeps = 0;      // DEM substeps, all patches
    std::int64_t sphere_steps = 0;  // spheres × substeps, all patches
  };
  const FrameWork& last_frame_work() const;
  // Sphere centres and radii of every live patch (x, y, z, r; m, world relative to the
  // heightfield origin) with each patch's fade-in factor, for rendering.
  void particles(std::vector<float>& xyzr) const;
  // The spheres of the bodies' shells enabled in the live patches (x, y, z, r; m, world), for
  // a debug overlay (docs/rendering.md "Bodies": `--shells`).
  void shell_spheres(std::vector<double>& xyzr) const;
  // The same spheres grouped by patch, in the order particles() writes them: each group's
  // sphere count and fade-in factor in [0, 1] (1 after fade_frames frames of simulation).
  std::vector<std::pair<std::size_t, float>> particle_groups() const;
  // Live patches' spheres as they sit on the GPU (GL backend only; empty on the CPU backend):
  // buffer (vec4 pos[] = xyz, radius in sim units), sphere count, the patch origin (m, world),
  // particle scale and fade-in. Drawn straight from the simulation's buffer, no CPU copy.
  struct GpuParticles {
    unsigned buffer = 0;
    std::int64_t count = 0;             // spheres in the buffer (granules' and shells')
    long long id_offset = -1;           // bytes to their int32 ids in the buffer (GlSimulation::particle_id_offset)
    std::int64_t granule_spheres = 0;   // the granules' spheres: ids 0 .. granule_spheres - 1
    Eigen::Vector3d origin = Eigen::Vector3d::Zero();
    float scale = 1, fade = 1;
  };
  std::vector<GpuParticles> gpu_particles() const;
  // The GL context of the GL backend (nullptr on the CPU backend): GPU particle buffers can
  // only be drawn by a renderer made in this context.
  gl::Context* gl_context() const;
  // Heightfield regions written by demotions since the last call (for renderers' caches).
  std::vector<GridRegion> take_dirty_regions();
  // ledger, conversions, pool, tile: the run report's sections (docs/cli.md).
  nlohmann::ordered_json report() const;

 private:
  TerrainManager() = default;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandpatch
