// tests particles/contact_avx2.cpp: the 8-lane AVX2 copy of the contact law against the shared
// scalar law (shaders/dem/physics_common.glsl through particles/contact.hpp) and the scalar
// pair pass's geometry around it (particles/dem_contacts.cpp), on random touching pairs.
//
// Tolerance: each output vector (force on sphere i, n x f_t, the updated spring xi) within
// 1e-6 of its magnitude plus 1e-12 (N or m) of the scalar one. The kernel is written to give
// the same bits (same operation order, -ffp-contract=off); the test reports how many lanes were
// bit-identical, and tests/particles/dem_test.cpp compares the two paths' state hashes
// (Simulation.Avx2PairKernelMatchesScalarBitForBit).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include "particles/contact.hpp"
#include "particles/contact_simd.hpp"

namespace sandpatch {
namespace {

struct Lane {
  Vec3 f, c, xi;
  float dmax = 0;
};

// The scalar pair pass for one lane of the batch (as particles/dem_contacts.cpp).
Lane scalar_lane(const simd::PairLaw& law, const simd::PairBatch& b, int k) {
  const float inv = 1.0f / std::sqrt(b.d2[k]);
  const float dist = b.d2[k] * inv;
  const Vec3 nrm{b.dx[k] * inv, b.dy[k] * inv, b.dz[k] * inv};
  const Vec3 v = physics::pair_contact_velocity(Vec3{b.dux[k], b.duy[k], b.duz[k]}, Vec3{}, nrm,
                                                Vec3{b.rwx[k], b.rwy[k], b.rwz[k]});
  const float cn = law.cn0 / std::sqrt(b.invm[k]);
  Vec3 xi{b.xix[k], b.xiy[k], b.xiz[k]};
  const ContactParams cp{law.kn, cn, law.kt, law.ctr * cn, law.mu, law.dt, b.newc[k] != 0.0f};
  float dm = b.dmax[k];
  const ContactForce cf = contact_force_h(cp, law.kn2, nrm, b.rs[k] - dist, v, xi, dm);
  return {cf.f, cross(nrm, cf.ft), xi, dm};
}

double norm(Vec3 a) { return std::sqrt(double(a.x) * a.x + double(a.y) * a.y + double(a.z) * a.z); }
bool same_bits(Vec3 a, Vec3 b) { return a.x == b.x && a.y == b.y && a.z == b.z; }

// Random touching pairs through the kernel and the scalar law; lambda = kn2 / k_n (1: linear).
// With lambda > 1 each lane also carries a largest overlap from before: none (a new contact),
// below the overlap now (loading) or above it (unloading, or the spring already open).
void random_pairs_match(const simd::PairLaw& law) {
  const bool hyst = law.kn2 > law.kn;
  const float m = 2500.0f * 4.0f / 3.0f * 3.14159265f * 0.005f * 0.005f * 0.005f;
  std::mt19937 rng(12345);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f), u01(0.0f, 1.0f);
  int lanes = 0, exact = 0;
  double worst = 0;
  for (int batch = 0; batch < 2000; ++batch) {
    simd::PairBatch b;
    for (int k = 0; k < simd::kPairLanes; ++k) {
      const float ri = 0.005f * (0.5f + u01(rng)), rj = 0.005f * (0.5f + u01(rng));
      Vec3 d{u(rng), u(rng), u(rng)};
      while (length(d) < 0.1f) d = {u(rng), u(rng), u(rng)};
      const float len = length(d);
      const float dist = (ri + rj) * (0.9f + 0.0999f * u01(rng));  // touching: overlap up to 10 %
      d = d * (dist / len);
      b.dx[k] = d.x, b.dy[k] = d.y, b.dz[k] = d.z;
      b.d2[k] = d.x * d.x + d.y * d.y + d.z * d.z;
      b.rs[k] = ri + rj;
      b.dux[k] = 0.5f * u(rng), b.duy[k] = 0.5f * u(rng), b.duz[k] = 0.5f * u(rng);
      b.rwx[k] = 0.05f * u(rng), b.rwy[k] = 0.05f * u(rng), b.rwz[k] = 0.05f * u(rng);
      const int kind = batch % 3;  // granule pairs, a granule against a static sphere, mixed masses
      b.invm[k] = kind == 0 ? 2.0f / m : (kind == 1 ? 1.0f / m : (1.0f + 3.0f * u01(rng)) / m);
      b.newc[k] = u01(rng) < 0.3f ? 1.0f : 0.0f;
      // springs from nothing to beyond the slip limit (mu k_n delta / k_t ~ 1e-4 m here)
      const float xs = u01(rng) < 0.2f ? 0.0f : 3e-4f * u01(rng);
      b.xix[k] = xs * u(rng), b.xiy[k] = xs * u(rng), b.xiz[k] = xs * u(rng);
      const float overlap = b.rs[k] - dist, pick = u01(rng);
      b.dmax[k] = !hyst || pick < 0.2f ? 0.0f : overlap * (pick < 0.5f ? u01(rng) : 1.0f + 0.3f * u01(rng));
    }
    b.count = simd::kPairLanes;
    Lane ref[simd::kPairLanes];
    for (int k = 0; k < simd::kPairLanes; ++k) ref[k] = scalar_lane(law, b, k);
    simd::spring_pairs_avx2(law, b);
    for (int k = 0; k < simd::kPairLanes; ++k) {
      const Lane got{{b.fx[k], b.fy[k], b.fz[k]}, {b.cx[k], b.cy[k], b.cz[k]}, {b.xix[k], b.xiy[k], b.xiz[k]}, b.dmax[k]};
      EXPECT_EQ(got.dmax, ref[k].dmax) << "batch " << batch << " lane " << k;
      const Vec3 g[3] = {got.f, got.c, got.xi}, r[3] = {ref[k].f, ref[k].c, ref[k].xi};
      bool all_exact = true;
      for (int q = 0; q < 3; ++q) {
        const double diff = norm(g[q] - r[q]), tol = 1e-6 * norm(r[q]) + 1e-12;
        worst = std::max(worst, diff / (norm(r[q]) + 1e-12));
        EXPECT_LE(diff, tol) << "batch " << batch << " lane " << k << " output " << q;
        all_exact = all_exact && same_bits(g[q], r[q]);
      }
      ++lanes;
      exact += all_exact;
    }
  }
  std::printf("lambda %.3f: %d lanes: %d bit-identical to the shared scalar law, worst relative difference %.3g\n",
              double(law.kn2 / law.kn), lanes, exact, worst);
  EXPECT_EQ(exact, lanes) << "the kernel is written to give the scalar law's bits";
}

// the default material (k_n = 3292 N/m, e = 0.3: zeta = 0.4972, k_t = 2/7 k_n, c_t = c_n/2,
// mu = 0.5), r = 5 mm spheres of 2500 kg/m^3, substep 1e-5 s
constexpr float kKn = 3292.0f, kZeta = 0.497239f;

TEST(ContactAvx2, MatchesSharedScalarLawOnRandomPairs) {
  if (!simd::avx2_available()) GTEST_SKIP() << "this CPU has no AVX2";
  random_pairs_match({kKn, float(2.0 * kZeta * std::sqrt(double(kKn))), kKn * 2.0f / 7.0f, 0.5f, 0.5f, 1e-5f, kKn});
}

// The hysteretic normal spring (Walton & Braun): lambda = 11.1 with no dashpot (e = 1: the
// e = 0.3 material of docs/dem.md "Hysteretic normal spring"), and lambda = 4 with the e = 0.3
// dashpot as well.
TEST(ContactAvx2, HystereticLaneMatchesSharedScalarLaw) {
  if (!simd::avx2_available()) GTEST_SKIP() << "this CPU has no AVX2";
  random_pairs_match({kKn, 0.0f, kKn * 2.0f / 7.0f, 0.5f, 0.5f, 1e-5f, kKn * 11.111111f});
  random_pairs_match({kKn, float(2.0 * kZeta * std::sqrt(double(kKn))), kKn * 2.0f / 7.0f, 0.5f, 0.5f, 1e-5f, kKn * 4.0f});
}

}  // namespace
}  // namespace sandpatch
