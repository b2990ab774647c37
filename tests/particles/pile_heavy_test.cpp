// Angle of repose, HEAVY (issue #3): three seeds at mu = 0.5 and a friction sweep of poured
// piles of 800 granules (particles/pile.hpp). Prints the mu -> angle table of docs/dem.md.
// Seven piles of about a minute each on one core.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <vector>

#include "particles/pile.hpp"

namespace sandpatch {

namespace {
ReposeResult pile(float mu, std::uint64_t seed) {
  PileDef d;
  d.material.friction = mu;
  d.seed = seed;
  d.granules = 800;  // twice the fast test's pile: more flank bins, less scatter
  auto r = measure_repose(d);
  EXPECT_TRUE(r.ok()) << r.message();
  if (!r) return {};
  std::printf("mu %.2f seed %llu: angle %.2f deg, residual %.2g m over %d bins, height %.3f m, %d granules, "
              "%.2f s simulated, %.1f s wall, at rest %d (%.2g m/s)\n",
              mu, (unsigned long long)seed, r->angle_deg, r->residual, r->fit_points, r->peak, r->granules,
              r->sim_seconds, r->wall_seconds, int(r->at_rest), r->final_speed);
  std::fflush(stdout);
  return *r;
}
}  // namespace

// Three seeds at mu = 0.5: each in 25-40 degrees, all within +-2 degrees of their mean (the
// issue's criterion). The sweep mu = 0.2, 0.35, 0.5, 0.7, 1.0 (seed 1): the angle rises with
// mu: no step up in mu gives an angle lower by more than the seed spread measured at mu = 0.5
// (max - min of the three seeds, at least 2 degrees: one seed per mu is one sample), and
// mu = 1.0 stands at least 4 degrees above mu = 0.2.
TEST(PileHeavy, SeedsAndFrictionSweep) {
  std::vector<double> seeds;
  for (std::uint64_t s : {1, 2, 3}) {
    ReposeResult r = pile(0.5f, s);
    EXPECT_TRUE(r.at_rest);
    EXPECT_GE(r.angle_deg, 25.0);
    EXPECT_LE(r.angle_deg, 40.0);
    seeds.push_back(r.angle_deg);
  }
  double mean = (seeds[0] + seeds[1] + seeds[2]) / 3;
  for (double a : seeds) EXPECT_NEAR(a, mean, 2.0);
  const std::vector<float> mus{0.2f, 0.35f, 0.5f, 0.7f, 1.0f};
  std::vector<double> ang;
  for (float mu : mus) ang.push_back(mu == 0.5f ? seeds[0] : pile(mu, 1).angle_deg);
  std::printf("\n| mu | angle (deg), seed 1 |\n|---|---|\n");
  for (std::size_t k = 0; k < mus.size(); ++k) std::printf("| %.2f | %.1f |\n", mus[k], ang[k]);
  std::printf("mu = 0.5, seeds 1-3: %.1f, %.1f, %.1f (mean %.1f)\n", seeds[0], seeds[1], seeds[2], mean);
  const double spread = std::max(2.0, *std::max_element(seeds.begin(), seeds.end()) -
                                          *std::min_element(seeds.begin(), seeds.end()));
  for (std::size_t k = 1; k < ang.size(); ++k) EXPECT_GT(ang[k], ang[k - 1] - spread) << "mu " << mus[k];
  EXPECT_GT(ang.back(), ang.front() + 4.0);
}

}  // namespace sandpatch
