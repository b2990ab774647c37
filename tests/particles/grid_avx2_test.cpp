// tests particles/grid_avx2.cpp: the neighbour search's 8-lane distance test against the
// scalar test of particles/dem_grid.cpp (for_forward), written out here: the same candidates,
// in the same order, for runs of every length from 0 to 20 and for runs whose last group of 8
// cannot be read whole (the one-by-one path). Exact: the output lists must be equal.
// tests/particles/dem_test.cpp (Simulation.Avx2PairKernelMatchesScalarBitForBit) compares whole
// runs of both paths by their state hashes.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "particles/contact_simd.hpp"
#include "particles/grid_simd.hpp"

namespace sandpatch {
namespace {

// for_forward's test: near unless |p_i - p_j|^2 >= ((r_i + r_j) + skin)^2 (a NaN is near).
std::vector<std::int32_t> scalar_near(const std::vector<float>& P, const simd::SearchSphere& s,
                                     const std::vector<std::array<std::int32_t, 2>>& runs) {
  std::vector<std::int32_t> out;
  for (const auto& r : runs)
    for (int j = r[0]; j < r[1]; ++j) {
      const float dx = s.x - P[4 * j], dy = s.y - P[4 * j + 1], dz = s.z - P[4 * j + 2];
      const float rs = s.r + P[4 * j + 3] + s.skin;
      if (dx * dx + dy * dy + dz * dz >= rs * rs) continue;
      out.push_back(j);
    }
  return out;
}

std::vector<std::int32_t> simd_near(const std::vector<float>& P, int readable, const simd::SearchSphere& s,
                                    const std::vector<std::array<std::int32_t, 2>>& runs) {
  std::vector<std::int32_t> out(P.size() / 4 + 1);
  const int n = simd::near_spheres_avx2(P.data(), readable, s, reinterpret_cast<const std::int32_t(*)[2]>(runs.data()),
                                        int(runs.size()), out.data());
  out.resize(std::size_t(n));
  return out;
}

TEST(GridAvx2, SameCandidatesInTheSameOrderAsTheScalarTest) {
  if (!simd::avx2_available()) GTEST_SKIP() << "no AVX2 on this CPU";
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> pos(-0.1f, 0.1f), rad(0.004f, 0.006f);
  const int n = 400;
  std::vector<float> P(4 * std::size_t(n));
  for (int j = 0; j < n; ++j) P[4 * j] = pos(rng), P[4 * j + 1] = pos(rng), P[4 * j + 2] = pos(rng), P[4 * j + 3] = rad(rng);
  // a sphere exactly at the reach (d2 == rs^2, not near), and one with a NaN centre (near)
  P[4 * 10] = 0.0f, P[4 * 10 + 1] = 0.0f, P[4 * 10 + 2] = 0.0f, P[4 * 10 + 3] = 0.005f;
  P[4 * 11 + 1] = std::numeric_limits<float>::quiet_NaN();
  int compared = 0, found = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const simd::SearchSphere s{pos(rng) * 0.3f, pos(rng) * 0.3f, pos(rng) * 0.3f, rad(rng), 0.0025f};
    std::vector<std::array<std::int32_t, 2>> runs;
    const int nruns = 1 + trial % 5;
    for (int k = 0; k < nruns; ++k) {
      const int len = (trial * 7 + k * 3) % 21;  // 0 .. 20
      const int j0 = (trial * 13 + k * 61) % (n - len);
      runs.push_back({j0, j0 + len});
    }
    if (trial % 50 == 0) runs.push_back({n - 5, n});  // a run at the array's end
    // all of P readable, then only up to the end of the last run (the one-by-one path)
    for (int readable : {n, runs.back()[1]}) {
      const auto a = simd_near(P, readable, s, runs), b = scalar_near(P, s, runs);
      ASSERT_EQ(a, b) << "trial " << trial << ", readable " << readable;
      ++compared, found += int(a.size());
    }
  }
  // sphere 10 at exactly the reach of a sphere at (0.015, 0, 0): d2 = rs^2, not a candidate;
  // sphere 11 (NaN) is one, as in the scalar test
  const simd::SearchSphere edge{0.0125f, 0.0f, 0.0f, 0.005f, 0.0025f};
  const std::vector<std::array<std::int32_t, 2>> runs{{8, 16}};
  EXPECT_EQ(simd_near(P, n, edge, runs), scalar_near(P, edge, runs));
  EXPECT_GT(found, 100) << "the random runs must include near spheres";
  std::printf("%d comparisons, %d near candidates\n", compared, found);
}

}  // namespace
}  // namespace sandpatch
