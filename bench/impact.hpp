// Sphere impacts into granular beds against experiments (docs/validation.md): drops through the
// World and its TerrainManager (measure_drop, bench/tradeoff_drop.hpp) at several drop heights
// and ball densities, the final penetration depth fitted as a power law and compared with
// Uehara, Ambroso, Ojha & Durian, "Low-speed impact craters in loose granular media", Phys.
// Rev. Lett. 90, 194301 (2003) and Ambroso, Santore, Abate & Durian, Phys. Rev. E 71, 051305
// (2005): d = (0.14 / mu) (rho_b / rho_g)^(1/2) D_b^(2/3) H^(1/3), H = h + d the total drop
// distance, mu = tan(angle of repose), rho_g the bed's bulk density.
#pragma once

#include "bench/power_fit.hpp"

#include <vector>

#include "bench/bench_tradeoff.hpp"
#include "bench/tradeoff_drop.hpp"
#include "common/error.hpp"

namespace sandpatch {


// Uehara et al. (2003) / Ambroso et al. (2005): final penetration depth (m) of a ball of
// diameter D_b (m) and density rho_b, dropped from h (m, its bottom above the surface), into a
// bed of bulk density rho_g and repose angle atan(mu): the root d of d = (0.14/mu)
// (rho_b/rho_g)^(1/2) D_b^(2/3) (h + d)^(1/3) (fixed point; the map is a contraction).
double uehara_depth(double mu, double rho_b, double rho_g, double diameter, double h);
// The prefactor A of Uehara's law that a measured depth d (m) at total drop H = h + d (m) gives,
// the exponents held at theirs: d = (A / mu) (rho_b / rho_g)^(1/2) D^(2/3) H^(1/3); the
// experiments' A is 0.14. 0 for arguments out of range.
double uehara_prefactor(double mu, double rho_b, double rho_g, double diameter, double depth, double total_drop);
// The angle of repose (deg) of poured piles of the granules at Coulomb friction `friction`
// (docs/calibration.md "Friction": 800 granules, three seeds each, 29.0 / 33.8 / 35.9 / 38.0 /
// 36.7 deg at 0.2 / 0.35 / 0.5 / 0.7 / 1.0), linear between them; 0 outside 0.2 ... 1.0.
double repose_deg(double friction);
// Uehara's mu for granules of that friction: tan(repose_deg); 0 outside 0.2 ... 1.0.
double repose_mu(double friction);

// One impact of a series: the drop's result and the penetration depth the comparison uses:
// the Bullet sphere's lowest point below the original surface at the end plus the shell
// spheres' radius (r x particle scale: the DEM shell's spheres are centred on the body's
// surface, so the soil meets a ball one granule sphere radius larger than Bullet's, m).
struct ImpactPoint {
  double drop_height = 0, density = 0;  // h (m), rho_b (kg/m^3)
  double depth = 0;                     // d, m
  double total_drop = 0;                // H = h + d, m
  DropResult drop;
};

// The series of docs/validation.md: the base drop at each height (density base.sphere_density)
// and at each density (height density_height). Each point one measure_drop.
struct ImpactSeriesDef {
  DropDef base;
  TradeoffKnobs knobs;
  std::vector<double> heights;     // m
  std::vector<double> densities;   // kg/m^3
  double density_height = 0.2;     // m
  double settle_after = 0.45;      // s simulated after the free fall (sqrt(2 h / g))
};
struct ImpactSeries {
  std::vector<ImpactPoint> by_height, by_density;
  PowerFit depth_vs_total_drop;    // d against H = h + d (Uehara: exponent 1/3)
  PowerFit depth_vs_density;       // d against rho_b (Uehara: exponent 1/2)
  double worst_rebound = 0;        // largest rebound_ratio of the series
  // The bed's bulk density (kg/m^3): the first point's granules x granule mass over the
  // patch's volume (terrain_side^2 x patch_depth; the granules the fill placed there).
  double bulk_density = 0;
};
Result<ImpactSeries> run_impact_series(const ImpactSeriesDef& def);

}  // namespace sandpatch
