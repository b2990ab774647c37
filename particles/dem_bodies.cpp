// Granule DEM, CPU backend: the body stage (dem.hpp steps 4-5): each sphere takes the pair
// pass's sums and its boundary contacts, each body sums its spheres in id order, integrates
// (symplectic Euler, normalised quaternion) and rebuilds its spheres with the velocity the
// next contact stage sees; kinematic moves of an asleep simulation; push_body. dem_impl.hpp.
#include "particles/dem_impl.hpp"

#include <omp.h>
#include <algorithm>

#include "particles/dem_control.hpp"
#include "particles/granule.hpp"

namespace sandpatch {

// Rebuilds the spheres of body i from its pose x4 (m, lane 3 unused), q and the velocities
// v4, w4 (m/s, rad/s; lane 3 = 0) the spheres' contacts are to see; returns the largest
// squared displacement (m^2) of one of them since the last sort.
// In 4-wide SSE2 registers (baseline x86-64), every lane doing the float operations of the
// Vec3 formulas in their order: arm = R o with R's columns, lane k = dot(row k, o);
// cross(a, b) lane-wise as math.hpp's. Lane 3 is unused (the radius and the inverse mass
// are kept in the stores).
__attribute__((always_inline)) inline float Simulation::Impl::rebuild_body(int i, const __m128 x4, const Quat q,
                                                                          const __m128 v4, const __m128 w4, int k0,
                                                                          int k1) {
  // rotation matrix of q (rows), cheaper than 4 quaternion rotations
  const float xx = q.x * q.x, yy = q.y * q.y, zz = q.z * q.z, xy = q.x * q.y, xz = q.x * q.z, yz = q.y * q.z,
              wx = q.w * q.x, wy = q.w * q.y, wz = q.w * q.z;
  const Vec3 r0{1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)};
  const Vec3 r1{2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)};
  const Vec3 r2{2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)};
  const __m128 c0 = _mm_setr_ps(r0.x, r1.x, r2.x, 0.0f), c1 = _mm_setr_ps(r0.y, r1.y, r2.y, 0.0f),
               c2 = _mm_setr_ps(r0.z, r1.z, r2.z, 0.0f);
  const __m128 w_yzx = _mm_shuffle_ps(w4, w4, _MM_SHUFFLE(3, 0, 2, 1)),
               w_zxy = _mm_shuffle_ps(w4, w4, _MM_SHUFFLE(3, 1, 0, 2));
  const __m128 invm4 = _mm_set1_ps(b.mass[4 * i + 1]);
  float d2max = 0;
  // a granule's sphere offsets are the shape's (the values p.offset holds, without the load)
  const bool granule = b.flags[i] & kBodyGranule;
  for (int k = k0, first = b.first[i], cnt = k1 < 0 ? b.count[i] : k1; k < cnt; ++k) {
    const int s = slot_of[first + k];
    const float* O = granule ? &shape_offsets[4 * k] : &p.offset[4 * s];
    const __m128 arm = _mm_add_ps(_mm_add_ps(_mm_mul_ps(c0, _mm_set1_ps(O[0])), _mm_mul_ps(c1, _mm_set1_ps(O[1]))),
                                  _mm_mul_ps(c2, _mm_set1_ps(O[2])));
    const __m128 xs = _mm_add_ps(x4, arm);
    const __m128 arm_yzx = _mm_shuffle_ps(arm, arm, _MM_SHUFFLE(3, 0, 2, 1)),
                 arm_zxy = _mm_shuffle_ps(arm, arm, _MM_SHUFFLE(3, 1, 0, 2));
    const __m128 us = _mm_add_ps(v4, _mm_sub_ps(_mm_mul_ps(w_yzx, arm_zxy), _mm_mul_ps(w_zxy, arm_yzx)));
    float* P = &p.pos[4 * s];
    // (xs.x, xs.y, xs.z, P[3] = radius) and (us.x, us.y, us.z, 1/m)
    _mm_storeu_ps(P, _mm_shuffle_ps(xs, _mm_unpackhi_ps(xs, _mm_loadu_ps(P)), _MM_SHUFFLE(3, 0, 1, 0)));
    _mm_storeu_ps(&p.vel[4 * s], _mm_shuffle_ps(us, _mm_unpackhi_ps(us, invm4), _MM_SHUFFLE(3, 0, 1, 0)));
    _mm_storeu_ps(&p.omega[4 * s], w4);
    const __m128 d = _mm_sub_ps(xs, _mm_loadu_ps(&pos_at_sort[4 * s]));
    const __m128 dd = _mm_mul_ps(d, d);
    const float d2 = (_mm_cvtss_f32(dd) + _mm_cvtss_f32(_mm_shuffle_ps(dd, dd, 1))) +
                     _mm_cvtss_f32(_mm_shuffle_ps(dd, dd, 2));
    d2max = std::max(d2max, d2);
  }
  return d2max;
}

// The same from the body's stored pose, with the velocities v, w (the body stage passes them
// predicted to the next contact stage's time, see `bodies`).
float Simulation::Impl::rebuild_body(int i, Vec3 v, Vec3 w) {
  return rebuild_body(i, from_vec3(ld3(b.pos, i)), ldq(b.quat, i), from_vec3(v), from_vec3(w));
}

// The same with the body's stored velocities.
float Simulation::Impl::rebuild_body(int i) { return rebuild_body(i, ld3(b.vel, i), ld3(b.omega, i)); }

float Simulation::Impl::rebuild_spheres(int i, int k0, int k1, Vec3 v, Vec3 w) {
  return rebuild_body(i, from_vec3(ld3(b.pos, i)), ldq(b.quat, i), from_vec3(v), from_vec3(w), k0, k1);
}

Simulation::Impl::GatherCtx Simulation::Impl::gather_ctx() const {
  constexpr float inf = std::numeric_limits<float>::infinity();
  float x0 = -inf, x1 = inf, z0 = -inf, z1 = inf;
  if (def.side_walls) x0 = def.bounds_min.x, x1 = def.bounds_max.x, z0 = def.bounds_min.z, z1 = def.bounds_max.z;
  if (!def.terrain.empty()) {
    const TerrainGrid& tg = def.terrain;
    x0 = std::max(x0, tg.fill_min_x), x1 = std::min(x1, tg.fill_max_x);
    z0 = std::max(z0, tg.fill_min_z), z1 = std::min(z1, tg.fill_max_z);
  }
  return {law, p.pos.data(), p.vel.data(), p.omega.data(), const_cast<float*>(acc.data()->v),
          const_cast<float*>(p.wall_xi.data()), const_cast<std::uint32_t*>(p.wall_mask.data()),
          const_cast<float*>(p.wall_dmax.data()), law.kn * std::max(1.0f, def.material.unloading_stiffness_ratio),
          physics::Boundaries{def.floor_height, def.side_walls, !def.terrain.empty(), def.bounds_min, def.bounds_max},
          def.floor_height, first_law, x0, x1, z0, z1};
}

// Sphere i's force F4 and torque T4 about its centre (lane 3 = 0); returns its centre (lane 3 = 0).
__attribute__((always_inline)) inline __m128 Simulation::Impl::gather_sphere4(const GatherCtx& g, const int i,
                                                                             const float dt, std::int64_t& nwall,
                                                                             __m128& F4, __m128& T4) {
  const float* P = g.P;
  const __m128 P4 = _mm_loadu_ps(P + 4 * std::size_t(i));  // centre, radius
  const float ri = P[4 * i + 3];
  // sphere-sphere: the pair pass's sums, zeroed for the next substep
  float* A = g.ACC + kAcc * std::size_t(i);
  const __m128 Fs = _mm_loadu_ps(A), C4 = _mm_loadu_ps(A + 4);
  _mm_storeu_ps(A, _mm_setzero_ps());
  _mm_storeu_ps(A + 4, _mm_setzero_ps());
  F4 = xyz0(Fs);
  T4 = _mm_add_ps(_mm_setzero_ps(), _mm_mul_ps(xyz0(C4), _mm_set1_ps(-ri)));  // T{} + (-r_i) C
  // boundaries, for dynamic spheres near one (the rest only clear a mask left set)
  if (g.V[4 * i + 3] > 0.0f) {
    const float px = P[4 * i], py = P[4 * i + 1], pz = P[4 * i + 2];
    const std::uint32_t sides = (px - g.x0 < ri ? 2u : 0u) | (g.x1 - px < ri ? 4u : 0u) | (pz - g.z0 < ri ? 8u : 0u) |
                                (g.z1 - pz < ri ? 16u : 0u);
    const std::uint32_t slots = (py - g.floor_y < ri ? 1u : 0u) | sides | (sides ? 32u : 0u);
    if (slots) {
      Vec3 F = to_vec3(F4), T = to_vec3(T4);
      boundary_contacts(g, i, dt, slots, F, T, nwall);
      F4 = from_vec3(F), T4 = from_vec3(T);
    } else if (g.WM[i] != 0) {
      g.WM[i] = 0;
    }
  }
  return xyz0(P4);
}

// Adds the forces of body i's spheres [k0, k1) (its own order) to F and their torques about
// the body's centre to T (lane 3 = 0): T + T_s + (x_s - x) x F_s, sphere by sphere.
__attribute__((always_inline)) inline void Simulation::Impl::sum_spheres(const GatherCtx& gctx, const int i, const int k0,
                                                                        const int k1, const float dt,
                                                                        std::int64_t& nwall, __m128& F, __m128& T) {
  const __m128 x = xyz0(_mm_loadu_ps(&b.pos[4 * std::size_t(i)]));
  for (int k = k0, first = b.first[i]; k < k1; ++k) {
    __m128 Fs, Ts;
    const __m128 xs = gather_sphere4(gctx, slot_of[first + k], dt, nwall, Fs, Ts);
    F = _mm_add_ps(F, Fs);
    T = _mm_add_ps(_mm_add_ps(T, Ts), cross4(_mm_sub_ps(xs, x), Fs));
  }
}

// The body stage for granule i (dynamic, isotropic inertia): the formulas of the general
// path below in 4-wide SSE2 registers, each lane doing the scalar code's float operations in
// its order (the same results bit for bit, ~1/3 fewer instructions).
__attribute__((always_inline)) inline void Simulation::Impl::granule_update(const GatherCtx& gctx, const int i,
                                                                           const float dt, std::int64_t& nwall,
                                                                           float& d2max, float& vmax, int& bad) {
  float* const BP = &b.pos[4 * std::size_t(i)];
  float* const BV = &b.vel[4 * std::size_t(i)];
  float* const BW = &b.omega[4 * std::size_t(i)];
  const __m128 x_st = _mm_loadu_ps(BP), v_st = _mm_loadu_ps(BV), w_st = _mm_loadu_ps(BW);
  const __m128 x = xyz0(x_st), v_old = xyz0(v_st), w_old = xyz0(w_st);
  __m128 F = _mm_setzero_ps(), T = _mm_setzero_ps();
  for (int k = 0, first = b.first[i], cnt = b.count[i]; k < cnt; ++k) {
    __m128 Fs, Ts;
    const __m128 xs = gather_sphere4(gctx, slot_of[first + k], dt, nwall, Fs, Ts);
    F = _mm_add_ps(F, Fs);
    T = _mm_add_ps(_mm_add_ps(T, Ts), cross4(_mm_sub_ps(xs, x), Fs));  // T + T_s + (x_s - x) x F_s
  }
  float* const BF = &b.force[4 * std::size_t(i)];
  float* const BT = &b.torque[4 * std::size_t(i)];
  _mm_storeu_ps(BF, xyz_keep_w(F, _mm_loadu_ps(BF)));
  _mm_storeu_ps(BT, xyz_keep_w(T, _mm_loadu_ps(BT)));
  const __m128 dt4 = _mm_set1_ps(dt);
  const __m128 g4 = _mm_setr_ps(gravity.x, gravity.y, gravity.z, 0.0f);
  // v + dt (F / m + g), w + T (dt / I)
  const __m128 v = _mm_add_ps(v_old, _mm_mul_ps(dt4, _mm_add_ps(_mm_mul_ps(F, _mm_set1_ps(b.mass[4 * i + 1])), g4)));
  const __m128 w = _mm_add_ps(w_old, _mm_mul_ps(T, _mm_set1_ps(dt * b.inv_inertia[4 * i])));
  _mm_storeu_ps(BV, xyz_keep_w(v, v_st));
  _mm_storeu_ps(BW, xyz_keep_w(w, w_st));
  const float reach = shape.centre_distance + shape.radius;
  vmax = std::max(vmax, std::sqrt(norm2(v)) + std::sqrt(norm2(w)) * reach);
  const __m128 xn = _mm_add_ps(x, _mm_mul_ps(dt4, v));
  alignas(16) float xa[4], va[4], wa[4];
  _mm_store_ps(xa, xn);
  _mm_store_ps(va, v);
  _mm_store_ps(wa, w);
  const Quat q = advance_orientation(ldq(b.quat, i), Vec3{wa[0], wa[1], wa[2]}, dt);
  if (!std::isfinite(xa[0] + xa[1] + xa[2] + va[0] + va[1] + va[2] + wa[0] + wa[1] + wa[2] + q.w)) ++bad;
  _mm_storeu_ps(BP, xyz_keep_w(xn, x_st));
  stq(b.quat, i, q);
  // the velocity predictor of the general path: v + pred_gain (v - v_old)
  const __m128 vp = _mm_add_ps(v, _mm_mul_ps(_mm_set1_ps(pred_gain), _mm_sub_ps(v, v_old)));
  d2max = std::max(d2max, rebuild_body(i, xn, q, vp, w));
}

Vec3 Simulation::Impl::integrate_shell(int i, Vec3 F, Vec3 T, float dt, Vec3* w_out, int& bad) {
  const std::uint32_t fl = b.flags[i];
  const Vec3 x = ld3(b.pos, i);
  st3(b.force, i, F);
  st3(b.torque, i, T);
  Vec3 v = ld3(b.vel, i), w = ld3(b.omega, i);
  const Vec3 v_old = v;
  Quat q = ldq(b.quat, i);
  if (fl & kBodyDynamic) {
    const float invm = b.mass[4 * i + 1];
    v = v + dt * (F * invm + gravity);
    const Vec3 iI = ld3(b.inv_inertia, i);
    // body frame: I dw/dt = T - w x I w
    Vec3 wb = rotate_inv(q, w), tb = rotate_inv(q, T);
    Vec3 Iw{iI.x > 0 ? wb.x / iI.x : 0, iI.y > 0 ? wb.y / iI.y : 0, iI.z > 0 ? wb.z / iI.z : 0};
    Vec3 rhs = tb - cross(wb, Iw);
    wb = wb + dt * Vec3{rhs.x * iI.x, rhs.y * iI.y, rhs.z * iI.z};
    w = rotate(q, wb);
    st3(b.vel, i, v);
    st3(b.omega, i, w);
  }
  Vec3 xn = x + dt * v;
  q = advance_orientation(q, w, dt);
  if (!std::isfinite(xn.x + xn.y + xn.z + v.x + v.y + v.z + w.x + w.y + w.z + q.w)) ++bad;
  st3(b.pos, i, xn);
  stq(b.quat, i, q);
  // Velocity predictor: symplectic Euler's v is the velocity of [t_n, t_n+1], half a step
  // behind the positions the next contact stage sees, so the dashpot would act on a lagged
  // velocity (to first order the pair moves as if its mass were m_eff - c_n dt/2: e = 0.1
  // came out +3.3 % at dt = t_contact/50 with the contact 3.3 % short). The spheres get
  // v + (dt/2) a instead (gain pred_gain = 1/2, less at large damping per substep:
  // predictor_gain), a = (v - v_old)/dt this substep's acceleration (all forces and
  // gravity): zero at rest, so resting contacts see what they saw before; zero in a body's
  // first substep (rebuild_body(i) elsewhere). Translation only: predicting w as well kept
  // granule piles and beds jittering (rotation about a contact has a smaller point mass,
  // so a larger damping per substep; measured, docs/dem.md "Step size").
  // (a shell: granules take granule_update; its spheres are measured from the shell list's build)
  *w_out = w;
  return v + pred_gain * (v - v_old);
}

// The body stage's runs (dem_impl.hpp body_runs) of the bodies [0, n_order) (order: their
// indices, null: the identity); planned again after a sort or a change of the sleeping regions.
void Simulation::Impl::plan_body_runs(int runs, int n_order, const std::int32_t* order) {
  if (int(body_runs.size()) == runs + 1 && body_runs.back() == n_order && body_runs_epoch == work_epoch) return;
  body_runs.assign(std::size_t(runs) + 1, 0);
  const std::uint8_t* doze = def.sleep_regions ? dozing.data() : nullptr;
  // work of a body: its spheres (a dozing granule only clears its sums: about an eighth)
  split_in_runs(n_order, runs, body_runs.data(), [&](int t) {
    const int i = order ? order[t] : t;
    return std::int64_t(doze && doze[i] ? 1 : 2 * b.count[i]);
  });
  body_runs_epoch = work_epoch;
}

// ---- body stage: gather each sphere (gather_sphere4), sum the spheres' forces in id order,
// integrate, rebuild the spheres. Wide shells (wide_bodies) in three passes over their chunks:
// the chunks' sums, each body's step from them, the chunks' spheres rebuilt.
bool Simulation::Impl::bodies(float dt, float* d2max_out, float* d2shell_out) {
  float d2max = 0, d2shell = 0, vmax = 0;
  int bad = 0;
  std::int64_t nwall = 0;
  const int n = nb;
  const bool ordered = int(body_order.size()) + int(wide_bodies.size()) == n;
  const std::int32_t* order = body_order.data();
  const int n_order = ordered ? int(body_order.size()) : n;
  const GatherCtx gctx = gather_ctx();
  const std::uint8_t* doze = def.sleep_regions ? dozing.data() : nullptr;
  const int n_chunks = ordered ? int(wide_chunks.size()) : 0;
  if (n_chunks > 0) {
    wide_parts.resize(std::size_t(n_chunks));
    wide_motion.resize(wide_bodies.size());
  }
  // The bodies in `threads` contiguous runs of the body order (which follows the spheres'
  // grid order), of about equal work: a thread writes the spheres of its run only, so two
  // threads share cache lines of the sphere arrays only where their runs meet. (Chunks of 128
  // bodies handed out in turn shared them all over: on two threads the stage ran no faster
  // than on one; docs/BENCHMARKS.md "The body stage in runs of the body order".) Which
  // thread steps a body does not change what is computed.
  const bool parallel = n > kParallelSpheres / 2 || np > kParallelSpheres;
  // (inside another parallel region, as patches stepped side by side are, the team is one thread)
  const int runs = parallel && !omp_in_parallel() ? std::max(1, threads) : 1;
  plan_body_runs(runs, n_order, ordered ? order : nullptr);
#pragma omp parallel num_threads(threads) if (parallel)
  {
    if (n_chunks > 0) {
      // the chunks' sums, each in its spheres' order (a static shell's sums are only cleared)
#pragma omp for schedule(dynamic, 1) reduction(+ : nwall)
      for (int c = 0; c < n_chunks; ++c) {
        const WideChunk& ch = wide_chunks[std::size_t(c)];
        const int i = ch.body;
        WidePart& part = wide_parts[std::size_t(c)];
        __m128 F = _mm_setzero_ps(), T = _mm_setzero_ps();
        if (b.flags[i] & kBodyStatic) {
          for (int k = ch.k0; k < ch.k1; ++k) acc[std::size_t(slot_of[b.first[i] + k])] = SphereSums{};
        } else {
          sum_spheres(gctx, i, ch.k0, ch.k1, dt, nwall, F, T);
        }
        _mm_store_ps(part.F, F);
        _mm_store_ps(part.T, T);
      }
      // each wide body's step from its chunks' sums, in chunk order
#pragma omp single
      for (std::size_t w = 0; w < wide_bodies.size(); ++w) {
        const WideBody& wb = wide_bodies[w];
        const int i = wb.body;
        WideMotion& m = wide_motion[w];
        if (b.flags[i] & kBodyStatic) {
          st3(b.force, i, Vec3{});
          st3(b.torque, i, Vec3{});
          continue;
        }
        __m128 F = _mm_setzero_ps(), T = _mm_setzero_ps();
        for (int c = wb.c0; c < wb.c1; ++c) {
          F = _mm_add_ps(F, _mm_load_ps(wide_parts[std::size_t(c)].F));
          T = _mm_add_ps(T, _mm_load_ps(wide_parts[std::size_t(c)].T));
        }
        m.v = integrate_shell(i, to_vec3(F), to_vec3(T), dt, &m.w, bad);
      }
      // (the single's barrier) the chunks' spheres rebuilt
#pragma omp for schedule(dynamic, 1) reduction(max : d2shell)
      for (int c = 0; c < n_chunks; ++c) {
        const WideChunk& ch = wide_chunks[std::size_t(c)];
        const WideMotion& m = wide_motion[std::size_t(ch.wide)];
        if (!(b.flags[ch.body] & kBodyStatic)) d2shell = std::max(d2shell, rebuild_spheres(ch.body, ch.k0, ch.k1, m.v, m.w));
      }
    }
#pragma omp for schedule(static, 1) reduction(max : d2max, d2shell, vmax) reduction(+ : bad, nwall)
    for (int run = 0; run < runs; ++run) {
      for (int t = body_runs[std::size_t(run)]; t < body_runs[std::size_t(run) + 1]; ++t) {
        const int i = ordered ? order[t] : t;
        const std::uint32_t fl = b.flags[i];
        if (fl & kBodyStatic) {  // no force on a static body (its spheres' sums are only cleared)
          st3(b.force, i, Vec3{});
          st3(b.torque, i, Vec3{});
          for (int k = 0, first = b.first[i], cnt = b.count[i]; k < cnt; ++k)
            acc[std::size_t(slot_of[first + k])] = SphereSums{};
          continue;
        }
        if (fl & kBodyGranule) {  // (granules are dynamic)
          if (doze && doze[i]) {  // asleep in a still region (dem_regions.cpp): its sums are only cleared
            for (int k = 0, first = b.first[i]; k < 4; ++k) acc[std::size_t(slot_of[first + k])] = SphereSums{};
            continue;
          }
          granule_update(gctx, i, dt, nwall, d2max, vmax, bad);
          continue;
        }
        __m128 F = _mm_setzero_ps(), T = _mm_setzero_ps();
        sum_spheres(gctx, i, 0, b.count[i], dt, nwall, F, T);
        Vec3 w;
        const Vec3 vp = integrate_shell(i, to_vec3(F), to_vec3(T), dt, &w, bad);
        d2shell = std::max(d2shell, rebuild_body(i, vp, w));
      }
    }
  }
  *d2max_out = d2max;
  *d2shell_out = d2shell;
  granule_vmax = vmax;
  stats.wall_contacts = nwall;
  return bad == 0;
}

double Simulation::Impl::max_granule_speed() const {
  double m = 0;
  for (int i = 0; i < nb; ++i) {
    if (!(b.flags[i] & kBodyGranule)) continue;
    double s = length(ld3(b.vel, i)) + length(ld3(b.omega, i)) * (shape.centre_distance + shape.radius);
    m = std::max(m, s);
  }
  return m;
}

void Simulation::Impl::move_kinematic(double dt) {
  for (int i = 0; i < nb; ++i) {
    if (!(b.flags[i] & kBodyKinematic)) continue;
    Vec3 v = ld3(b.vel, i), w = ld3(b.omega, i);
    if (dot(v, v) == 0.0f && dot(w, w) == 0.0f) continue;
    st3(b.pos, i, ld3(b.pos, i) + float(dt) * v);
    Quat q = ldq(b.quat, i);
    Quat qd = Quat{w.x, w.y, w.z, 0} * q;
    float hd = 0.5f * float(dt);
    stq(b.quat, i, normalized(Quat{q.x + hd * qd.x, q.y + hd * qd.y, q.z + hd * qd.z, q.w + hd * qd.w}));
    rebuild_body(i);
    need_sort = true;
  }
}

// Appends a body and its spheres; the caller has checked the capacities.
int Simulation::Impl::push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm,
                                Vec3 inv_inertia, const Vec3* offsets, const float* radii, int count,
                                bool one_radius) {
  int i = nb++;
  {
    float arm = 0, rmin = std::numeric_limits<float>::infinity();
    for (int k = 0; k < count; ++k) {
      arm = std::max(arm, length(offsets[k]));
      rmin = std::min(rmin, one_radius ? radii[0] : radii[k]);
    }
    float mpt = 0;
    if ((flags & kBodyDynamic) && invm > 0) {
      const float imin = 1.0f / std::max({inv_inertia.x, inv_inertia.y, inv_inertia.z});
      mpt = float(point_effective_mass(mass, imin, arm));
    }
    guard_pt_mass[i] = mpt;
    guard_arm[i] = arm;
    guard_rmin[i] = rmin;
  }
  write_body_record(b, std::size_t(i), flags, x, q, v, w, mass, invm, inv_inertia, np, count);  // dem_control.hpp
  for (int k = 0; k < count; ++k) {
    int s = np++;
    p.id[s] = s;
    p.body[s] = i;
    slot_of[s] = s;
    st3(p.offset, s, offsets[k]);
    p.pos[4 * s + 3] = one_radius ? radii[0] : radii[k];
    for (int c = 0; c < 3; ++c) pos_at_sort[4 * s + c] = std::numeric_limits<float>::infinity();
    for (int kk = 0; kk < 3 * kWallSlots; ++kk) p.wall_xi[std::size_t(s) * 3 * kWallSlots + kk] = 0.0f;
    p.wall_mask[s] = 0;
  }
  rebuild_body(i);
  need_sort = true;
  wake_up(*this);
  return i;
}

}  // namespace sandpatch
