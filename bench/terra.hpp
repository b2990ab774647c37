// Terramechanics measurements on the DEM bed of scenes/wheel_on_sand.json (docs/validation.md
// "Terramechanics"): the soil's parameters from a plate-sinkage test at two plate widths
// (Bekker's pressure-sinkage law) and a grousered shear plate at several normal stresses
// (Janosi & Hanamoto's shear law), then a single rigid wheel under load driven at set slips,
// its drawbar pull and sinkage compared with the rigid-wheel model of Wong & Reece that
// integrates those two laws around the contact arc (Wong, Theory of Ground Vehicles, ch. 2
// and 4).
//
// Every test runs through the World (manager/world.hpp) on the scene's terrain, material and
// simulation settings, with the scene's bodies replaced by the test's body:
//   plate  a kinematic box (square, b x b, 6 cm thick) held 2 cm above the surface while its
//          patch fills, then pressed down at a constant speed;
//   shear  a dynamic grousered plate (a comb: a bar with blades under it, extruded across)
//          whose weight is the normal load; its blades start in the soil; after it settles its
//          x velocity is set before every frame (y free, z, tilt and spin held);
//   wheel  the scene's rig: a kinematic "carriage" moved along x at v, a vertical "slider"
//          joint (free) to a dynamic "hub", a hinge "axle" from the hub to the "wheel" (dynamic
//          cylinder, axle along z) whose velocity motor turns it at w: slip s = 1 - v / (w r);
//          the hub's and the wheel's weight is the load. A scene with only a wheel: its x
//          velocity and spin are set before every frame instead (y free, z and tilt held).
// Sign conventions: y up, the rig moves along +x. Drawbar pull DP = the x component of the
// granular force on the wheel (the soil's net push forward: thrust minus the resistances;
// the carriage holds the wheel back with -DP).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/error.hpp"

namespace sandpatch::terra {

// ---- the soil laws (SI inside: Pa, m; Bekker's moduli in the units of the law) ----

// Bekker's pressure-sinkage law p = (k_c / b + k_phi) z^n: p in Pa, z and b in m, k_c in
// Pa/m^(n-1) = N/m^(n+1), k_phi in Pa/m^n = N/m^(n+2) (kN/m^(n+1), kN/m^(n+2) in the tables).
struct Bekker {
  double n = 1, k_c = 0, k_phi = 0;
  double pressure(double b, double z) const;  // Pa; 0 for z <= 0
};
// Janosi & Hanamoto: tau = (c + sigma tan phi) (1 - exp(-j / K)); c in Pa, phi in rad, K in m.
struct ShearLaw {
  double c = 0, phi = 0, K = 0.01;
  double stress(double sigma, double j) const;  // Pa; j <= 0 gives 0
};

// ---- fits ----

// Plate sinkage: ln p = n ln z + ln k_i, one k_i per plate width b_i, one n shared (least
// squares over every point of every plate with z in [z_lo, z_hi]); k_i = k_c / b_i + k_phi
// gives k_c and k_phi. Uncertainties: one standard error from the residuals (the points of a
// press are correlated frame to frame, so they are a lower bound). With exactly two widths k_c
// and k_phi are determined, with more they are a weighted line through (1 / b_i, k_i).
struct BekkerFit {
  Bekker soil;
  double n_se = 0, k_c_se = 0, k_phi_se = 0;
  std::vector<double> widths, k, k_se;  // per plate: b_i (m), k_i (Pa/m^n) and its se
  std::vector<double> n_alone, n_alone_se;  // per plate: its own exponent (ln p on ln z alone) and se
  double rms_log = 0;                   // rms residual of ln p
  int points = 0;
};
struct PlateCurve {
  double width = 0;                      // b, m
  std::vector<double> z, p;              // sinkage (m) and pressure (Pa), per frame
};
Result<BekkerFit> fit_bekker(const std::vector<PlateCurve>& plates, double z_lo, double z_hi);

// Shear: c, tan(phi) and K by least squares of tau = (c + sigma tan phi)(1 - exp(-j / K)) over
// every point of every curve (golden section on ln K, the other two linear for each K). The
// uncertainties: one standard error from the residuals (c, phi), and the half width of the K
// range where the sum of squares rises by one residual variance (K); the points of a drag are
// correlated frame to frame, so these are lower bounds. Per curve also: the plateau (points
// with j >= plateau_from: mean and sd), K fitted to tau / plateau alone, and the peak.
struct ShearCurve {
  double sigma = 0;                      // Pa, the normal stress over the shear window
  std::vector<double> j, tau;            // shear displacement (m) and shear stress (Pa)
  double tau_max = 0, tau_max_sd = 0;    // Pa: plateau mean and standard deviation
  double K = 0;                          // m, this curve's own fit
  double tau_peak = 0, j_peak = 0;       // Pa, m: the largest shear stress (mean over 9 frames) and where
};
struct ShearFit {
  ShearLaw soil;
  double c_se = 0, phi_se = 0, K_se = 0;  // Pa, rad, m
};
// `plateau_from`: the plateau is the points with j >= plateau_from (m).
Result<ShearFit> fit_shear(std::vector<ShearCurve>& curves, double plateau_from);

// ---- the rigid wheel (Wong & Reece 1967; Wong, Theory of Ground Vehicles, ch. 4) ----
struct WheelGeometry {
  double radius = 0.3, width = 0.4;     // m
};
struct WheelModel {
  double theta1 = 0;        // rad, entry angle
  double sinkage = 0;       // m, r (1 - cos theta1)
  double load = 0;          // N, the vertical component of the stresses
  double drawbar_pull = 0;  // N, their horizontal component (+x: forward)
  double torque = 0;        // N m, the shear stresses' moment about the axle
  bool ok = false;          // a sinkage in (0, r) carries `load`
};
// Coefficients of the angle of the largest normal stress theta_m = (c1 + c2 s) theta1 (Wong &
// Reece's fits for sand: c1 ~ 0.4, c2 ~ 0.2 to 0.3).
struct WongReece {
  double c1 = 0.4, c2 = 0.3;
};
// The stresses integrated over the arc for entry angle theta1 (exit at theta = 0: no rebound).
WheelModel wheel_at_entry(const Bekker& bekker, const ShearLaw& shear, const WheelGeometry& g, double slip,
                          double theta1, const WongReece& wr = {});
// The entry angle that carries `load` (N) at `slip`: bisection on theta1 in (0, pi/2).
WheelModel wheel_under_load(const Bekker& bekker, const ShearLaw& shear, const WheelGeometry& g, double slip,
                            double load, const WongReece& wr = {});

// ---- the DEM tests ----

struct RigSetup {
  std::string scene = "scenes/wheel_on_sand.json";  // the bed (terrain, material, simulation) and the wheel
  int threads = 1;
  double bed_depth = 0;       // m: the patch depth (terrain.patch_depth) instead of the scene's; 0 keeps it
};

struct PlateDef {
  double width = 0.3;         // b, m (square plate)
  double speed = 0.04;        // m/s, pressing speed
  double depth = 0.12;        // m, pressed this far below the surface
};
struct PlateRun {
  PlateCurve curve;           // every pressing frame with the plate carried
  std::vector<double> t;      // s
  int granules = 0;           // peak
  double simulated_s = 0, wall_s = 0;
};
Result<PlateRun> run_plate(const RigSetup& setup, const PlateDef& def);

struct ShearDef {
  double sigma = 4000;        // Pa, the normal stress (the plate's weight / its area)
  double length = 0.6;        // m along x (the shear direction)
  double width = 0.4;         // m along z
  int blades = 4;             // grousers, evenly spread, the outer ones flush with the ends
  double blade_depth = 0.06;  // m below the bar, started in the soil
  double blade_thickness = 0.03;  // m
  double settle = 0.5;        // s with the plate let down before the drag
  double speed = 0.1;         // m/s, the drag
  double travel = 0.35;       // m, the drag's length
};
struct ShearRun {
  ShearCurve curve;           // every drag frame
  std::vector<double> t;      // s
  std::vector<double> sink;   // m, the blades' tips below the original surface, per drag frame
  double blade_sinkage = 0;   // m, the blades' tips below the surface at the drag's start
  int granules = 0;
  double simulated_s = 0, wall_s = 0;
};
Result<ShearRun> run_shear(const RigSetup& setup, const ShearDef& def);

struct WheelDef {
  double slip = 0.3;          // s = 1 - v / (w r) commanded
  double speed = 0.25;        // v, m/s
  double settle = 0.4;        // s let down before the drive
  double drive = 2.2;         // s driven
  double window_from = 1.0;   // s after the drive starts: the steady window's start (0.25 m: past the
                              // transient of leaving the settling place)
};
struct WheelRun {
  double slip_cmd = 0, slip = 0;   // commanded; measured (over the window: 1 - dx/dt / (w r), w the mean of the spin before and after each frame)
  double load = 0;                 // N, the wheel's weight (and the hub's, jointed)
  WheelGeometry soil_seen;         // m: the cylinder grown by one shell sphere radius (rim and both faces)
  bool jointed = false;            // driven through the scene's carriage, slider and motorised axle
  double drawbar_pull = 0, drawbar_pull_sd = 0;  // N, mean and sd over the window
  double sinkage = 0, sinkage_sd = 0;            // m, below the original surface
  double torque = 0;               // N m, the soil's moment resisting the spin (mean over the window)
  double vertical = 0;             // N, mean granular force up over the window
  std::vector<double> t, x, dp, sink;  // per frame, from the drive's start
  std::vector<double> fy, hf_fy;       // N per frame: granular and heightfield (Bullet) vertical force
  int granules = 0;
  double simulated_s = 0, wall_s = 0;
};
Result<WheelRun> run_wheel(const RigSetup& setup, const WheelDef& def);

// ---- bench terra ----
struct BenchTerraArgs {
  std::string scene = "scenes/wheel_on_sand.json";
  std::vector<double> plates = {0.3, 0.5};        // m
  std::vector<double> sigmas = {2000, 4000, 8000};  // Pa
  std::vector<double> slips = {0, 0.15, 0.3, 0.45, 0.6};
  double z_lo = 0.03, z_hi = 0.12;                 // m, the Bekker fit's window
  double bed_depth = 0;                            // m, RigSetup::bed_depth
  bool plates_only = false;                        // stop after the Bekker fit
  std::string out;                                 // directory for the series (CSV), "" none
  int threads = 1;
  bool json = false;
};
std::string check_bench_terra_args(const BenchTerraArgs& a);
int run_bench_terra(const BenchTerraArgs& a);

}  // namespace sandpatch::terra
