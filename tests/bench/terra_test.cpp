// Terramechanics (bench/terra.hpp): the fits and the rigid-wheel model against formulas, and a
// fast subset of the DEM tests (docs/validation.md "Terramechanics").
#include "bench/terra.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

namespace sandpatch::terra {
namespace {

std::string scene() { return std::string(SANDPATCH_SOURCE_DIR) + "/scenes/wheel_on_sand.json"; }

TEST(TerraFit, BekkerRecoversTheLawFromTwoPlates) {
  const Bekker truth{1.1, 40e3, 900e3};  // n, k_c (N/m^2.1), k_phi (N/m^3.1)
  std::vector<PlateCurve> plates;
  for (double b : {0.3, 0.5}) {
    PlateCurve c;
    c.width = b;
    for (int i = 0; i < 50; ++i) {
      const double z = 0.01 + 0.002 * i;
      const double noise = 1.0 + 0.02 * std::sin(13.0 * i + 7.0 * b);  // +-2 %
      c.z.push_back(z);
      c.p.push_back(truth.pressure(b, z) * noise);
    }
    plates.push_back(c);
  }
  auto f = fit_bekker(plates, 0.02, 0.1);
  ASSERT_TRUE(f) << f.message();
  EXPECT_NEAR(f->soil.n, truth.n, 0.02);
  EXPECT_NEAR(f->soil.k_c, truth.k_c, 0.25 * truth.k_c);
  EXPECT_NEAR(f->soil.k_phi, truth.k_phi, 0.05 * truth.k_phi);
  EXPECT_GT(f->n_se, 0);
  EXPECT_LT(f->n_se, 0.02);
  // one width cannot separate k_c from k_phi
  plates[1].width = 0.3;
  EXPECT_FALSE(fit_bekker(plates, 0.02, 0.1));
  EXPECT_FALSE(fit_bekker({plates[0]}, 0.02, 0.1));
}

TEST(TerraFit, JanosiHanamotoRecoversCPhiK) {
  const ShearLaw truth{500.0, 30.0 * M_PI / 180, 0.03};
  std::vector<ShearCurve> curves;
  for (double sg : {2000.0, 4000.0, 8000.0}) {
    ShearCurve c;
    c.sigma = sg;
    for (int i = 0; i < 120; ++i) {
      const double j = 0.0025 * i;
      c.j.push_back(j);
      c.tau.push_back(truth.stress(sg, j) * (1.0 + 0.01 * std::cos(5.0 * i)));
    }
    curves.push_back(c);
  }
  auto f = fit_shear(curves, 0.15);
  ASSERT_TRUE(f) << f.message();
  EXPECT_NEAR(f->soil.c, truth.c, 60);
  EXPECT_NEAR(f->soil.phi, truth.phi, 0.01);
  EXPECT_NEAR(f->soil.K, truth.K, 0.002);
}

// Without shear and with the normal stress at every point of the rim Bekker's pressure at the
// sinkage there (theta_m = 0: the largest at the bottom, Bekker's own assumption), the
// integrals reduce to Bekker's closed forms for a rigid wheel: the vertical load is the
// pressure integrated along the chord, W = b int p(z) dx, and the drawbar pull is minus the
// compaction resistance R_c = b k z0^(n+1) / (n+1), k = k_c / b + k_phi (Wong, ch. 4).
TEST(TerraModel, WithoutShearDrawbarPullIsBekkersCompactionResistance) {
  const Bekker bk{1.2, 20e3, 1.2e6};
  const ShearLaw none{0, 0, 0.02};
  const WheelGeometry g{0.325, 0.45};
  const WongReece front{0.0, 0.0};
  const WheelModel m = wheel_under_load(bk, none, g, 0.2, 1000.0, front);
  ASSERT_TRUE(m.ok);
  EXPECT_NEAR(m.load, 1000.0, 0.5);
  const double k = bk.k_c / g.width + bk.k_phi;
  const double rc = g.width * k * std::pow(m.sinkage, bk.n + 1) / (bk.n + 1);
  EXPECT_NEAR(-m.drawbar_pull, rc, 0.005 * rc);
  EXPECT_NEAR(m.torque, 0.0, 1e-9);
  // the load by the chord: W = b int_0^{l} k (z0 - r + sqrt(r^2 - x^2))^n dx, l = r sin(theta1)
  const double r = g.radius, l = r * std::sin(m.theta1);
  double w = 0;
  const int N = 20000;
  for (int i = 0; i < N; ++i) {
    const double x = (i + 0.5) * l / N;
    w += k * std::pow(std::max(0.0, m.sinkage - r + std::sqrt(r * r - x * x)), bk.n) * l / N;
  }
  EXPECT_NEAR(g.width * w, 1000.0, 2.0);
}

TEST(TerraModel, DrawbarPullRisesWithSlipAndSaturates) {
  const Bekker bk{1.2, 0, 1.2e6};
  const ShearLaw sh{0, 30.0 * M_PI / 180, 0.03};
  const WheelGeometry g{0.325, 0.45};
  std::vector<double> dp;
  for (double s : {0.0, 0.15, 0.3, 0.45, 0.6}) {
    const WheelModel m = wheel_under_load(bk, sh, g, s, 1000.0);
    ASSERT_TRUE(m.ok) << s;
    EXPECT_NEAR(m.load, 1000.0, 1.0);
    dp.push_back(m.drawbar_pull);
  }
  EXPECT_LT(dp[0], 0);  // rolling: the compaction resistance wins
  for (std::size_t i = 1; i < dp.size(); ++i) EXPECT_GT(dp[i], dp[i - 1]);
  EXPECT_LT(dp[4] - dp[3], dp[1] - dp[0]);  // saturating
  // below the pull a Coulomb soil could give at most: W tan(phi)
  EXPECT_LT(dp[4], 1000.0 * std::tan(sh.phi));
}

TEST(TerraRig, RefusesBadDefinitionsNamingTheField) {
  RigSetup s;
  s.scene = scene();
  PlateDef p;
  p.width = 0.01;
  auto r = run_plate(s, p);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().field, "PlateDef.width");
  WheelDef w;
  w.slip = 1.5;
  auto rw = run_wheel(s, w);
  ASSERT_FALSE(rw);
  EXPECT_EQ(rw.error().field, "WheelDef.slip");
  ShearDef sd;
  sd.blades = 1;
  auto rs = run_shear(s, sd);
  ASSERT_FALSE(rs);
  EXPECT_EQ(rs.error().field, "ShearDef.blades");
  BenchTerraArgs a;
  a.plates = {0.3};
  EXPECT_NE(check_bench_terra_args(a), "");
}

// The DEM: a 0.3 m plate pressed 7 cm into the bed. The pressure grows with the sinkage as a
// power between 0.7 and 2.5 (Bekker's n for soils is 0.5 to 1.5; bench terra fits it).
TEST(TerraRig, PlatePressureGrowsWithSinkage) {
  RigSetup s;
  s.scene = scene();
  s.bed_depth = 0.5;  // half the scene's bed: half the granules (the exponent's range holds on both)
  PlateDef d;
  d.width = 0.3;
  d.speed = 0.06;
  d.depth = 0.07;
  auto r = run_plate(s, d);
  ASSERT_TRUE(r) << r.message();
  std::vector<double> lz, lp;
  double p3 = 0, p6 = 0;
  for (std::size_t i = 0; i < r->curve.z.size(); ++i) {
    const double z = r->curve.z[i], p = r->curve.p[i];
    if (z >= 0.03 && z <= 0.07 && p > 0) {
      lz.push_back(std::log(z));
      lp.push_back(std::log(p));
    }
    if (std::abs(z - 0.03) < 0.003) p3 = std::max(p3, p);
    if (std::abs(z - 0.06) < 0.003) p6 = std::max(p6, p);
  }
  ASSERT_GE(lz.size(), 10u);
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < lz.size(); ++i) mx += lz[i], my += lp[i];
  mx /= double(lz.size());
  my /= double(lz.size());
  double sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < lz.size(); ++i) sxx += (lz[i] - mx) * (lz[i] - mx), sxy += (lz[i] - mx) * (lp[i] - my);
  const double n = sxy / sxx;
  EXPECT_GT(n, 0.7);
  EXPECT_LT(n, 2.5);
  EXPECT_GT(p6, 1.5 * p3);
  RecordProperty("n", std::to_string(n));
}

// The DEM wheel: at 30 % slip the soil pushes the wheel forward harder than at 0 % (the
// drawbar pull rises with slip: the shear displacement along the contact grows with it).
// Short drives (0.2 m): the heavy test runs the five slips to a steady state.
TEST(TerraRig, DrawbarPullRisesWithSlip) {
  RigSetup s;
  s.scene = scene();
  s.bed_depth = 0.5;  // half the scene's bed: half the granules (measured on both: docs/validation.md)
  std::vector<double> dp;
  for (double slip : {0.0, 0.3}) {
    WheelDef d;
    d.slip = slip;
    d.drive = 0.8;
    d.window_from = 0.3;
    auto r = run_wheel(s, d);
    ASSERT_TRUE(r) << r.message();
    EXPECT_NEAR(r->vertical, r->load, 0.15 * r->load);  // it carries its load
    EXPECT_TRUE(r->jointed);                            // carriage, slider, hub, motorised axle
    EXPECT_NEAR(r->slip, slip, 0.03);                   // the motor holds the commanded rate
    EXPECT_GT(r->sinkage, 0.0);
    dp.push_back(r->drawbar_pull);
  }
  EXPECT_GT(dp[1], dp[0] + 0.05 * 2943.0) << "DP at 0 %: " << dp[0] << " N, at 30 %: " << dp[1] << " N";
}

}  // namespace
}  // namespace sandpatch::terra
