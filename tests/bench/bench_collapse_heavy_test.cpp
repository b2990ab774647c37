// HEAVY: the full quasi-2D column-collapse sweep of `sandpatch bench collapse` (nine aspect
// ratios 0.5 ... 8, L0 = 10 lattice columns, slot 3 wide, mu = 0.5, seed 1, one thread; about
// 6-8 minutes on a busy two-core machine) and its fitted exponents against the published ones
// (docs/validation.md "Granular column collapse" has the table and the references):
//   runout (l_inf - L0)/L0 = k a^n, target a <= 2 (measured 0.58-1.81): Lube et al. 2005 (planar) n = 1;
//                                    target a >= 3 (2.71-6.53): Lube et al. 2005 n = 2/3, Balmforth & Kerswell
//                                    2005 narrow slots n = 0.65 +- 0.05;
//   (the short columns run with seeds 1, 2 and 3 and are fitted together);
//   final height h_inf/L0 = k a^n, target a >= 3: Balmforth & Kerswell n = 0.5 (narrow) / 0.4
//                                    (wide). The model does NOT agree here (measured 0.58):
//                                    asserted is what it gives, documented as a disagreement.
// Run: ctest --test-dir build -R CollapseHeavy --output-on-failure (or ./build/tests/bench/bench_collapse_heavy_test)
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "bench/collapse.hpp"

using namespace sandpatch;

TEST(CollapseHeavy, SweepExponentsAgainstThePublishedScalings) {
  const std::vector<double> targets = {0.5, 0.75, 1, 1.5, 2, 3, 4, 6, 8};
  std::vector<double> a, runout, height;
  std::vector<double> a_lo, r_lo, a_hi, r_hi, h_hi;  // split on the target a: <= 2 and >= 3
  for (double t : targets) {
    CollapseDef c;
    c.aspect = t;
    c.threads = 1;
    auto r = run_collapse(c);
    ASSERT_TRUE(r.ok()) << r.message();
    std::printf("a = %.3f: (l_inf - L0)/L0 = %.3f, h_inf/L0 = %.3f, %d granules, %.1f s wall\n", r->aspect,
                r->runout, r->height, r->granules, r->wall_seconds);
    std::fflush(stdout);
    a.push_back(r->aspect);
    runout.push_back(r->runout);
    height.push_back(r->height);
    if (t <= 2.5) {
      a_lo.push_back(r->aspect), r_lo.push_back(r->runout);
    } else {
      a_hi.push_back(r->aspect), r_hi.push_back(r->runout), h_hi.push_back(r->height);
    }
    // every deposit grows with a (the sweep is monotone in the runout)
    if (a.size() >= 2) {
      EXPECT_GT(runout.back(), 0.9 * runout[runout.size() - 2]);
    }
  }
  // the short columns again with seeds 2 and 3: one column's runout scatters (the low-a
  // exponent of seeds 1, 2, 3 alone: 1.17, 0.87, 0.84), the pooled fit is asserted
  for (std::uint64_t seed : {2, 3}) {
    for (double t : targets) {
      if (t > 2.5) continue;
      CollapseDef c;
      c.aspect = t;
      c.seed = seed;
      c.threads = 1;
      auto r = run_collapse(c);
      ASSERT_TRUE(r.ok()) << r.message();
      std::printf("seed %llu, a = %.3f: (l_inf - L0)/L0 = %.3f\n", (unsigned long long)seed, r->aspect, r->runout);
      a_lo.push_back(r->aspect), r_lo.push_back(r->runout);
    }
  }
  const PowerFit lo = fit_power_law(a_lo, r_lo), hi = fit_power_law(a_hi, r_hi), h = fit_power_law(a_hi, h_hi);
  std::printf("runout low a: n = %.3f +- %.3f, k = %.3f; high a: n = %.3f +- %.3f, k = %.3f; "
              "height high a: n = %.3f +- %.3f, k = %.3f\n",
              lo.exponent, lo.exponent_se, lo.prefactor, hi.exponent, hi.exponent_se, hi.prefactor, h.exponent,
              h.exponent_se, h.prefactor);
  ASSERT_EQ(lo.points, 15);
  ASSERT_EQ(hi.points, 4);
  // low a, seeds 1-3 pooled: linear (n = 1) within 2 standard errors (measured 0.96 +- 0.09),
  // prefactor within 25 % of Lube's 1.2 (measured 1.01: the narrow slot's walls brake the flow)
  EXPECT_NEAR(lo.exponent, 1.0, 2 * lo.exponent_se);
  EXPECT_NEAR(lo.prefactor / 1.2, 1.0, 0.25);
  // high a: within the combined uncertainty (2 sigma) of Balmforth & Kerswell's narrow slots,
  // 0.65 +- 0.05 (measured 0.725 +- 0.039), and inside [0.55, 0.85] whatever the fit's SE
  const double sigma = std::sqrt(hi.exponent_se * hi.exponent_se + 0.05 * 0.05);
  EXPECT_NEAR(hi.exponent, 0.65, 2 * sigma);
  EXPECT_GT(hi.exponent, 0.55);
  EXPECT_LT(hi.exponent, 0.85);
  // the runout law's change of regime: the high-a exponent is below the low-a one
  EXPECT_LT(hi.exponent, lo.exponent);
  // final height: the disagreement, asserted as measured (0.58 +- 0.02 against the published
  // 0.4 - 0.5): the exponent stays in [0.5, 0.75]
  EXPECT_GT(h.exponent, 0.5);
  EXPECT_LT(h.exponent, 0.75);
}
