// Material formulas; see material.hpp for the equations.
#include "particles/material.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <vector>

namespace sandpatch {

namespace {
// Clamped collision in units of w0 = 1, v0 = 1 (material.hpp): {e, geometric contact time}.
struct Clamped {
  double e, t;
};
Clamped clamped(double z) {
  double ts, x, v;  // time the force vanishes, overlap and overlap rate there
  if (z < 1.0 - 1e-7) {
    const double wd = std::sqrt(1.0 - z * z);
    ts = (std::numbers::pi - std::atan2(2.0 * z * wd, 1.0 - 2.0 * z * z)) / wd;
    x = std::exp(-z * ts) * std::sin(wd * ts) / wd;
    v = std::exp(-z * ts) * (std::cos(wd * ts) - z / wd * std::sin(wd * ts));
  } else if (z > 1.0 + 1e-7) {
    // delta = (exp(l+ t) - exp(l- t)) / (2W); delta'' = 0 where exp(2W t) = (l-/l+)^2.
    // Written with l+ = -1/(z + W) (= -z + W without the cancellation at large z).
    const double W = std::sqrt(z * z - 1.0);
    const double lp = -1.0 / (z + W), lm = -(z + W);
    ts = std::log(lm / lp) / W;
    const double ep = std::exp(lp * ts), em = std::exp(lm * ts);
    x = (ep - em) / (2.0 * W);
    v = (lp * ep - lm * em) / (2.0 * W);
  } else {  // critical: delta = t exp(-t), delta'' = 0 at t = 2 (|z - 1| < 1e-7 changes e by < 1e-7)
    ts = 2.0;
    x = 2.0 * std::exp(-2.0);
    v = -std::exp(-2.0);
  }
  return {-v, ts + x / (-v)};
}
}  // namespace

double clamped_restitution(double zeta) { return clamped(zeta).e; }
double clamped_contact_time_w0(double zeta) { return clamped(zeta).t; }

double damping_ratio_from_restitution(double e) {
  if (!(e < 1.0)) return 0.0;
  if (!(e > 0.0)) return std::numeric_limits<double>::infinity();
  // e_clamped is strictly decreasing in zeta (1 at 0, ~1/(4 zeta^2) at large zeta): bracket
  // by doubling, then bisect to the last bit.
  double lo = 0.0, hi = 1.0;
  while (clamped_restitution(hi) > e && hi < 1e30) lo = hi, hi *= 2.0;
  for (int k = 0; k < 200 && hi - lo > 1e-15 * hi; ++k) {
    const double mid = 0.5 * (lo + hi);
    (clamped_restitution(mid) > e ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

double normal_damping(const Material& m, double m_eff) {
  return 2.0 * damping_ratio_from_restitution(m.restitution) * std::sqrt(m.normal_stiffness * m_eff);
}

double clamped_contact_time(const Material& m, double m_eff) {
  return clamped_contact_time_w0(damping_ratio_from_restitution(m.restitution)) * std::sqrt(m_eff / m.normal_stiffness);
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
  check(m.unloading_stiffness_ratio >= 1 && m.unloading_stiffness_ratio <= 100, "unloading_stiffness_ratio",
        m.unloading_stiffness_ratio, "must be in [1, 100] (unloading / loading normal stiffness; 1 = linear spring)");
  if (!es.empty()) return es;
  return Ok{};
}

}  // namespace sandpatch
