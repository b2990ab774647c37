// Quasi-two-dimensional granular column collapse (docs/validation.md "Granular column
// collapse"): the flow a user watches, against the published experiments (Balmforth &
// Kerswell, J. Fluid Mech. 538 (2005) 399-428, narrow and wide slots; the column collapse
// of Lube, Huppert, Sparks & Hallworth and Lajeunesse et al., 2004-2005).
//
// Geometry (sim units = m, y up): a slot between the side walls z = 0 and z = W; the back
// wall x = 0; a bedrock floor y = 0 (the material's Coulomb friction mu, as every wall). The
// column of length L0 along x is a lattice of tetrahedral granules (particles/bed.hpp)
// behind a gate, a static shell of spheres of the granule radius whose surface is the plane
// x = L0. The lattice settles inside the walls and the gate; at t = 0 the gate is removed
// at once (Simulation::set_body_enabled) and the column spreads along +x until it stops.
//
// Measured (on the granules' sphere centres, r = sphere radius):
//   H0      initial height: highest sphere top (y + r) of the settled column at release
//   a       = H0 / L0, the aspect ratio (the one the results are plotted against)
//   l_inf   runout from the back wall: the spheres are binned along x in bins of one granule
//           bounding diameter; the deposit is the run of occupied bins from x = 0 up to the
//           first two empty bins in a row; l_inf is the farthest sphere edge (x + r) in it.
//           Granules beyond that gap (thrown ahead of the front) are counted, not measured.
//   h_inf   final height: highest sphere top of the deposit
//   t_stop  time after release at which the front (l_inf) last moved by more than 1 % of
//           L0 (the front's arrest time)
// The run ends when every granule is slower than rest_speed, or when neither l_inf nor h_inf
// has moved by 1 % of L0 for 0.3 s after 3 sqrt(H0 / g), or after max_flow.
#pragma once

#include "bench/power_fit.hpp"

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/error.hpp"

namespace sandpatch {

struct CollapseDef {
  double aspect = 1.0;        // target H0 / L0 (the settled column's measured a is reported)
  int length_granules = 10;   // L0 in lattice columns along x (spacing 1.02 bounding diameters)
  int width_granules = 3;     // slot width W in lattice columns along z
  float particle_radius = 0.005f;  // r, m
  float friction = 0.5f;      // mu: granule-granule, floor and walls
  // normal law: 1 = the default material's linear spring-dashpot (e = 0.3); > 1 = the
  // hysteretic spring with this unloading / loading stiffness ratio and restitution 1
  float unloading = 1.0f;
  float restitution = -1.0f;  // the dashpot's restitution; < 0: 0.3 (linear) or 1 (hysteretic)
  std::uint64_t seed = 1;     // lattice orientations and jitter
  double frame_dt = 2e-3;     // s, frames substepped by the stability guard
  double max_settle = 1.5;    // s simulated for the column to settle before release
  double max_flow = 4.0;      // s simulated after release at most
  double rest_speed = 0.02;   // m/s: at rest when every granule is slower (|v| + |w| reach)
  int threads = 1;            // OpenMP threads (results do not depend on it)
};

struct CollapseResult {
  int granules = 0;
  double L0 = 0, W = 0, H0 = 0, aspect = 0;  // m; a = H0 / L0
  double d = 0;               // m, granule bounding diameter
  double l_inf = 0, h_inf = 0;  // m
  double runout = 0;          // (l_inf - L0) / L0
  double height = 0;          // h_inf / L0
  int ejected = 0;            // granules beyond the deposit's front gap
  double settle_time = 0;     // s simulated before release
  double t_stop = 0;          // s after release (front arrest)
  double t_flow = 0;          // s simulated after release
  bool at_rest = false;       // every granule below rest_speed at the end (else max_flow ran out)
  double wall_seconds = 0;    // whole run (settle + flow)
  std::int64_t sphere_steps = 0;  // spheres x substeps (the cost)
  std::vector<double> profile;    // m, final surface per bin of width d from x = 0 (-1 empty)
};

// Checks the definition (errors name CollapseDef.<field>, the value and the range).
Status check_collapse(const CollapseDef& def);
Result<CollapseResult> run_collapse(const CollapseDef& def);


// bench collapse: one collapse per aspect ratio, one thread each, then the fits against the
// published exponents. Prints a table (with json, one JSON object on the last line).
struct BenchCollapseArgs {
  std::vector<double> aspects = {0.5, 0.75, 1, 1.5, 2, 3, 4, 6, 8};
  std::vector<float> frictions = {0.5f};  // a sweep per friction
  int length_granules = 10;
  int width_granules = 3;
  double split = 2.5;   // target a: fits over the runs of target a <= split, > split, and all
  float unloading = 1.0f;     // CollapseDef::unloading
  float restitution = -1.0f;  // CollapseDef::restitution
  std::uint64_t seed = 1;
  int threads = 1;
  bool json = false;
};
std::string check_bench_collapse_args(const BenchCollapseArgs& args);
int run_bench_collapse(const BenchCollapseArgs& args);
nlohmann::json collapse_json(const CollapseResult& r);

}  // namespace sandpatch
