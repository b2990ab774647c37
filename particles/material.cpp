// Material formulas; see material.hpp for the equations.
#include "particles/material.hpp"

#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

namespace sandpatch {

double damping_ratio_from_restitution(double e) {
  if (e >= 1.0) return 0.0;
  double l = std::log(e);
  return -l / std::sqrt(std::numbers::pi * std::numbers::pi + l * l);
}

double restitution_from_damping_ratio(double zeta) {
  return std::exp(-std::numbers::pi * zeta / std::sqrt(1.0 - zeta * zeta));
}

double normal_damping(const Material& m, double m_eff) {
  return 2.0 * damping_ratio_from_restitution(m.restitution) * std::sqrt(m.normal_stiffness * m_eff);
}

double contact_time(const Material& m, double m_eff) {
  double zeta = damping_ratio_from_restitution(m.restitution);
  return std::numbers::pi * std::sqrt(m_eff / m.normal_stiffness) / std::sqrt(1.0 - zeta * zeta);
}

namespace {
// Clamped collision in units of w0 = 1, v0 = 1: returns {e, contact time}.
void clamped(double z, double* e, double* t) {
  double wd = std::sqrt(1.0 - z * z);
  double ts = (std::numbers::pi - std::atan2(2.0 * z * wd, 1.0 - 2.0 * z * z)) / wd;
  double x = std::exp(-z * ts) * std::sin(wd * ts) / wd;
  double v = std::exp(-z * ts) * (std::cos(wd * ts) - z / wd * std::sin(wd * ts));
  *e = -v;
  *t = ts + x / (-v);
}
}  // namespace

double clamped_restitution(double zeta) {
  double e, t;
  clamped(zeta, &e, &t);
  return e;
}

double clamped_contact_time(const Material& m, double m_eff) {
  double e, t;
  clamped(damping_ratio_from_restitution(m.restitution), &e, &t);
  return t * std::sqrt(m_eff / m.normal_stiffness);
}

Status validate(const Material& m, const std::string& p) {
  std::vector<Error> es;
  auto check = [&](bool ok, const char* f, double v, const char* allowed) {
    if (!ok || !std::isfinite(v)) es.push_back(Error{"", p + "." + f, format_number(v), allowed, ""});
  };
  check(m.density > 0, "density", m.density, "must be > 0 (kg/m^3)");
  check(m.normal_stiffness > 0, "normal_stiffness", m.normal_stiffness, "must be > 0 (N/m)");
  check(m.restitution > 0 && m.restitution <= 1, "restitution", m.restitution, "must be in (0, 1]");
  check(m.friction >= 0, "friction", m.friction, "must be >= 0");
  check(m.tangential_stiffness_ratio > 0, "tangential_stiffness_ratio", m.tangential_stiffness_ratio,
        "must be > 0 (k_t / k_n)");
  check(m.tangential_damping_ratio >= 0, "tangential_damping_ratio", m.tangential_damping_ratio,
        "must be >= 0 (c_t / c_n)");
  check(m.bell_shear_viscosity >= 0, "bell_shear_viscosity", m.bell_shear_viscosity, "must be >= 0 (N s/m)");
  if (!es.empty()) return es;
  return Ok{};
}

}  // namespace sandpatch
