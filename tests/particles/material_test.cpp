// Material formulas (particles/material.cpp): each case checks a closed form.
#include "particles/material.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

namespace sandpatch {

// zeta(e) inverts e(zeta) = exp(-pi zeta / sqrt(1 - zeta^2)) to round-off.
TEST(Material, DampingRatioRoundTrip) {
  for (double e : {0.05, 0.1, 0.3, 0.5, 0.9, 0.999}) {
    double z = damping_ratio_from_restitution(e);
    EXPECT_NEAR(restitution_from_damping_ratio(z), e, 1e-12) << e;
  }
  EXPECT_EQ(damping_ratio_from_restitution(1.0), 0.0);
}

// The peer's parameters: k_n = 3292 N/m, e = 0.3, m_eff = m/2 of a d = 0.01 m sphere give
// t_c = 1.5e-3 s (in.lammps_bed) and c_n = m_eff gamma_n with gamma_n = 1605 1/s.
TEST(Material, PeerContactTime) {
  Material m;
  double ms = 2500.0 * 4.0 / 3.0 * std::numbers::pi * 0.005 * 0.005 * 0.005;
  EXPECT_NEAR(contact_time(m, ms / 2), 1.5e-3, 1.5e-3 * 0.01);
  EXPECT_NEAR(normal_damping(m, ms / 2) / (ms / 2), 1605.0, 1605.0 * 0.01);
}

// The clamped law: undamped -> e = 1, t = pi/w0; its restitution never drops below 0.135.
TEST(Material, ClampedLaw) {
  EXPECT_NEAR(clamped_restitution(0.0), 1.0, 1e-12);
  Material m;
  m.restitution = 1.0f;
  EXPECT_NEAR(clamped_contact_time(m, 1.0), std::numbers::pi * std::sqrt(1.0 / m.normal_stiffness), 1e-9);
  for (double z = 0.0; z < 0.999; z += 0.01) EXPECT_GT(clamped_restitution(z), 0.135) << z;
  // weak damping: clamped and textbook agree (e = 0.9 within 0.3%)
  double z9 = damping_ratio_from_restitution(0.9);
  EXPECT_NEAR(clamped_restitution(z9), 0.9, 0.9 * 0.003);
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
