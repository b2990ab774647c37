// Contact material of the granule DEM and the formulas that tie its parameters together
// (Bell et al. 2005; Cundall & Strack 1979;
// Schwager & Poeschel 2007, "Coefficient of restitution and linear-dashpot model revisited",
// Granular Matter 9:465).
//
// Linear spring-dashpot normal force, f_n = max(0, k_n delta - c_n v.n) (N, never attractive):
//   c_n = 2 zeta sqrt(k_n m_eff)         (N s/m; m_eff = reduced mass of the pair, kg)
//   w0  = sqrt(k_n / m_eff)              (rad/s, undamped angular frequency)
//
// Material::restitution is the e a user MEASURES in a head-on collision with this clamped
// force. zeta is chosen by inverting the clamped relation e_clamped(zeta) over [0, inf)
// (damping_ratio_from_restitution), not the textbook e = exp(-pi zeta / sqrt(1 - zeta^2)),
// which assumes a force that turns attractive at the end of the contact and cannot reach
// e < 0.1353 with the clamp (docs/dem.md has the measurements).
#pragma once

#include <string>

#include "common/error.hpp"

namespace sandpatch {

// Tangential (shear) force law.
enum class ShearLaw {
  // Cundall-Strack: per-contact tangential spring xi (m) with history, rotated into the
  // tangent plane every substep, f_t = -k_t xi - c_t v_t, capped at mu f_n (the default).
  // The only law (Bell et al. 2005's velocity-capped shear was removed: it cannot hold a bed
  // at rest, docs/dem.md). The enum stays: manager/granule_tile.cpp hashes it into tile keys.
  SpringHistory,
};

struct Material {
  float density = 2500.0f;            // kg/m^3 of the sphere material
  float normal_stiffness = 3292.0f;   // k_n, N/m
  float restitution = 0.3f;           // e in (0, 1]: measured normal coefficient of restitution
  float friction = 0.5f;              // mu >= 0: Coulomb coefficient (sphere-sphere and walls)
  ShearLaw shear = ShearLaw::SpringHistory;
  float tangential_stiffness_ratio = 2.0f / 7.0f;  // k_t / k_n (SpringHistory)
  float tangential_damping_ratio = 0.5f;           // c_t / c_n (SpringHistory)
  // kn2 / k_n >= 1: the hysteretic normal spring (Walton & Braun 1986; physics_common.glsl
  // contact_force_h) unloads along kn2 = this x k_n, so a contact gives back 1/this of the
  // energy its loading stored (on top of the dashpot). 1 = the linear spring. Both backends.
  float unloading_stiffness_ratio = 1.0f;
};

// ---- The clamped law (what the simulation does), zeta in [0, inf) ----
// A head-on collision at approach speed v0 with f_n = max(0, k_n delta - c_n v.n): in units
// of w0 and v0, delta'' + 2 zeta delta' + delta = 0, delta(0) = 0, delta'(0) = 1, until the
// force k_n delta + c_n delta' first vanishes (delta'' = 0) at t*; the bodies then separate
// freely at the speed |delta'(t*)|.
//   zeta < 1:  w_d = sqrt(1 - zeta^2),  w_d t* = pi - atan2(2 zeta w_d, 1 - 2 zeta^2)
//   zeta = 1:  t* = 2, e = exp(-2) = 0.1353, contact time 4
//   zeta > 1:  l_+- = -zeta +- W, W = sqrt(zeta^2 - 1),  t* = ln(l_-/l_+) / W
//   e = -delta'(t*) (monotone, 1 at zeta = 0, -> 1/(4 zeta^2) as zeta -> inf)
//   contact time = t* + delta(t*)/|delta'(t*)| (geometric: until the spheres stop overlapping)
double clamped_restitution(double zeta);
// Geometric contact time of the clamped law in units of 1/w0 (pi at zeta = 0, 4 at zeta = 1,
// -> 2 zeta as zeta -> inf).
double clamped_contact_time_w0(double zeta);
// Damping ratio zeta in [0, inf) whose clamped collision has restitution e in (0, 1]: the
// inverse of clamped_restitution (bracketed bisection; e = 1 -> 0). Relative error of
// clamped_restitution(zeta) vs e below 1e-12. This is the material's mapping.
double damping_ratio_from_restitution(double e);
// Normal damping coefficient c_n (N s/m) for a pair of reduced mass m_eff (kg).
double normal_damping(const Material& m, double m_eff);
// Geometric contact time (s) of the clamped law for reduced mass m_eff (kg).
double clamped_contact_time(const Material& m, double m_eff);

// Validates the material; errors name "<prefix>.field".
Status validate(const Material& m, const std::string& prefix);

}  // namespace sandpatch
