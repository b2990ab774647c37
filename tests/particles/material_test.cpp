// Material formulas (particles/material.cpp): each case checks a closed form or an
// independent numerical integration.
#include "particles/material.hpp"
#include "tests/particles/textbook_law.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace sandpatch {

namespace {
// Clamped head-on collision integrated numerically (RK4, h = 1e-5/w0, units w0 = v0 = 1):
// delta'' = -delta - 2 zeta delta' while delta + 2 zeta delta' > 0, then free flight.
// Returns {e, geometric contact time}; independent of the closed forms in material.cpp.
std::pair<double, double> integrate_clamped(double z) {
  const double h = 1e-5;
  double x = 0, v = 1, t = 0;
  auto acc = [z](double x_, double v_) { return -x_ - 2 * z * v_; };
  while (true) {
    const double k1x = v, k1v = acc(x, v);
    const double k2x = v + 0.5 * h * k1v, k2v = acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v);
    const double k3x = v + 0.5 * h * k2v, k3v = acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v);
    const double k4x = v + h * k3v, k4v = acc(x + h * k3x, v + h * k3v);
    const double xn = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
    const double vn = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
    const double f0 = x + 2 * z * v, f1 = xn + 2 * z * vn;  // force / k_n
    if (f1 <= 0) {  // the force vanished inside this step: interpolate t*, x, v
      const double s = f0 / (f0 - f1);
      const double xs = x + s * (xn - x), vs = v + s * (vn - v);
      return {-vs, t + s * h + xs / (-vs)};
    }
    x = xn, v = vn, t += h;
  }
}
}  // namespace

// The material mapping: zeta(e) inverts the clamped law e_clamped(zeta) to 1e-12 for every
// e in (0, 1], including e below exp(-2) = 0.1353 (over-damped, zeta > 1).
TEST(Material, DampingRatioInvertsClampedLaw) {
  for (double e : {1e-4, 0.01, 0.05, 0.1, 0.13, 0.1353, 0.14, 0.3, 0.5, 0.9, 0.999}) {
    double z = damping_ratio_from_restitution(e);
    EXPECT_NEAR(clamped_restitution(z), e, 1e-12 * e) << e;
    EXPECT_EQ(z > 1.0, e < std::exp(-2.0)) << e;
  }
  EXPECT_EQ(damping_ratio_from_restitution(1.0), 0.0);
  // the values quoted in docs/dem.md (6 digits)
  EXPECT_NEAR(damping_ratio_from_restitution(0.1), 1.243188, 1e-6);
  EXPECT_NEAR(damping_ratio_from_restitution(0.3), 0.497239, 1e-6);
  EXPECT_NEAR(damping_ratio_from_restitution(0.5), 0.255276, 1e-6);
  EXPECT_NEAR(damping_ratio_from_restitution(0.9), 0.034265, 1e-6);
}

// The textbook pair zeta(e) <-> e(zeta) (kept for the peer) round-trips to round-off.
TEST(Material, TextbookRoundTrip) {
  for (double e : {0.05, 0.1, 0.3, 0.5, 0.9, 0.999}) {
    double z = testutil::textbook_damping_ratio(e);
    EXPECT_NEAR(testutil::textbook_restitution(z), e, 1e-12) << e;
  }
  EXPECT_EQ(testutil::textbook_damping_ratio(1.0), 0.0);
  EXPECT_TRUE(std::isinf(testutil::textbook_contact_time(1.0, 1.0, 1.0)));
}

// The peer's parameters: k_n = 3292 N/m, e = 0.3 through the TEXTBOOK mapping, m_eff = m/2 of
// a d = 0.01 m sphere give t_c = 1.5e-3 s and c_n = m_eff gamma_n with gamma_n = 1605 1/s
// (docs/BENCHMARKS.md "Running the LAMMPS peer"; LAMMPS' hooke lets the force turn attractive). Our e = 0.3
// is the clamped (measured) one: zeta = 0.4972, so gamma_n = 2 zeta w0 = 2230 1/s.
TEST(Material, PeerContactTime) {
  Material m;
  double ms = 2500.0 * 4.0 / 3.0 * std::numbers::pi * 0.005 * 0.005 * 0.005;
  double zt = testutil::textbook_damping_ratio(0.3);
  EXPECT_NEAR(testutil::textbook_contact_time(zt, m.normal_stiffness, ms / 2), 1.5e-3, 1.5e-3 * 0.01);
  EXPECT_NEAR(2 * zt * std::sqrt(m.normal_stiffness / (ms / 2)), 1605.0, 1605.0 * 0.01);
  EXPECT_NEAR(normal_damping(m, ms / 2) / (ms / 2), 2230.0, 2230.0 * 0.01);
}

// Closed forms of the clamped law (material.hpp): zeta = 0 -> e = 1, t = pi; critical
// zeta = 1 -> e = exp(-2), t = 4 (continuous from both sides); zeta -> inf: e 4 zeta^2 -> 1,
// t / (2 zeta) -> 1; e strictly decreasing; weak damping agrees with the textbook e.
TEST(Material, ClampedLawClosedForms) {
  EXPECT_NEAR(clamped_restitution(0.0), 1.0, 1e-12);
  EXPECT_NEAR(clamped_contact_time_w0(0.0), std::numbers::pi, 1e-12);
  for (double z : {1.0 - 1e-5, 1.0, 1.0 + 1e-5}) {
    EXPECT_NEAR(clamped_restitution(z), std::exp(-2.0), 1e-5) << z;
    EXPECT_NEAR(clamped_contact_time_w0(z), 4.0, 1e-4) << z;
  }
  EXPECT_NEAR(clamped_restitution(100.0) * 4e4, 1.0, 1e-3);
  EXPECT_NEAR(clamped_contact_time_w0(100.0) / 200.0, 1.0, 1e-3);
  double prev = 2.0;
  for (double z = 0.0; z < 20.0; z += 0.001) {
    double e = clamped_restitution(z);
    ASSERT_LT(e, prev) << z;
    prev = e;
  }
  double z9 = testutil::textbook_damping_ratio(0.9);
  EXPECT_NEAR(clamped_restitution(z9), 0.9, 0.9 * 0.003);
  Material m;
  m.restitution = 1.0f;
  EXPECT_NEAR(clamped_contact_time(m, 1.0), std::numbers::pi * std::sqrt(1.0 / m.normal_stiffness), 1e-9);
}

// The closed forms against a direct RK4 integration of the clamped collision, under-,
// critically and over-damped: e and contact time agree to 1e-6 (relative).
TEST(Material, ClampedLawMatchesIntegration) {
  for (double z : {0.1, 0.4972, 0.9, 1.0, 1.2432, 3.0}) {
    auto [e, t] = integrate_clamped(z);
    EXPECT_NEAR(clamped_restitution(z), e, 1e-6 * e) << z;
    EXPECT_NEAR(clamped_contact_time_w0(z), t, 1e-6 * t) << z;
  }
}

// Errors name the field and the allowed range.
TEST(Material, ValidateNamesField) {
  Material m;
  m.restitution = 1.5f;
  auto st = validate(m, "def.material");
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().field, "def.material.restitution");
  EXPECT_NE(st.error().allowed.find("(0, 1]"), std::string::npos);
}

}  // namespace sandpatch
