// The textbook linear spring-dashpot relations (a force allowed to turn attractive), for the
// tests only: the LAMMPS peer's gamma_n (docs/BENCHMARKS.md "Running the LAMMPS peer") was derived with them,
// and the tests check the clamped law of particles/material.hpp against them where both agree.
//   e = exp(-pi zeta / sqrt(1 - zeta^2)),  zeta = -ln e / sqrt(pi^2 + ln^2 e),
//   t_c = pi / (w0 sqrt(1 - zeta^2))  (s; +inf for zeta >= 1)
#pragma once

#include <cmath>
#include <limits>
#include <numbers>

namespace sandpatch::testutil {

inline double textbook_damping_ratio(double e) {
  if (e >= 1.0) return 0.0;
  const double l = std::log(e);
  return -l / std::sqrt(std::numbers::pi * std::numbers::pi + l * l);
}

inline double textbook_restitution(double zeta) {
  return std::exp(-std::numbers::pi * zeta / std::sqrt(1.0 - zeta * zeta));
}

// Contact time (s) for stiffness k_n (N/m) and reduced mass m_eff (kg).
inline double textbook_contact_time(double zeta, double k_n, double m_eff) {
  if (zeta >= 1.0) return std::numeric_limits<double>::infinity();
  return std::numbers::pi * std::sqrt(m_eff / k_n) / std::sqrt(1.0 - zeta * zeta);
}

}  // namespace sandpatch::testutil
