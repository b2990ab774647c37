// The third reference case of `sandpatch bench tradeoff` (bench/bench_tradeoff.hpp, docs/tradeoff.md):
// a sphere (a Bullet rigid body) dropped onto a small flat heightfield terrain driven by the
// real TerrainManager (manager/terrain_manager.hpp), in the frame of manager/run.cpp (manager
// before the bodies, `substeps` Bullet steps, manager after), and the crater it leaves measured
// in the heightfield after demote_all: what a user of the library sees. The knobs only this path
// has are turned here: the scene's Bullet substeps, the slot capacity and LOD on or off.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/error.hpp"

namespace sandpatch {

struct TradeoffKnobs;

// World units (m, s, kg). Terrain: a flat square heightfield of side terrain_side at `spacing`,
// its surface at y = surface_height, soil 2 m deep; patches patch_depth deep (the manager's
// TerrainManagerDef::patch_depth). Sphere: radius R, density rho_b, released at rest with its
// lowest point drop_height above the surface at the terrain's centre (impact speed
// sqrt(2 g H)). Frames of frame_dt; `run_seconds` simulated, then every patch demoted
// (TerrainManager::demote_all) and the heightfield compared with the original:
//   Δh = new − original height per sample, binned by distance from the drop axis (bins of one
//   sample spacing; bins stop one bin short of the terrain's half side). The crater is the run of
//   bins from the axis whose mean Δh < −r_w (r_w = granule radius × particle scale: the whole
//   patch settles by about a centimetre when the impact shakes it, so "below the original
//   surface" alone runs to the patch's edge), the rim the run after it whose mean Δh > 0.
//   depth          − mean Δh of the samples within R/2 of the axis
//   crater volume  Σ −Δh × spacing² over the samples within the crater's radius
//   rim volume     Σ  Δh × spacing² over the samples of the rim's bins; rim height its largest bin mean
//   far field      mean Δh of the samples from 2 R to the last bin (the patch's settling)
// LOD off (knobs.lod = false): request_patch over the whole terrain at t = 0 (TerrainManager's
// own request path); LOD on: the manager's contact prediction places the patch, with
// lod_apron (m) around the predicted footprint. idle_timeout is beyond the run in both, so
// the only demotion is demote_all at the end.
struct DropDef {
  double sphere_radius = 0.2;        // R, m (8 granule radii of the material)
  double sphere_density = 2500.0;    // rho_b, kg/m^3 (mass 83.8 kg at R = 0.2 m)
  double drop_height = 0.3;          // H, m (2.43 m/s at impact)
  double terrain_side = 1.6;         // m (8 R)
  float spacing = 0.04f;             // m, heightfield sample spacing (R / 5)
  double surface_height = 1.0;       // m, local height of the flat surface
  double patch_depth = 0.4;          // m of granules under the surface (2 R)
  double run_seconds = 1.5;          // s simulated before demote_all
  double frame_dt = 1.0 / 60.0;      // s, the scene's simulation.dt
  // The material: the manager's defaults (GranularMaterial: r = 2.5 cm, 2650 kg/m^3, mu 0.5,
  // e 0.3, k_n 2e4 N/m).
  float granule_radius = 0.025f;     // m
  float granule_density = 2650.0f;
  float friction = 0.5f;
  float restitution = 0.3f;
  float stiffness = 2.0e4f;
  float unloading_ratio = 1.0f;      // Material::unloading_stiffness_ratio (1: linear normal spring)
  int threads = 0;                   // DEM threads, 0 = OpenMP default
  std::string tile_cache;            // TerrainManagerDef::tile_cache ("" = $SANDPATCH_TILE_CACHE or the default)
  std::uint64_t settle_seed = 0;     // 0: knobs.seed; else the tile's settling seed (TerrainManagerDef::seed)
  double after_demotion = 0;          // s of frames run after demote_all (DropResult::shift_after_demotion)
  int max_substeps = 0;              // DEM substeps a frame may take (0: the manager's default)
  bool trace = false;                // record DropResult::frames (one per frame)
};

// One frame of the sphere as Bullet has it at the frame's end (world units).
struct DropFrame {
  double t = 0;       // s, simulated, end of the frame (release at 0)
  double bottom = 0;  // m, the sphere's lowest point above the original surface (negative: below)
  double vy = 0;      // m/s, vertical velocity (up +)
  double fy = 0;      // N, vertical soil force on it over the frame (TerrainManager::soil_force)
};

struct DropResult {
  // The manager refused the run (a patch larger than the slot): its error message, naming the
  // field to raise (simulation.pool.granules_per_slot). Nothing below is measured then.
  bool refused = false;
  std::string refusal;
  double refused_at = 0;       // s, simulated time of the refusal
  double depth = 0;            // m
  double crater_volume = 0;    // m^3
  double crater_radius = 0;    // m, outer edge of the crater's bins
  double rim_volume = 0;       // m^3
  double rim_height = 0;       // m
  double far_field_dh = 0;     // m, mean Δh 2 R and more from the axis (negative: the patch settled)
  double sphere_sink = 0;      // m, sphere bottom below the original surface at the end
  double ledger_error_pct = 0; // the manager's volume ledger over the run (%)
  int granules = 0;            // peak live granules
  int patches = 0;             // promotions
  std::int64_t pool_bytes = 0; // the pool's fixed DEM capacity (TerrainManager::pool_bytes)
  double sim_seconds = 0;      // s simulated
  double wall_seconds = 0;     // s wall of the frame loop and demote_all (the cost)
  double dem_seconds = 0;      // s wall of the Dem stage within it
  double setup_seconds = 0;    // s wall of TerrainManager::create (tile from the cache or settled)
  double dt = 0;               // s, DEM substep of a 1/60 s frame (a probe simulation of the slot's definition)
  double contact_time = 0;     // s, its t_c
  bool asleep_at_end = false;  // every patch asleep at the end of the run
  std::vector<double> dh;      // m, mean Δh per radial bin (-1e300: no sample)
  // The impact, from Bullet's state at the frame ends: impact speed |vy| of the last frame
  // before the soil first pushed the sphere (m/s; sqrt(2 g H) up to a frame's free fall), the
  // largest upward speed after it (m/s, 0 when it never moved up) and their ratio, the
  // highest its lowest point came once it had stopped going down, relative to the original
  // surface (m; its lowest point at the end when it never stopped going down), and
  // the time from the first soil force until its speed stays below 1 % of the impact speed (s).
  double impact_speed = 0;
  double rebound_speed = 0;
  double rebound_ratio = 0;
  double rebound_bottom = 0;
  double settle_time = 0;
  double deepest = 0;          // m, deepest point of the sphere's bottom below the surface during the run
  // The penetration's dynamics (Ambroso et al., Phys. Rev. E 72, 041305 (2005): spheres into
  // glass beads stop after about 3 d / v0, their deceleration largest at impact and falling
  // throughout): from the first soil force (the frame before the one in which it passed 10 % of
  // the weight) until the sphere first goes down slower than 1 % of the impact speed
  // (interpolated between frame ends): that time (s), the lowest point's travel over it (m), stop_time × impact_speed /
  // stop_penetration, and when the soil's upward force on the sphere was largest, as a
  // fraction of stop_time (0: at impact). 0 when the sphere never hit or never stopped.
  double stop_time = 0;
  double stop_penetration = 0;
  double stop_time_ratio = 0;
  double peak_force_at = 0;
  std::vector<DropFrame> frames;  // def.trace
  // After demote_all: the heightfield's depth at the drop axis below the original surface (m;
  // the crater written under the body), and how far the sphere moved over after_demotion
  // seconds of frames on the heightfield alone (m; 0 when after_demotion is 0).
  double axis_depth_after = 0;
  double shift_after_demotion = 0;
};

// Errors: "DropDef.<field>" / "DropDef.knobs.<field>" for a bad definition, the heightfield's or
// the manager's own (named fields) when it cannot be built. A slot too small is not an error:
// DropResult::refused.
Result<DropResult> measure_drop(const DropDef& def, const TradeoffKnobs& knobs);

}  // namespace sandpatch
