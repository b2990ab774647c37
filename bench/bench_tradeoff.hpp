// `sandpatch bench tradeoff` (bench/bench_tradeoff.cpp, docs/tradeoff.md): the knobs users turn
// (particle scale, DEM dt relative to the contact time, patch size, backend, Bullet substeps,
// slot capacity, LOD on or off) swept over three fixed reference cases: the angle of repose of a
// poured pile, the crater a dropped sphere leaves in a granular bed (straight on the DEM), and
// the crater a Bullet sphere leaves in a heightfield terrain driven by the TerrainManager
// (bench/tradeoff_drop.hpp); per setting the wall time, the real-time factor and the error
// against the finest setting of the sweep; the Pareto front of error against cost.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/error.hpp"
#include "particles/material.hpp"
#include "particles/math.hpp"

namespace sandpatch {

enum class TradeoffCase { Pile, Crater, Drop };
const char* to_string(TradeoffCase c);

// The knobs of one setting.
struct TradeoffKnobs {
  // Particle scale s (Leach & Marais §4.3; scene simulation.particle_scale): the simulation runs
  // granules of the material's radius r; the world sees them s times larger, so a fixed world
  // volume holds 1/s^3 as many granules. s = 1 is the material as given.
  double particle_scale = 1.0;
  // N: the DEM substep is dt = t_c / N (t_c the contact time of the lightest pair; docs/dem.md:
  // stable near t_c / 1.7, accurate from t_c / 20). SimulationDef.accuracy_steps_per_contact.
  int steps_per_contact = 20;
  // Crater only: side of the square patch (granular bed, side walls) in sphere radii R. The slot
  // capacity a patch needs follows from it (granules reported per setting).
  double patch_radii = 8.0;
  std::string backend = "cpu";  // crater only: "cpu" (OpenMP) or "gl" (compute shaders)
  std::uint64_t seed = 1;       // bed lattice / pour jitter and orientations; drop: the tile's settling seed
  // Drop only (bench/tradeoff_drop.hpp, through the TerrainManager):
  // Bullet steps per frame (scene simulation.substeps): run.cpp steps the bodies `substeps`
  // times by dt / substeps (BulletWorld::step_frame) after the manager handed them the patch's
  // mean contact force, which acts over every substep.
  int substeps = 1;
  // Slot capacity (scene simulation.pool.granules_per_slot). A patch that needs more is refused
  // by the manager (an error naming the field): that setting's outcome is "refused".
  int granules_per_slot = 16384;
  // LOD on: patches where the manager predicts contacts, lod_apron m around the footprint
  // (TerrainManagerDef::lod.apron); off: the whole terrain as particles from t = 0
  // (request_patch over it), no demotion until the end in either.
  bool lod = true;
  double lod_apron = 0.2;       // m, LOD on only
};

struct TradeoffSetting {
  std::string id;               // unique, e.g. "crater_s1.5_n20_p8_cpu", "drop_s1_n20_sub1_lodoff_slot16384"
  TradeoffCase kind = TradeoffCase::Pile;
  TradeoffKnobs knobs;
  bool reference = false;       // the finest setting of its case: errors are measured against it
  // A repeat of a setting with another seed: its error is the case's noise floor (differences
  // below it are the chaos of granular flow, not the knob).
  bool noise = false;
};

enum class TradeoffSweep { Quick, Default, Full };
const char* to_string(TradeoffSweep s);
// The settings of a sweep, reference first within each case. Quick: small piles and beds (a
// test); Default: a few minutes on 2 cores; Full: finer scales and more steps per contact.
std::vector<TradeoffSetting> tradeoff_sweep(TradeoffSweep sweep);
// The drop case's definition for the sweep (Quick: a shorter run).
struct DropDef;
DropDef tradeoff_drop_def(TradeoffSweep sweep);
// Pile size (granules) at particle scale 1 for the sweep; 1/s^3 of it at scale s.
int tradeoff_pile_granules(TradeoffSweep sweep);

// Marks the settings no other setting dominates: i is dominated when some j has cost_j <= cost_i
// and error_j <= error_i with one of them strictly smaller. Non-finite entries are dominated.
std::vector<bool> pareto_front(const std::vector<double>& cost, const std::vector<double>& error);

// ---- crater: a sphere dropped into a granular bed ----
// World units unless said. The bed: granules of the material's radius (sim units) poured on a
// loose lattice into a walled box of side patch_radii R / s and settled (depth bed_depth_radii
// R / s after settling, sim units); a sphere of radius R and density rho_b falls from
// drop_height onto its centre (released one granule radius above the surface at the speed
// sqrt(2 g H)). The sim runs the mapping of particles/scale.hpp: sizes / s, gravity g / s,
// speeds / s, the sphere's density kept (mass = rho_b x its simulated volume).
// Surface: granule sphere tops binned by distance from the impact axis (bins of bin_radii R) in
// 8 sectors, a cell's surface its highest top, a bin's the mean over its non-empty sectors
// (fit_flank of particles/pile.hpp), before the drop and impact_seconds after it; Δh = after −
// before per bin. The crater is the run of bins from the axis out with Δh < 0: depth = max −Δh,
// volume = Σ −Δh × bin area; the rim is the run of bins after it with Δh > 0: volume Σ Δh × bin
// area, height max Δh. Bins stop half a bin short of the patch wall.
struct CraterDef {
  double sphere_radius = 0.04;       // R, m (8 granule sphere radii at particle scale 1)
  double sphere_density = 2500.0;    // rho_b, kg/m^3
  double drop_height = 0.1;          // H, m: impact speed sqrt(2 g H)
  double bed_depth_radii = 2.0;      // settled bed depth, x R
  double impact_seconds = 0.3;       // s simulated after release
  double bin_radii = 0.5;            // surface bin width, x R
  float granule_radius = 0.005f;     // r, m (sim units): the material's granule sphere radius
  Material material;                 // DEM contact material (default: the peer's, mu = 0.5)
  TradeoffKnobs knobs;               // particle_scale, steps_per_contact, patch_radii, backend, seed
  // Settle a bed of this side (x R, >= knobs.patch_radii) and cut the patch from its centre (the
  // manager cuts patches from pre-settled tiles the same way); 0 = the patch itself.
  double settle_patch_radii = 0;
  int threads = 0;                   // OpenMP threads, 0 = default
  // Record CraterResult::frames, one per frame of frame_dt, with the energy ledger on (CPU
  // backend only; Simulation::set_energy_ledger).
  bool trace = false;
  double frame_dt = 1.0 / 120.0;     // s per step() of the impact
};

// One frame of the impact straight on the DEM (world units, energies in J of the simulation:
// at particle scale 1 the world's). Energies relative to the release.
struct CraterFrame {
  double t = 0;           // s since release
  double bottom = 0;      // m, sphere's lowest point above the mean surface around the axis
  double vy = 0;          // m/s, sphere's vertical velocity
  double body_kinetic = 0, body_potential = 0;  // J, sphere (potential: gravity, relative)
  double bed_kinetic = 0, bed_potential = 0;    // J, granules (potential: gravity, relative)
  double elastic = 0;     // J, energy in the contact springs (normal and tangential; relative)
  double elastic_tangential = 0;  // J, of which in the tangential springs (relative)
  double normal_damping = 0, friction = 0;      // J dissipated since the release
};

struct CraterResult {
  double depth = 0;           // m
  double crater_volume = 0;   // m^3
  double crater_radius = 0;   // m, outer edge of the crater run
  double rim_volume = 0;      // m^3
  double rim_height = 0;      // m
  int granules = 0;           // granules in the patch (the slot capacity it needs)
  int spheres = 0;            // DEM spheres, granules' and the sphere's shell
  double sim_seconds = 0;     // s simulated in the timed impact
  double wall_seconds = 0;    // s wall of the impact (the cost)
  double setup_seconds = 0;   // s wall of building and settling the bed (not in the cost)
  double dt = 0;              // s, DEM substep
  double contact_time = 0;    // s, t_c of the lightest pair
  double final_speed = 0;     // m/s world, fastest granule at the end
  double sphere_sink = 0;     // m, sphere bottom below the original mean surface at the end
  std::vector<double> dh;     // m per bin (Δh), -1e300 where a bin was empty
  std::vector<CraterFrame> frames;  // CraterDef::trace
};

// Settled beds kept between calls of one sweep (same scale, seed and settled size): granule
// poses (sim units) and the wall seconds their settling took.
struct SettledBed {
  double particle_scale = 1, patch_radii = 0;
  std::uint64_t seed = 0;
  std::vector<Vec3> position;
  std::vector<Quat> orientation;
  double settle_seconds = 0;
};
struct CraterBeds {
  std::vector<SettledBed> beds;
};

// Builds (or takes from `beds`), settles, drops and measures. Errors: the simulation's (named
// fields), the GL context's (field "backend"), or "CraterDef.<field>" for a bad definition.
Result<CraterResult> measure_crater(const CraterDef& def, CraterBeds* beds = nullptr);

// ---- the bench ----
struct BenchTradeoffArgs {
  TradeoffSweep sweep = TradeoffSweep::Default;
  int threads = 0;              // 0 = all cores
  bool gl = true;               // run the gl settings when a GL context can be made
  std::string out_dir;          // "" = out/bench_tradeoff_<sweep>
  std::string plot_script;      // "" = no plot (scripts/plot_tradeoff.py)
  bool json = false;
};
std::string check_bench_tradeoff_args(const BenchTradeoffArgs& args);
// Writes OUT/tradeoff.csv (one row a setting), OUT/tradeoff.json (everything) and, with a plot
// script, OUT/tradeoff.png. With json the last stdout line is one JSON object:
// {"bench": "tradeoff", "csv": ..., "plot": ... or null, "settings": [{"id", "case", knobs...
// (substeps, granules_per_slot, lod, lod_apron_m: null outside the drop case), "outcome" (ok,
// refused, skipped), "wall_s", "real_time_factor", "error", "pareto", "refused" (the manager's
// message), ...}], ...}. A refused drop setting is an outcome, not a failure. Exit: 0 ok, 1
// failure, 2 bad input.
int run_bench_tradeoff(const BenchTradeoffArgs& args);

}  // namespace sandpatch
