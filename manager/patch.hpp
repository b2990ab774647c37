// The terrain manager's patch types (internal to manager/; see terrain_manager.hpp): a pool
// slot and the record kept for its patch, the body a patch carries, and the pre-settled tiles
// of one particle scale.
//
// A slot is split the way Box2D splits b2Body from b2BodySim: `Slot` holds what the per-frame
// stages touch (the simulation, the state, the patch's placement, the bodies it carries, the
// upload cursor and the timers), `PatchRecord` what promotion keeps for the demotion and the
// report (the heights and spheres of the fill, the ledger, conversion times, granule count).
// TerrainManager::Impl keeps them in two arrays indexed alike (Impl::slots, Impl::records).
#pragma once

#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/depth_conversion.hpp"
#include "manager/granule_tile.hpp"
#include "particles/backend.hpp"

namespace sandpatch {

enum class SlotState { Free, Filling, Active, Asleep };

// A body a patch carries: its shell in the patch's simulation.
struct Carried {
  RigidBodyId body;
  sandpatch::BodyId shell;
  bool enabled = true;
  Eigen::Vector3f v0 = Eigen::Vector3f::Zero(), w0 = Eigen::Vector3f::Zero();  // world velocities at the frame start
  // A kinematic or static body: its shell is kinematic in the DEM (it pushes the granules,
  // they do not move it), its pose set from Bullet's, and the soil's force on it is the mean
  // of the DEM's contact force over the frame's substeps (sim units, summed in f_sum, t_sum).
  bool prescribed = false;
  // A tool: a kinematic or static body, or a dynamic one joined to others (a machine's bucket
  // on its arm). Its shell, once enabled, is kept up to carry_height over the patch (what it
  // scooped is carried up), and what it lets go of with granules in it is reported
  // (coupling.cpp engage_limit, couple_before). Set every frame: joints come and go.
  bool tool = false;
  Eigen::Vector3d set_position = Eigen::Vector3d::Zero();  // m, world: the pose last given to the shell
  Eigen::Quaternionf set_orientation = Eigen::Quaternionf::Identity();
  Eigen::Vector3d f_sum = Eigen::Vector3d::Zero(), t_sum = Eigen::Vector3d::Zero();
  Eigen::Vector3f force = Eigen::Vector3f::Zero(), torque = Eigen::Vector3f::Zero();  // N, N m world: the last frame's mean
  // A dynamic body: the granules pushed its shell over the last frame (more than a thousandth
  // of its weight); one on joints that felt none and rose clear of its join height leaves the
  // patch (coupling.cpp couple_before).
  bool felt_soil = true;
};

// The particle ids [first, first + count) of body b's spheres in a simulation: ids follow the
// bodies' creation order (a patch's granules first, then the shells).
inline std::pair<std::size_t, std::size_t> particle_range(const DemBackend& sim, BodyId b) {
  std::size_t first = 0;
  for (int k = 0; k < b.index; ++k) first += std::size_t(sim.body_particle_count(BodyId{k}));
  return {first, std::size_t(sim.body_particle_count(b))};
}

// Volume of the patch's soil (m³): the heightfield's before promotion, the granules' while
// it lives, the heightfield's after demotion.
struct Ledger {
  double before = 0, active = 0, after = 0;
  double packing_fraction = 0;  // of the tile the fill was cut from (sphere volume / bulk volume)
  double target = 0;            // m³: before less the granules that left the apron, at packing_fraction
  double rise_cut = 0;          // m³: what the demotion took off the rendered rise, to the granules' packing (conserve_volume, ≤ 0)
  double correction = 0;        // m³: what it then added over the moved ground to reach target (conserve_volume)
  bool closed = false;
};

// What the frame touches: one pool slot and the patch in it.
struct Slot {
  std::unique_ptr<DemBackend> sim;
  SlotState state = SlotState::Free;
  int patch = -1;            // id of the patch in the slot
  GridRegion region;         // heightfield samples of the patch
  GridRegion apron;          // region + the band where spilled granules may rest
  Eigen::Vector3d origin;    // m, world: sim (0,0,0)
  double floor_local = 0;    // m, floor height relative to the heightfield origin
  double top_local = 0;      // m, highest surface sample of the region at promotion
  double scale = 1;          // world size / simulated size of this patch, fixed while it lives
  // A promotion in progress (filling.cpp), one part a frame: the slot reset (`cut` false),
  // the fill cut from the tile into `pending` (`cut` true), then its uploads.
  bool cut = false;
  std::unique_ptr<FillCut> cutter;  // the cut under way (null before its first part and after its last)
  GranuleShape cut_shape;           // of the tile it cuts from
  float cut_rebound = 0;            // m (sim units): that tile's GranuleTile::rebound
  float cut_packing = 0;            // that tile's packing fraction
  int predicted_granules = 0;  // the budget's prediction, until the fill is cut
  int budget_entry = -1;       // its entry in the budget's log (-1: none)
  std::vector<PlacedGranule> pending;  // granules still to upload
  std::size_t uploaded = 0;
  int fade = 0;              // frames simulated, up to fade_frames
  double asleep_for = 0;     // s asleep and untouched
  int held = 0;              // frames in a row the budget held it (not stepped; budget.cpp)
  int steps_per_contact = 0;  // the DEM's N (dt_sub <= t_c / N) if the budget lowered it; 0: the manager's
  // An idle demotion in progress, one part a frame (demotion.cpp): 0 nothing done yet, 1 the
  // fill's surface rendered, 2 the surface now rendered too; the next part writes them.
  struct Demotion {
    int stage = 0;
    int row = 0;  // the first row of the stage's CPU depth render still to do (demotion.cpp)
    int parts = 0;  // parts done so far (report: ledger.patches[].demotion_parts)
    bool releasing = false;  // released for a request (planning.cpp release_idle): held, not stepped
    HeightImage was, now;
    std::vector<float> hat_was, hat_now;  // their hat means over the apron (a staged part of its own)
    bool on_gl = false;
    double ms = 0;  // wall, the parts so far
  } demotion;
  std::vector<Carried> carried;
  // Travelling (planning.cpp extend, filling.cpp take_over): a successor filling, the slot
  // index of the patch it will take over (-1: none); that patch, the slot index of its
  // successor while it fills (it is kept, not demoted, until then); a successor whose heights
  // at promotion over its predecessor's apron wait for the predecessor's demotion (rebase), and
  // the bodies it took over (their shells are not lifted clear of the granules they rest in).
  int predecessor = -1;
  int successor = -1;
  bool superseded = false;  // taken over: held and demoted, one part a frame
  int rebase_from = -1;     // the predecessor's slot index until its demotion wrote its heights
  std::vector<std::pair<int, int>> inherited;  // (index, generation) of the bodies taken over
  bool live() const { return state != SlotState::Free; }
  bool ready() const { return state == SlotState::Active || state == SlotState::Asleep; }
  explicit Slot(std::unique_ptr<DemBackend> s) : sim(std::move(s)) {}
};

// What a patch's DEM has cost (Impl::step_patches, around DemBackend::step): wall time of the
// step calls, their substeps and sphere-steps. A sphere-step is one sphere through one
// substep; the spheres are the granules' (4 each) and the enabled shells'. The last_* fields
// are the last step call's; substep_dt and contacts_per_sphere are the last step's that ran
// substeps. Read by the report and by anything that predicts what a patch costs.
struct DemCost {
  double wall_ms = 0;                // ms, wall, all step calls
  std::int64_t substeps = 0;         // all step calls
  std::int64_t sphere_steps = 0;     // sum over step calls of spheres x substeps
  std::int64_t frames = 0;           // step calls (frames the patch was stepped awake)
  double last_wall_ms = 0;           // ms, the last step call
  std::int64_t last_frame = -1;      // the manager's frame (step_patches call) of the last step call
  int last_substeps = 0;             // the last step call's (0 if it found the DEM asleep)
  int last_spheres = 0;              // spheres of the last step call
  int last_rebuilds = 0;             // grid sorts + neighbour-list rebuilds of the last step call
  double substep_dt = 0;             // s (simulation time), the last substep length
  double contacts_per_sphere = 0;    // 2 x sphere-sphere pairs touching / spheres, at the last substep
  int patch = -1;                    // the patch these are for (a slot's record keeps the last
                                     // patch's until the next patch's first step)
  int granules = 0;                  // granules of the last step call
  double contact_sphere_steps = 0;   // sum over step calls of 2 x pairs touching at its last substep x substeps
  std::int64_t grid_rebuilds = 0;    // the DEM's grid sorts + neighbour-list rebuilds (StepStats::resorts)
  std::int64_t shell_lists = 0;      // rebuilds of the shell list alone (StepStats::shell_lists)
  double entry_sphere_steps = 0;     // sum over step calls of neighbour-list entries at its last substep x substeps
  std::int64_t sleeping_sphere_steps = 0;  // of sphere_steps, those of granules asleep in still regions (StepStats::sleeping_granules)
  // ms, wall, of the CPU backend's stages in the step calls (StepStats; 0 on the GL backend):
  // the grid sort + neighbour list, the pair pass, the body stage
  double sort_ms = 0, pair_ms = 0, body_ms = 0;
  // ms, wall, of the GL backend's step calls (StepStats; 0 on the CPU backend): issuing the
  // substeps' commands, and the frame's read-back (waiting for the GPU)
  double submit_ms = 0, readback_ms = 0;
  // sphere-steps per second of wall time in the step calls (0 before any)
  double sphere_steps_per_s() const { return wall_ms > 0 ? double(sphere_steps) / (1e-3 * wall_ms) : 0.0; }
  // contacts per sphere over all substeps, each frame's taken from its last substep
  double mean_contacts_per_sphere() const { return sphere_steps > 0 ? contact_sphere_steps / double(sphere_steps) : 0.0; }
  // neighbour-list entries (pairs within r_i + r_j + skin) per sphere, the same way
  double mean_list_entries_per_sphere() const { return sphere_steps > 0 ? entry_sphere_steps / double(sphere_steps) : 0.0; }
  // the fraction of sphere-steps whose granule slept in a still region (dem.md "Sleeping regions")
  double sleeping_fraction() const { return sphere_steps > 0 ? double(sleeping_sphere_steps) / double(sphere_steps) : 0.0; }
  // sphere-steps per second of the spheres that were awake (the work done; 0 before any)
  double awake_sphere_steps_per_s() const {
    return wall_ms > 0 ? double(sphere_steps - sleeping_sphere_steps) / (1e-3 * wall_ms) : 0.0;
  }
  // One step call of `spheres` spheres that took wall_ms and ran st.substeps substeps; its
  // stages' times are scaled by `share` (patches stepped side by side: the call's share of
  // the section's wall time over its own thread's time).
  void add(double ms, const StepStats& st, int spheres, double share = 1) {
    wall_ms += ms;
    substeps += st.substeps;
    sphere_steps += std::int64_t(spheres) * st.substeps;
    ++frames;
    last_wall_ms = ms;
    last_substeps = st.substeps;
    last_spheres = spheres;
    last_rebuilds = st.resorts;
    contact_sphere_steps += 2.0 * double(st.contacts) * st.substeps;
    grid_rebuilds += st.resorts;
    shell_lists += st.shell_lists;
    entry_sphere_steps += double(st.neighbour_entries) * st.substeps;
    sleeping_sphere_steps += 4 * std::int64_t(st.sleeping_granules) * st.substeps;
    sort_ms += 1e3 * share * st.sort_seconds;
    pair_ms += 1e3 * share * st.pair_seconds;
    body_ms += 1e3 * share * st.body_seconds;
    submit_ms += 1e3 * st.submit_seconds;
    readback_ms += 1e3 * st.readback_seconds;
    if (st.substeps > 0) {
      substep_dt = st.substep_dt;
      contacts_per_sphere = spheres > 0 ? 2.0 * double(st.contacts) / spheres : 0.0;
    }
  }
};

// What the demotion and the report read: the record of the patch in the slot of the same index.
struct PatchRecord {
  int granules = 0;                   // uploaded
  double fill_ms = 0;                 // promotion and uploads, wall
  std::vector<float> before_heights;  // heights of the slot's apron at promotion
  std::vector<float> fill_spheres;    // the granule spheres as filled (x, y, z, r; m, heightfield-local): the
                                      // demotion renders them too, so its render error cancels where nothing moved
  float fill_rise = 0;                // m, the tile's elastic rebound (GranuleTile::rebound), world
  Ledger ledger;
  DemCost cost;                       // its DEM's steps (coupling.cpp step_patches)
};

// Pre-settled tiles (granule_tile.hpp) of one particle scale, shallowest first. A fill deeper
// than a tile's vertical period would stack copies, and the seam leaves voids (measured:
// surfaces just above a seam render 0.75 d low), so a patch takes the shallowest tile that
// holds its depth, and a deeper one is settled (and kept) when none does. A tile is settled in
// simulation units, its period a whole number of heightfield cells at its scale, under
// gravity g / s.
struct TileSet {
  double scale = 1;                 // world size / simulated size
  int cells = 1;                    // heightfield cells per tile period (patch sides fall on tile walls)
  GranuleTileDef def;
  std::vector<GranuleTile> tiles;   // shallowest first
};

}  // namespace sandpatch
