// Angle of repose of the granule DEM: a poured pile on a rough floor and the flank fit
// (the angle of repose of a pile against the material's value).
// Used by tests/particles/pile_test.cpp and meant for `sandpatch bench tradeoff`.
//
// Pile (measure_repose): a rough floor (a static shell of spheres of the granule radius on a
// square lattice of spacing 2 r, centres at y = 0, inside a disc) and granules poured in
// batches onto its centre: every `batch_interval` s a hexagonal cluster of `batch` granules
// (centre spacing = the granule's bounding diameter x 1.02, random orientations and jitter
// from `seed`) appears one bounding diameter above the highest granule, at rest, and falls.
// After the last batch the pile relaxes until every granule on the disc is slower than
// `rest_speed` (or `max_relax` s); granules that rolled off onto the bedrock are not the
// pile. Simulation parameters: material as given, gravity 9.81 m/s^2, frames of `frame_dt` s
// substepped by the stability guard.
//
// Flank fit (fit_flank): surface points (distance s from the pile's axis, the vertical through
// the centroid of the granules on the disc; height h of a sphere top above the rough layer)
// are binned in s (bin width `bin`) and `sectors` azimuthal sectors; a
// cell's surface is its highest sphere top; a bin's surface is the mean over its non-empty
// sectors. The outer flank is the run of bins from the highest bin outwards up to the first
// bin at or below lo_frac x peak (the toe, and the one-granule carpet of granules that bounced
// off beyond it) or empty; of those, the bins below hi_frac x peak (the rounded top is left
// out) get a least-squares line h = a + b s, giving the flank angle atan(-b) (degrees) and
// the RMS residual about the line (m). The pile's profile is concave (rounded top, spread
// toe), so the angle depends on the band: 20-80 % of the peak (the default) leaves both out,
// 15-85 % already reaches into the toe (docs/dem.md has the measurements that chose it).
// Points with s > 1e6 bins give no fit (angle 0, points 0).
//
// Cone fit (fit_cone_area, the angle measure_repose reports): no axis and no profile. The
// surface map z(x, z) is the highest sphere centre within `reach` of each cell (a cell of
// `cell` m; the dilation closes the gaps between surface spheres and moves every contour out
// by the same reach, which does not change a slope); A(z) is the area where the surface lies
// above the level z, and r(z) = sqrt(A(z) / pi) the radius of a disc of that area. A cone of
// angle a has r(z) = (H - z) / tan a for every cross-section shape and position, so a
// least-squares line z = c + b r(z) over `levels` levels from lo_frac to hi_frac of the
// highest sphere H gives the angle atan(-b). Every surface cell of every azimuth contributes
// to every level, and a bump moves a level's area by its own area only. Seed-to-seed standard
// deviation at mu = 0.5, six seeds: 1.20 deg against the flank fit's 1.85 (800 granules), 2.4
// against 3.3 (400); over the 15 piles of the mu sweep 1.25 against 1.30 (docs/dem.md
// "Angle of repose").
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <vector>

#include "common/error.hpp"
#include "particles/dem.hpp"
#include "particles/material.hpp"
#include "particles/math.hpp"

namespace sandpatch {

struct SurfacePoint {
  double s = 0;      // m, distance along the flank (radius from the pile axis, or x)
  double h = 0;      // m, height of the sphere top above the floor
  int sector = 0;    // azimuthal sector in [0, sectors)
};

struct FlankFitDef {
  double bin = 0.01;      // m, bin width along s
  int sectors = 1;        // azimuthal sectors
  double lo_frac = 0.2;   // the flank ends (toe) at the first bin <= lo_frac * peak
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

struct ConeFitDef {
  double cell = 0.0025;   // m, surface-map cell
  double reach = 0.01;    // m, a sphere centre raises the cells within this horizontal distance
  double lo_frac = 0.2;   // lowest level, fraction of the highest sphere H (above the carpet)
  double hi_frac = 0.8;   // highest level (below the rounded top)
  int levels = 31;        // levels, evenly spaced
};

struct ConeFit {
  double angle_deg = 0;   // atan(-slope), degrees
  double slope = 0;       // dz/dr
  double residual = 0;    // m, RMS level residual about the line
  double height = 0;      // m, highest sphere centre H
  int levels = 0;         // levels in the fit (< 2: no fit, angle 0)
};

// points: sphere centres (x, height, z) in m, heights above the floor; those with
// x^2 + z^2 > radius^2 are left out (rolled off the disc).
ConeFit fit_cone_area(const std::vector<Vec3>& points, double radius, const ConeFitDef& def);

struct PileDef {
  Material material;                // friction is the mu of the sweep
  float particle_radius = 0.005f;   // r, m
  int granules = 400;               // poured in total
  int batch = 37;                   // granules per batch: 1, 7, 19 or 37 (hexagonal rings)
  double batch_interval = 0.1;      // s between batches
  double max_relax = 3.0;           // s, longest relaxation after the last batch
  double rest_speed = 0.005;        // m/s, max granule speed |v| + |w|(d + r) at rest
  float floor_radius = 0.2f;        // m, radius of the rough floor disc
  double frame_dt = 2e-3;           // s per step() call (substepped by the guard)
  std::uint64_t seed = 1;           // jitter and orientations (same seed, same pile)
  int threads = 0;                  // OpenMP threads; 0 = default
  FlankFitDef fit{0.01, 8, 0.2, 0.8};
  ConeFitDef cone;
};

struct ReposeResult {
  double angle_deg = 0;     // angle of repose, degrees: the cone fit (fit_cone_area)
  double residual = 0;      // m, RMS residual of the cone fit
  int fit_points = 0;       // levels in the cone fit
  double flank_angle_deg = 0;  // the flank fit's angle (fit_flank), degrees, for comparison
  double flank_residual = 0;   // m, RMS residual of the flank fit
  int flank_points = 0;        // bins in the flank fit
  double peak = 0;          // m, pile height (highest bin surface)
  int granules = 0;         // granules simulated
  double sim_seconds = 0;   // simulated time, s
  double wall_seconds = 0;  // wall-clock time, s
  double final_speed = 0;   // m/s, max granule speed |v| + |w|(d + r) on the disc at the end
  bool at_rest = false;     // final_speed < rest_speed
  std::vector<double> profile;  // m, surface height per fit bin (FlankFit::surface)
  std::vector<Vec3> spheres;    // m, granule sphere centres at the end (floor at y = 0)
  double axis_x = 0, axis_z = 0;  // m, the pile's axis (centroid of the granules on the disc)
};

// Pours the pile and fits its flank on the CPU backend. Errors: the simulation's (named
// fields) or "PileDef.<field>" for a bad definition.
Result<ReposeResult> measure_repose(const PileDef& def);

// The parts of measure_repose, for other backends (tests/particles/gpu: the GL backend):
Status validate(const PileDef& def);                 // errors name "PileDef.<field>"
SimulationDef pile_simulation_def(const PileDef& def);  // bounds, bedrock, capacities
ShellDef pile_floor(const PileDef& def);             // the rough floor disc (static shell)
// Pours the pile into `sim`, an empty simulation created from pile_simulation_def(def), and
// fits its flank. Sim: any type with the CPU Simulation's methods (Simulation, GlSimulation).
template <class Sim>
Result<ReposeResult> pour_pile(Sim& sim, const PileDef& def);

namespace pile_detail {
Quat random_orientation(std::uint64_t& s);
double uniform01(std::uint64_t& s);
void fit_pile(const PileDef& pd, const std::vector<Vec3>& positions, int floor_spheres, ReposeResult& out);
}  // namespace pile_detail

template <class Sim>
Result<ReposeResult> pour_pile(Sim& sim, const PileDef& pd) {
  const auto t_start = std::chrono::steady_clock::now();
  if (auto v = validate(pd); !v) return v.errors();
  if (auto f = sim.add_shell(pile_floor(pd)); !f) return f.errors();
  const int floor_spheres = sim.particle_count();
  const float r = pd.particle_radius;
  const GranuleShape& g = sim.granule_shape();
  const float reach = g.centre_distance + g.radius;  // bounding radius, m
  const float a = 2.0f * reach * 1.02f;              // cluster spacing, m
  // hexagonal cluster: rings 0..k, a point (i, j) of the triangular lattice
  std::vector<Vec3> cluster;
  const int rings = pd.batch == 1 ? 0 : pd.batch == 7 ? 1 : pd.batch == 19 ? 2 : 3;
  for (int i = -rings; i <= rings; ++i)
    for (int j = -rings; j <= rings; ++j) {
      const int k = -i - j;
      if (k > rings || k < -rings) continue;
      cluster.push_back({a * (i + 0.5f * j), 0, a * (0.8660254f * j)});
    }
  std::uint64_t seed = pd.seed;
  ReposeResult out;
  int added = 0;
  const int frames_per_batch = std::max(1, int(std::lround(pd.batch_interval / pd.frame_dt)));
  while (added < pd.granules) {
    float top = r + reach;  // highest granule centre (or a granule resting on the floor)
    for (int b = 1; b < sim.body_count(); ++b) top = std::max(top, sim.body_position(BodyId{b}).y);
    const float y = top + a;
    for (std::size_t c = 0; c < cluster.size() && added < pd.granules; ++c, ++added) {
      const float jx = float((pile_detail::uniform01(seed) - 0.5) * 0.04 * a);
      const float jz = float((pile_detail::uniform01(seed) - 0.5) * 0.04 * a);
      auto id = sim.add_granule({cluster[c].x + jx, y, cluster[c].z + jz}, pile_detail::random_orientation(seed));
      if (!id) return id.errors();
    }
    for (int f = 0; f < frames_per_batch; ++f)
      if (auto st = sim.step(pd.frame_dt); !st) return st.errors();
  }
  // the pile's speed: max |v| + |w| (d + r) over the granules on the disc (a granule that
  // rolled off onto the bedrock is not part of the pile and may tumble for seconds)
  const double R2 = double(pd.floor_radius) * pd.floor_radius;
  auto pile_speed = [&] {
    double m = 0;
    for (int b = 1; b < sim.body_count(); ++b) {
      const Vec3 x = sim.body_position(BodyId{b});
      if (double(x.x) * x.x + double(x.z) * x.z > R2) continue;
      const Vec3 v = sim.body_velocity(BodyId{b}), w = sim.body_angular_velocity(BodyId{b});
      m = std::max(m, double(std::sqrt(dot(v, v)) + std::sqrt(dot(w, w)) * reach));
    }
    return m;
  };
  const int relax_frames = int(pd.max_relax / pd.frame_dt);
  for (int f = 0; f < relax_frames; ++f) {
    if (auto st = sim.step(pd.frame_dt); !st) return st.errors();
    // the whole simulation first (cheap), the disc only when something is still moving
    if (sim.max_granule_speed() < pd.rest_speed || pile_speed() < pd.rest_speed) break;
  }
  out.final_speed = pile_speed();
  out.at_rest = out.final_speed < pd.rest_speed;
  pile_detail::fit_pile(pd, sim.particle_positions(), floor_spheres, out);
  out.granules = sim.body_count() - 1;
  out.sim_seconds = sim.time();
  out.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return out;
}

}  // namespace sandpatch
