// tests bench/bench_collapse.cpp (bench/collapse.hpp): the power-law fit against hand-computed
// values, the definition's checks, and two short column collapses against the published
// planar runout law for small aspect ratios (docs/validation.md "Granular column collapse").
// The full sweep with the fitted exponents is the heavy test bench_collapse_heavy_test.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "bench/collapse.hpp"

using namespace sandpatch;

TEST(CollapseFit, RecoversAnExactPowerLaw) {
  const std::vector<double> a = {0.5, 1, 2, 4, 8};
  std::vector<double> y;
  for (double v : a) y.push_back(1.9 * std::pow(v, 2.0 / 3.0));
  const PowerFit f = fit_power_law(a, y);
  EXPECT_EQ(f.points, 5);
  EXPECT_NEAR(f.exponent, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(f.prefactor, 1.9, 1e-12);
  EXPECT_NEAR(f.exponent_se, 0.0, 1e-12);
  // the range selects points: lo <= x <= hi
  EXPECT_EQ(fit_power_law(a, y, 1, 4).points, 3);
  EXPECT_EQ(fit_power_law(a, y, 10).points, 0);
}

// Three points with ln y = ln x + (+e, -2e, +e) at ln x = -1, 0, 1: slope 1 exactly (the
// residual pattern is orthogonal to ln x), intercept 0, RSS = 6 e^2, s^2 = RSS / (3 - 2),
// Sxx = 2, so SE(n) = sqrt(6 e^2 / 2) = sqrt(3) e and SE(ln k) = sqrt(6 e^2 / 3) = sqrt(2) e.
TEST(CollapseFit, StandardErrorsMatchTheFormula) {
  const double e = 0.05;
  const std::vector<double> x = {std::exp(-1.0), 1.0, std::exp(1.0)};
  const std::vector<double> y = {std::exp(-1.0 + e), std::exp(-2 * e), std::exp(1.0 + e)};
  const PowerFit f = fit_power_law(x, y);
  EXPECT_NEAR(f.exponent, 1.0, 1e-12);
  EXPECT_NEAR(f.prefactor, 1.0, 1e-12);
  EXPECT_NEAR(f.exponent_se, std::sqrt(3.0) * e, 1e-12);
  EXPECT_NEAR(f.log_prefactor_se, std::sqrt(2.0) * e, 1e-12);
}

TEST(Collapse, BadDefinitionNamesTheField) {
  CollapseDef c;
  c.aspect = -1;
  auto r = run_collapse(c);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "CollapseDef.aspect");
  EXPECT_NE(r.message().find("[0.2, 16]"), std::string::npos) << r.message();
  c = CollapseDef{};
  c.friction = std::nanf("");
  EXPECT_EQ(check_collapse(c).error().field, "CollapseDef.friction");
  // a column too large to allocate is refused before anything is allocated
  c = CollapseDef{};
  c.aspect = 16;
  c.length_granules = 64;
  c.width_granules = 32;
  EXPECT_EQ(check_collapse(c).error().field, "CollapseDef.aspect");
  BenchCollapseArgs b;
  b.aspects = {0.1};
  EXPECT_NE(check_bench_collapse_args(b).find("--aspects"), std::string::npos);
}

// Two short columns (the default slot: L0 = 10 lattice columns, 3 wide, mu = 0.5, one thread),
// three seeds each, against the planar law of Lube et al. (2005) for small aspect ratios,
// (l_inf - L0) / L0 = 1.2 a. One column's runout scatters from seed to seed (at a ~ 1 the
// ratio to the law is 1.06, 0.75, 0.78 for seeds 1, 2, 3; at a ~ 0.5 0.71, 0.96, 1.09: the
// column is 6 granules tall and a granule is 0.1 L0), so the mean over the seeds is asserted:
// measured 0.86 (a ~ 1) and 0.92 (a ~ 0.5), asserted within 25 % of the law (the narrow
// slot's walls brake the flow: docs/validation.md). Each column's top survives (h_inf / H0 >
// 0.9: the published h_inf = H0 below a ~ 1) and its front stops within 3 to 7 sqrt(H0 / g).
TEST(Collapse, SmallColumnsFollowThePlanarRunoutLaw) {
  for (double aspect : {1.0, 0.5}) {
    double sum = 0;
    for (std::uint64_t seed : {1, 2, 3}) {
      CollapseDef c;
      c.aspect = aspect;
      c.seed = seed;
      c.threads = 1;
      auto r = run_collapse(c);
      ASSERT_TRUE(r.ok()) << r.message();
      const double law = 1.2 * r->aspect;
      std::printf("a = %.3f (target %.2f, seed %llu): (l_inf - L0)/L0 = %.3f, law 1.2 a = %.3f (ratio %.2f), "
                  "h_inf/H0 = %.3f, t_stop = %.2f s = %.2f sqrt(H0/g), %d granules, %.1f s wall\n",
                  r->aspect, aspect, (unsigned long long)seed, r->runout, law, r->runout / law, r->h_inf / r->H0,
                  r->t_stop, r->t_stop / std::sqrt(r->H0 / 9.81), r->granules, r->wall_seconds);
      sum += r->runout / law;
      EXPECT_NEAR(r->aspect, aspect, 0.25 * aspect);
      EXPECT_GT(r->h_inf / r->H0, 0.9);
      const double t = r->t_stop / std::sqrt(r->H0 / 9.81);
      EXPECT_GT(t, 3.0);
      EXPECT_LT(t, 7.0);
      EXPECT_LE(r->ejected, 2);
    }
    std::printf("a ~ %.2f: mean ratio to 1.2 a over seeds 1-3: %.3f\n", aspect, sum / 3);
    EXPECT_NEAR(sum / 3, 1.0, 0.25) << "target a = " << aspect;
  }
}

// Determinism: the same column gives the same deposit with one thread or two.
TEST(Collapse, SameDepositForAnyThreadCount) {
  CollapseDef c;
  c.aspect = 0.5;
  c.threads = 1;
  auto one = run_collapse(c);
  c.threads = 2;
  auto two = run_collapse(c);
  ASSERT_TRUE(one.ok() && two.ok());
  EXPECT_EQ(one->l_inf, two->l_inf);
  EXPECT_EQ(one->h_inf, two->h_inf);
  EXPECT_EQ(one->H0, two->H0);
  EXPECT_EQ(one->profile, two->profile);
}
