// Angle of repose of the granule DEM: a poured pile on a rough floor and the flank fit
// (issue #3; DESIGN.md "Yardsticks": angle of repose of a pile against the material's value).
// Used by tests/particles/pile_test.cpp and meant for `sandpatch bench tradeoff`.
//
// Pile (measure_repose): a rough floor (a static shell of spheres of the granule radius on a
// square lattice of spacing 2 r, centres at y = 0, inside a disc) and granules poured in
// batches onto its centre: every `batch_interval` s a hexagonal cluster of `batch` granules
// (centre spacing = the granule's bounding diameter x 1.02, random orientations and jitter
// from `seed`) appears one bounding diameter above the highest granule, at rest, and falls.
// After the last batch the pile relaxes until every granule is slower than `rest_speed` (or
// `max_relax` s). Simulation parameters: material as given, gravity 9.81 m/s^2, frames of
// `frame_dt` s substepped by the stability guard.
//
// Flank fit (fit_flank): surface points (distance from the axis s, height h of a sphere top
// above the floor) are binned in s (bin width `bin`) and `sectors` azimuthal sectors; a
// cell's surface is its highest sphere top; a bin's surface is the mean over its non-empty
// sectors. The outer flank is the run of bins from the highest bin outwards up to the first
// bin at or below lo_frac x peak (the toe, and the one-granule carpet of granules that bounced
// off beyond it) or empty; of those, the bins below hi_frac x peak (the rounded top is left
// out) get a least-squares line h = a + b s, giving the flank angle atan(-b) (degrees) and
// the RMS residual about the line (m).
#pragma once

#include <cstdint>
#include <vector>

#include "common/error.hpp"
#include "particles/material.hpp"

namespace sandpatch {

struct SurfacePoint {
  double s = 0;      // m, distance along the flank (radius from the pile axis, or x)
  double h = 0;      // m, height of the sphere top above the floor
  int sector = 0;    // azimuthal sector in [0, sectors)
};

struct FlankFitDef {
  double bin = 0.01;      // m, bin width along s
  int sectors = 1;        // azimuthal sectors
  double lo_frac = 0.3;   // the flank ends (toe) at the first bin <= lo_frac * peak
  double hi_frac = 0.8;   // bins >= hi_frac * peak are the top, left out
  // true: only the run of bins from the peak outwards, ended by the first bin at or below
  // the toe level (the pile). false: every bin strictly between lo_frac and hi_frac of the
  // peak, wherever it is (the quasi-2D collapse of gl_repose_heavy_test).
  bool outer_run = true;
};

struct FlankFit {
  double angle_deg = 0;   // atan(-slope), degrees (positive for a surface falling with s)
  double slope = 0;       // dh/ds
  double residual = 0;    // m, RMS height residual of the fitted bins about the line
  double peak = 0;        // m, highest bin surface
  int points = 0;         // bins in the fit (< 2: no fit, angle 0)
  std::vector<double> surface;  // m, surface per bin (centre s = bin (k + 0.5)); -1 if empty
};

FlankFit fit_flank(const std::vector<SurfacePoint>& points, const FlankFitDef& def);

struct PileDef {
  Material material;                // friction is the mu of the sweep
  float particle_radius = 0.005f;   // r, m
  int granules = 400;               // poured in total
  int batch = 19;                   // granules per batch: 1, 7, 19 or 37 (hexagonal rings)
  double batch_interval = 0.1;      // s between batches
  double max_relax = 1.5;           // s, longest relaxation after the last batch
  double rest_speed = 0.005;        // m/s, max granule speed |v| + |w|(d + r) at rest
  float floor_radius = 0.2f;        // m, radius of the rough floor disc
  double frame_dt = 2e-3;           // s per step() call (substepped by the guard)
  std::uint64_t seed = 1;           // jitter and orientations (same seed, same pile)
  int threads = 0;                  // OpenMP threads; 0 = default
  FlankFitDef fit{0.01, 8, 0.3, 0.8};
};

struct ReposeResult {
  double angle_deg = 0;     // flank angle, degrees
  double residual = 0;      // m, RMS residual of the flank fit
  int fit_points = 0;       // bins in the fit
  double peak = 0;          // m, pile height (highest bin surface)
  int granules = 0;         // granules simulated
  double sim_seconds = 0;   // simulated time, s
  double wall_seconds = 0;  // wall-clock time, s
  double final_speed = 0;   // m/s, max granule speed at the end
  bool at_rest = false;     // final_speed < rest_speed
  std::vector<double> profile;  // m, surface height per fit bin (FlankFit::surface)
};

// Pours the pile and fits its flank. Errors: the simulation's (named fields) or
// "PileDef.<field>" for a bad definition.
Result<ReposeResult> measure_repose(const PileDef& def);

}  // namespace sandpatch
