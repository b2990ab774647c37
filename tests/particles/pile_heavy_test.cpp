// Angle of repose, HEAVY: poured piles of 800 granules (particles/pile.hpp), three
// seeds at each mu of the sweep 0.2, 0.35, 0.5, 0.7, 1.0. Prints the mu -> angle table of
// docs/dem.md. Fifteen piles, two at a time (one per core, each single-threaded).
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <thread>
#include <vector>

#include "particles/pile.hpp"

namespace sandpatch {

namespace {
struct PileRun {
  float mu;
  std::uint64_t seed;
  bool ok = false;
  ReposeResult r;
};

// Runs the piles on two threads (each pile is one single-threaded Simulation, so the result
// does not depend on which thread runs it).
void run_piles(std::vector<PileRun>& runs) {
  std::atomic<std::size_t> next{0};
  auto work = [&] {
    for (std::size_t k; (k = next++) < runs.size();) {
      PileDef d;
      d.material.friction = runs[k].mu;
      d.seed = runs[k].seed;
      d.granules = 800;
      d.threads = 1;
      auto r = measure_repose(d);
      runs[k].ok = r.ok();
      if (r) runs[k].r = std::move(*r);
      std::printf("mu %.2f seed %llu: angle %.2f deg (cone fit, residual %.2g m over %d levels; flank fit %.2f deg), "
                  "height %.3f m, %d granules, %.2f s simulated, %.1f s wall, at rest %d (%.2g m/s)\n",
                  runs[k].mu, (unsigned long long)runs[k].seed, runs[k].r.angle_deg, runs[k].r.residual,
                  runs[k].r.fit_points, runs[k].r.flank_angle_deg, runs[k].r.peak, runs[k].r.granules,
                  runs[k].r.sim_seconds, runs[k].r.wall_seconds, int(runs[k].r.at_rest), runs[k].r.final_speed);
      std::fflush(stdout);
    }
  };
  std::thread t(work);
  work();
  t.join();
}
}  // namespace

// At mu = 0.5 the three seeds are at rest, each in 25-40 degrees and within +-2 degrees of
// their mean (the criteria). Over the sweep, the mean of the three seeds rises with mu:
// no step up in mu lowers the mean by more than 2 standard errors of a difference of two
// means (s_d = s sqrt(2/3), s = the seeds' standard deviation pooled over all mu), and
// mu = 1.0 stands above mu = 0.2 by more than 3 s_d.
TEST(PileHeavy, SeedsAndFrictionSweep) {
  const std::vector<float> mus{0.2f, 0.35f, 0.5f, 0.7f, 1.0f};
  const std::vector<std::uint64_t> seeds{1, 2, 3};
  std::vector<PileRun> runs;
  for (float mu : mus)
    for (std::uint64_t s : seeds) runs.push_back({mu, s});
  run_piles(runs);
  for (const PileRun& r : runs) {
    EXPECT_TRUE(r.ok) << "mu " << r.mu << " seed " << r.seed;
    EXPECT_TRUE(r.r.at_rest) << "mu " << r.mu << " seed " << r.seed << ": " << r.r.final_speed << " m/s";
  }
  const std::size_t ns = seeds.size();
  std::vector<double> mean(mus.size(), 0.0);
  double ss = 0;  // pooled sum of squared deviations
  for (std::size_t m = 0; m < mus.size(); ++m) {
    for (std::size_t s = 0; s < ns; ++s) mean[m] += runs[m * ns + s].r.angle_deg / double(ns);
    for (std::size_t s = 0; s < ns; ++s) ss += std::pow(runs[m * ns + s].r.angle_deg - mean[m], 2);
  }
  const double sd = std::sqrt(ss / double(mus.size() * (ns - 1)));
  const double sdiff = sd * std::sqrt(2.0 / double(ns));
  std::printf("\n| mu | angle (deg), seeds 1, 2, 3 | mean |\n|---|---|---|\n");
  for (std::size_t m = 0; m < mus.size(); ++m)
    std::printf("| %.2f | %.1f, %.1f, %.1f | %.1f |\n", mus[m], runs[m * ns].r.angle_deg, runs[m * ns + 1].r.angle_deg,
                runs[m * ns + 2].r.angle_deg, mean[m]);
  std::printf("pooled seed standard deviation %.2f deg; standard error of a difference of means %.2f deg\n", sd, sdiff);

  const std::size_t m05 = 2;  // mu = 0.5
  for (std::size_t s = 0; s < ns; ++s) {
    const double a = runs[m05 * ns + s].r.angle_deg;
    EXPECT_GE(a, 25.0) << "seed " << seeds[s];
    EXPECT_LE(a, 40.0) << "seed " << seeds[s];
    EXPECT_NEAR(a, mean[m05], 2.0) << "seed " << seeds[s];
  }
  for (std::size_t m = 1; m < mus.size(); ++m) EXPECT_GT(mean[m], mean[m - 1] - 2.0 * sdiff) << "mu " << mus[m];
  EXPECT_GT(mean.back(), mean.front() + 3.0 * sdiff);
}

}  // namespace sandpatch
