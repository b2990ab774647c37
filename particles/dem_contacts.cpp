// Granule DEM, CPU backend: the contact stage's pair pass (dem.hpp step 3). Each pair is
// computed once with the contact law of shaders/dem/physics_common.glsl (particles/contact.hpp),
// or 8 at a time by the AVX2 kernel (contact_avx2.cpp, checked against it by
// tests/particles/contact_avx2_test.cpp), and added to both spheres' sums. dem_impl.hpp.
#include "particles/dem_impl.hpp"

#include <omp.h>
#include <cstdlib>
#include <cstring>

#include "particles/contact.hpp"
#include "particles/contact_simd.hpp"

namespace sandpatch {

bool simd::use_avx2_pair_kernel() {
#ifdef SANDPATCH_AVX2_KERNEL
  const char* k = std::getenv("SANDPATCH_DEM_KERNEL");
  return simd::avx2_available() && !(k && std::strcmp(k, "scalar") == 0);
#else
  return false;
#endif
}

// The slabs of each parity in `runs` contiguous runs of about equal work (dem_impl.hpp
// slab_runs); the slabs' work is counted again after a sort or a change of the sleeping regions.
void Simulation::Impl::plan_slab_runs(int runs) {
  const int nchunks = std::max(0, int(chunk_start.size()) - 1);
  const std::int32_t* CS = chunk_start.data();
  const std::int32_t* NS = nstart.data();
  const std::uint8_t* DZ = def.sleep_regions ? sphere_dozing.data() : nullptr;
  slab_runs.assign(2 * std::size_t(runs + 1), 0);
  if (runs > 1 && (slab_work_epoch != work_epoch || int(slab_work.size()) != nchunks)) {
    slab_work.assign(std::size_t(nchunks), 0);
    for (int c = 0; c < nchunks; ++c) {
      std::int64_t w = 0;
      // (an awake sphere's row: every pair's distance, the touching ones' law; a sleeping
      // sphere's: a test of each partner's sleep)
      for (int i = CS[c]; i < CS[c + 1]; ++i) w += DZ && DZ[i] ? 1 + (NS[i + 1] - NS[i]) / 2 : 2 + 2 * (NS[i + 1] - NS[i]);
      slab_work[std::size_t(c)] = w;
    }
    slab_work_epoch = work_epoch;
  }
  for (int parity = 0; parity < 2; ++parity)
    split_in_runs(nchunks > parity ? (nchunks - parity + 1) / 2 : 0, runs,
                  &slab_runs[std::size_t(parity) * std::size_t(runs + 1)],
                  [&](int k) { return runs > 1 ? slab_work[std::size_t(parity + 2 * k)] : 0; });
}

// ---- contact stage, pair pass: each pair is computed once, by its owner's entry, and added
// to both spheres' sums (acc; read by gather_sphere4 in the body stage), slab by slab
void Simulation::Impl::contacts(float dt) {
  const Material& mat = def.material;
  const float kn = mat.normal_stiffness;
  const float cn0 = float(2.0 * zeta * std::sqrt(double(mat.normal_stiffness)));  // c_n = cn0 sqrt(m_eff)
  const float kt = mat.normal_stiffness * mat.tangential_stiffness_ratio;
  const float ctr = mat.tangential_damping_ratio;
  const float mu = mat.friction;
  const float* P = p.pos.data();
  const float* V = p.vel.data();
  const float* W = p.omega.data();
  const std::uint8_t* DZ = def.sleep_regions ? sphere_dozing.data() : nullptr;  // asleep in a still region
  const std::int32_t* NS = nstart.data();
  const std::int32_t* NB = nbr.data();
  const std::int32_t* CS = chunk_start.data();
  float* XI = pairs.xi.data();
  float* ACC = acc.data()->v;
  std::uint8_t* TCH = pairs.touch.data();
  std::int64_t npairs = 0;
  const int n = np;
  law = {kn, cn0, kt, ctr, mu};  // for gather_sphere4
  const bool led = ledger;
  const bool hysteretic = mat.unloading_stiffness_ratio > 1.0f;
  const float kn2 = hysteretic ? kn * mat.unloading_stiffness_ratio : kn;  // unloading stiffness, N/m
  float* DM = pairs.dmax.data();
  double led_n = 0, led_f = 0, led_u = 0;
  if (led) ledger_spring_walls = 0;  // summed again by this substep's boundary contacts

  // the pair's force f on i (N) and n x f_t (N) into both sums: i gets +f, j gets -f, both
  // + n x f_t (their torques about their centres are -r_i and -r_j times it)
  auto add_pair = [&](int i, int j, __m128 f4, __m128 c4) __attribute__((always_inline)) {
    float* ai = ACC + kAcc * std::size_t(i);
    float* aj = ACC + kAcc * std::size_t(j);
    _mm_storeu_ps(ai, _mm_add_ps(_mm_loadu_ps(ai), f4));
    _mm_storeu_ps(ai + 4, _mm_add_ps(_mm_loadu_ps(ai + 4), c4));
    _mm_storeu_ps(aj, _mm_sub_ps(_mm_loadu_ps(aj), f4));
    _mm_storeu_ps(aj + 4, _mm_add_ps(_mm_loadu_ps(aj + 4), c4));
  };
  // Sphere i as its pairs read it: centre (m), radius (m), velocity (m/s), its body's
  // inverse mass (1/kg) and r_i w_i (m/s).
  struct Own {
    Vec3 p;
    float r;
    Vec3 u;
    float invm;
    Vec3 rw;
  };
  // A touching pair of the walk: list entry e (its spring xe), partner j of radius rj (m),
  // d = p_i - p_j (m), d2 = |d|^2 (m^2) and rs = r_i + r_j (m).
  struct Touch {
    int e, j;
    float dx, dy, dz, rj, rs, d2;
    float* xe;
  };
  // A touching pair by the scalar law (contact.hpp): sphere i (o) and t.j, with the pair's
  // history (spring t.xe, touch flag tch, largest overlap dm) and c_n = cn; its force and
  // n x f_t into both sums and, with the ledger on, its dissipated work into ln, lf, lu.
  auto scalar_pair = [&](int i, const Own& o, const Touch& t, float cn, std::uint8_t& tch, float& dm, double& ln,
                         double& lf, double& lu) __attribute__((always_inline)) {
    const int j = t.j;
    float* xe = t.xe;
    const float inv = 1.0f / std::sqrt(t.d2);
    const float dist = t.d2 * inv;
    const Vec3 nrm{t.dx * inv, t.dy * inv, t.dz * inv};
    const Vec3 uj{V[4 * j], V[4 * j + 1], V[4 * j + 2]};
    const Vec3 rwj = t.rj * Vec3{W[4 * j], W[4 * j + 1], W[4 * j + 2]};
    // contact-point velocity (physics_common.glsl); the spheres' velocities are the
    // bodies' predicted to this substep's time (`bodies`)
    const Vec3 v = physics::pair_contact_velocity(o.u, uj, nrm, o.rw + rwj);
    Vec3 xi{xe[0], xe[1], xe[2]};  // zero for a new contact; carried over on rebuilds
    const ContactParams cp{kn, cn, kt, ctr * cn, mu, dt, first_law && tch == 0};  // new_contact: first substep
    tch = 1;
    const float xi2_old = dot(xi, xi);
    const float dm_old = dm;
    ContactForce cf = contact_force_h(cp, kn2, nrm, t.rs - dist, v, xi, dm);
    if (led) ledger_terms(kn, kn2, kt, t.rs - dist, dm_old, dm, nrm, v, dt, xi2_old, cf.f, cf.ft, xi, ln, lf, lu);
    xe[0] = xi.x;
    xe[1] = xi.y;
    xe[2] = xi.z;
    add_pair(i, j, from_vec3(cf.f), from_vec3(cross(nrm, cf.ft)));
  };
  // The walk over the entries [e0, e1) of sphere i's row in a list (partners pn, springs xs,
  // touch flags tch, largest overlaps dm): a pair apart (|d| >= r_i + r_j, or the same centre)
  // has its spring forgotten; a touching one is counted in `touching` and handed to
  // pair(i, sphere i, touch). The granules' list (slab by slab) and the shell list's.
  auto walk_row = [&](int i, int e0, int e1, const std::int32_t* pn, float* xs, std::uint8_t* tch, float* dm,
                      std::int64_t& touching, auto&& pair) __attribute__((always_inline)) {
    if (e0 == e1) return;
    const float ri = P[4 * i + 3];
    const Own o{{P[4 * i], P[4 * i + 1], P[4 * i + 2]}, ri, {V[4 * i], V[4 * i + 1], V[4 * i + 2]}, V[4 * i + 3],
                ri * Vec3{W[4 * i], W[4 * i + 1], W[4 * i + 2]}};
    // a sphere asleep in a still region skips its pairs with other sleeping spheres, their
    // history left as it is (dem_regions.cpp)
    const bool dozing_i = DZ && DZ[i];
    for (int e = e0; e < e1; ++e) {
      const int j = pn[e];
      if (dozing_i && DZ[j]) continue;
      const float dx = o.p.x - P[4 * j], dy = o.p.y - P[4 * j + 1], dz = o.p.z - P[4 * j + 2];
      const float rj = P[4 * j + 3];
      const float rs = ri + rj;
      const float d2 = dx * dx + dy * dy + dz * dz;
      float* xe = xs + 3 * std::size_t(e);
      if (d2 >= rs * rs || d2 <= 0.0f) {  // apart: the spring is forgotten
        tch[e] = 0;
        if (hysteretic) dm[e] = 0.0f;
        if (xe[0] != 0.0f || xe[1] != 0.0f || xe[2] != 0.0f) xe[0] = xe[1] = xe[2] = 0.0f;
        continue;
      }
      ++touching;
      pair(i, o, Touch{e, j, dx, dy, dz, rj, rs, d2, xe});
    }
  };
  // (one run a thread; inside another parallel region, as patches stepped side by side are,
  // the team is one thread)
  const int runs = n > kParallelSpheres && !omp_in_parallel() ? std::max(1, threads) : 1;
  plan_slab_runs(runs);
  const int* RUNS = slab_runs.data();
#pragma omp parallel num_threads(threads) if (n > kParallelSpheres)
  {
  // The walk both passes make over slab c: every entry of its spheres' rows (walk_row).
  auto walk_slab = [&](int c, std::int64_t& touching, auto&& pair) __attribute__((always_inline)) {
    for (int i = CS[c], i1 = CS[c + 1]; i < i1; ++i) walk_row(i, NS[i], NS[i + 1], NB, XI, TCH, DM, touching, pair);
  };
  if (simd_pairs && !ledger) {
  // pair pass, AVX2: the same walk; touching pairs are collected per thread into batches of
  // 8 and evaluated by the kernel (same results, contact_simd.hpp), then added to the sums in
  // pair order (the pass reads no sum, so the additions are those of the scalar pass). A
  // slab is one task, its last batch evaluated before the slab ends.
  const simd::PairLaw plaw{kn, cn0, kt, ctr, mu, dt, kn2};
  simd::PairBatch bt;
  int bi[simd::kPairLanes], bj[simd::kPairLanes];
  auto flush = [&]() {
    const int cnt = bt.count;
    for (int k = cnt; k < simd::kPairLanes; ++k) {  // idle lanes: a copy of lane 0
      bt.dx[k] = bt.dx[0], bt.dy[k] = bt.dy[0], bt.dz[k] = bt.dz[0], bt.d2[k] = bt.d2[0], bt.rs[k] = bt.rs[0];
      bt.dux[k] = bt.dux[0], bt.duy[k] = bt.duy[0], bt.duz[k] = bt.duz[0];
      bt.rwx[k] = bt.rwx[0], bt.rwy[k] = bt.rwy[0], bt.rwz[k] = bt.rwz[0];
      bt.invm[k] = bt.invm[0], bt.newc[k] = bt.newc[0];
      bt.xix[k] = bt.xix[0], bt.xiy[k] = bt.xiy[0], bt.xiz[k] = bt.xiz[0], bt.dmax[k] = bt.dmax[0];
    }
#ifdef SANDPATCH_AVX2_KERNEL
    simd::spring_pairs_avx2(plaw, bt);
#endif
    for (int k = 0; k < cnt; ++k) {
      float* xe = XI + 3 * std::size_t(bt.entry[k]);
      xe[0] = bt.xix[k], xe[1] = bt.xiy[k], xe[2] = bt.xiz[k];
      if (hysteretic) DM[bt.entry[k]] = bt.dmax[k];
      add_pair(bi[k], bj[k], _mm_setr_ps(bt.fx[k], bt.fy[k], bt.fz[k], 0.0f),
               _mm_setr_ps(bt.cx[k], bt.cy[k], bt.cz[k], 0.0f));
    }
    bt.count = 0;
  };
  for (int parity = 0; parity < 2; ++parity) {
  const int* R = RUNS + std::size_t(parity) * std::size_t(runs + 1);
#pragma omp for schedule(static, 1) reduction(+ : npairs)
  for (int run = 0; run < runs; ++run)
  for (int c = parity + 2 * R[run]; c < parity + 2 * R[run + 1]; c += 2) {
    bt.count = 0;
    walk_slab(c, npairs, [&](int i, const Own& o, const Touch& t) __attribute__((always_inline)) {
      const int k = bt.count++;
      const int j = t.j, e = t.e;
      const Vec3 du = o.u - Vec3{V[4 * j], V[4 * j + 1], V[4 * j + 2]};
      const Vec3 rw = o.rw + t.rj * Vec3{W[4 * j], W[4 * j + 1], W[4 * j + 2]};
      bt.dx[k] = t.dx, bt.dy[k] = t.dy, bt.dz[k] = t.dz, bt.d2[k] = t.d2, bt.rs[k] = t.rs;
      bt.dux[k] = du.x, bt.duy[k] = du.y, bt.duz[k] = du.z;
      bt.rwx[k] = rw.x, bt.rwy[k] = rw.y, bt.rwz[k] = rw.z;
      bt.invm[k] = o.invm + V[4 * j + 3];
      bt.newc[k] = first_law && TCH[e] == 0 ? 1.0f : 0.0f;  // first substep (ContactParams::new_contact)
      TCH[e] = 1;
      bt.xix[k] = t.xe[0], bt.xiy[k] = t.xe[1], bt.xiz[k] = t.xe[2];
      bt.dmax[k] = DM[e];
      bt.entry[k] = e;
      bi[k] = i, bj[k] = j;
      if (bt.count == simd::kPairLanes) flush();
    });
    if (bt.count > 0) flush();
  }
  }
  } else {
  // pair pass: each entry computes its pair once
  for (int parity = 0; parity < 2; ++parity) {
  const int* R = RUNS + std::size_t(parity) * std::size_t(runs + 1);
#pragma omp for schedule(static, 1) reduction(+ : npairs, led_n, led_f, led_u)
  for (int run = 0; run < runs; ++run)
  for (int c = parity + 2 * R[run]; c < parity + 2 * R[run + 1]; c += 2) {
    // c_n = 2 zeta sqrt(k_n m_eff); granule beds repeat the same mass pair, so the last value
    // is reused while the pair's inverse masses are the same
    float last_invm_i = -1.0f, last_invm_j = -1.0f, last_cn = 0.0f;
    walk_slab(c, npairs, [&](int i, const Own& o, const Touch& t) __attribute__((always_inline)) {
      const float invm_j = V[4 * t.j + 3];
      if (invm_j != last_invm_j || o.invm != last_invm_i) {
        last_invm_i = o.invm;
        last_invm_j = invm_j;
        last_cn = cn0 / std::sqrt(o.invm + invm_j);
      }
      scalar_pair(i, o, t, last_cn, TCH[t.e], DM[t.e], led_n, led_f, led_u);
    });
  }
  }
  }  // scalar pair pass
  }  // omp parallel
  // the shell list's pairs, in list order on this thread (dem_impl.hpp: a few per shell sphere
  // near the sand), after the slabs': the same sums for any thread count
  {
    const std::int32_t* SN = snbr.data();
    float* SXI = spairs.xi.data();
    std::uint8_t* STCH = spairs.touch.data();
    float* SDM = spairs.dmax.data();
    std::int64_t touching = 0;
    for (int r = 0, rows = int(srow.size()); r < rows; ++r)
      walk_row(srow[std::size_t(r)], sstart[std::size_t(r)], sstart[std::size_t(r) + 1], SN, SXI, STCH, SDM, touching,
               [&](int i, const Own& o, const Touch& t) {
                 scalar_pair(i, o, t, cn0 / std::sqrt(o.invm + V[4 * t.j + 3]), STCH[t.e], SDM[t.e], led_n, led_f, led_u);
               });
    npairs += touching;
  }
  ledger_normal += led_n;
  ledger_friction += led_f;
  if (led) ledger_spring_pairs = led_u;
  stats.contacts = npairs;
  stats.neighbour_entries = (nstart.empty() ? 0 : nstart.back()) + std::int64_t(snbr.size());
}

}  // namespace sandpatch
