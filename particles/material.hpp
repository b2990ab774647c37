// Contact material of the granule DEM and the formulas that tie its parameters together
// (../shared/DESIGN.md "Granule model"; Bell et al. 2005; Cundall & Strack 1979).
//
// Linear spring-dashpot normal force, one damping ratio for every pair:
//   zeta = -ln e / sqrt(pi^2 + ln^2 e)          (inverse of e = exp(-pi zeta / sqrt(1 - zeta^2)))
//   c_n  = 2 zeta sqrt(k_n m_eff)               (N s/m; m_eff = reduced mass of the pair, kg)
//   t_c  = pi / sqrt(k_n/m_eff - (c_n / (2 m_eff))^2) = pi sqrt(m_eff/k_n) / sqrt(1 - zeta^2)   (s)
#pragma once

#include <string>

#include "common/error.hpp"

namespace sandpatch {

// Tangential (shear) force law.
enum class ShearLaw {
  // Cundall-Strack: per-contact tangential spring xi (m) with history, rotated into the
  // tangent plane every substep, f_t = -k_t xi - c_t v_t, capped at mu f_n (the default).
  SpringHistory,
  // Bell et al. 2005: velocity-capped shear f_t = -min(mu f_n, k_t |v_t|) v_t/|v_t| with
  // k_t = bell_shear_viscosity (N s/m). Kept as an option; it cannot hold a bed at rest
  // (docs/dem.md has the measurement).
  BellVelocityCapped,
};

struct Material {
  float density = 2500.0f;            // kg/m^3 of the sphere material
  float normal_stiffness = 3292.0f;   // k_n, N/m
  float restitution = 0.3f;           // e in (0, 1]: normal coefficient of restitution
  float friction = 0.5f;              // mu >= 0: Coulomb coefficient (sphere-sphere and walls)
  ShearLaw shear = ShearLaw::SpringHistory;
  float tangential_stiffness_ratio = 2.0f / 7.0f;  // k_t / k_n (SpringHistory)
  float tangential_damping_ratio = 0.5f;           // c_t / c_n (SpringHistory)
  float bell_shear_viscosity = 2.0f;               // N s/m, the k_t of Bell's law
};

// Damping ratio zeta for restitution e (e = 1 -> 0).
double damping_ratio_from_restitution(double e);
// Restitution for damping ratio zeta < 1.
double restitution_from_damping_ratio(double zeta);
// Normal damping coefficient c_n (N s/m) for a pair of reduced mass m_eff (kg).
double normal_damping(const Material& m, double m_eff);
// Contact time t_c (s) of the damped normal spring for reduced mass m_eff (kg).
double contact_time(const Material& m, double m_eff);

// The "never attractive" clamp f_n >= 0 ends a collision when k_n delta = c_n v.n, before
// the overlap closes, so the measured restitution and contact time differ from the formulas
// above (Schwager & Poeschel 2008). For 0 <= zeta < 1, with w_d = sqrt(1 - zeta^2) (in units
// of w0 = sqrt(k_n/m_eff)), the force vanishes at w_d t* = pi - atan2(2 zeta w_d, 1 - 2 zeta^2);
// the bodies then fly apart freely:
//   e_clamped  = -v(t*)/v0,      t_contact = t* + delta(t*)/|v(t*)|   (geometric contact)
// e_clamped >= 0.1355 for every zeta < 1: a clamped linear dashpot cannot give e = 0.1.
double clamped_restitution(double zeta);
// Geometric contact time (s) of the clamped law for reduced mass m_eff (kg).
double clamped_contact_time(const Material& m, double m_eff);

// Validates the material; errors name "<prefix>.field".
Status validate(const Material& m, const std::string& prefix);

}  // namespace sandpatch
