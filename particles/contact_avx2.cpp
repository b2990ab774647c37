// The contact law of shaders/dem/physics_common.glsl (contact.hpp) for 8 touching pairs at
// once (AVX2), see contact_simd.hpp. Compiled with -mavx2 -ffp-contract=off (particles/CMakeLists.txt) and
// called only after a cpuid check, so the library still runs on baseline x86-64.
//
// Each line below is the line of contact_force (or of dem_contacts.cpp's pair pass) with the same name,
// in the same operation order; `sel(m, a, b)` is the lane-wise `m ? a : b`.
#include "particles/contact_simd.hpp"

#include <immintrin.h>

namespace sandpatch::simd {

namespace {

using V = __m256;

inline V ld(const float* p) { return _mm256_load_ps(p); }
inline void st(float* p, V v) { _mm256_store_ps(p, v); }
inline V set1(float x) { return _mm256_set1_ps(x); }
inline V add(V a, V b) { return _mm256_add_ps(a, b); }
inline V sub(V a, V b) { return _mm256_sub_ps(a, b); }
inline V mul(V a, V b) { return _mm256_mul_ps(a, b); }
inline V dvd(V a, V b) { return _mm256_div_ps(a, b); }
inline V sqr(V a) { return _mm256_sqrt_ps(a); }
inline V gt(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }  // a > b (false on NaN)
inline V lt(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }  // a < b (false on NaN)
inline V sel(V m, V a, V b) { return _mm256_blendv_ps(b, a, m); }
inline bool any(V m) { return _mm256_movemask_ps(m) != 0; }
// a.x*b.x + a.y*b.y + a.z*b.z, left to right as math.hpp's dot
inline V dot3(V ax, V ay, V az, V bx, V by, V bz) { return add(add(mul(ax, bx), mul(ay, by)), mul(az, bz)); }

}  // namespace

bool avx2_available() {
  static const bool ok = __builtin_cpu_supports("avx2");
  return ok;
}

void spring_pairs_avx2(const PairLaw& law, PairBatch& b) {
  const V zero = _mm256_setzero_ps(), one = set1(1.0f), half = set1(0.5f);
  const V kn = set1(law.kn), kt = set1(law.kt), mkt = set1(-law.kt), mu = set1(law.mu), dt = set1(law.dt);
  const V sign = set1(-0.0f);

  // pair geometry (dem_contacts.cpp): inv = 1/sqrt(d2), dist = d2 inv, n = d inv
  const V d2 = ld(b.d2);
  const V inv = dvd(one, sqr(d2));
  const V dist = mul(d2, inv);
  const V nx = mul(ld(b.dx), inv), ny = mul(ld(b.dy), inv), nz = mul(ld(b.dz), inv);
  // v = (u_i - u_j) + n x (r_i w_i + r_j w_j)
  const V rwx = ld(b.rwx), rwy = ld(b.rwy), rwz = ld(b.rwz);
  const V vx = add(ld(b.dux), sub(mul(ny, rwz), mul(nz, rwy)));
  const V vy = add(ld(b.duy), sub(mul(nz, rwx), mul(nx, rwz)));
  const V vz = add(ld(b.duz), sub(mul(nx, rwy), mul(ny, rwx)));
  // c_n = cn0 / sqrt(1/m_i + 1/m_j), c_t = ctr c_n
  const V cn = dvd(set1(law.cn0), sqr(ld(b.invm)));
  const V ct = mul(set1(law.ctr), cn);
  const V delta = sub(ld(b.rs), dist);

  // contact_force
  const V vn = dot3(vx, vy, vz, nx, ny, nz);
  V fd = mul(cn, vn);
  {
    // first substep of a contact (physics_common.glsl): |fd| = c_n (min(delta/dt, |vn|) + |vn|/2)
    // with the sign of vn, lane by lane in contact_force's order
    const V m = gt(ld(b.newc), zero);
    if (any(m)) {
      const V avn = _mm256_andnot_ps(sign, vn);
      const V dd = sel(lt(delta, mul(avn, dt)), dvd(delta, dt), avn);
      const V mag = mul(cn, add(dd, mul(half, avn)));
      fd = sel(m, _mm256_or_ps(_mm256_andnot_ps(sign, mag), _mm256_and_ps(sign, vn)), fd);
    }
  }
  V fel = mul(kn, delta);
  if (law.kn2 > law.kn) {
    // hysteretic normal spring: dmax = max(delta, dmax); d0 = dmax (1 - k_n/kn2);
    // fel = max(0, min(k_n delta, kn2 (delta - d0)))
    V dm = ld(b.dmax);
    dm = sel(gt(delta, dm), delta, dm);
    const V d0 = mul(dm, set1(1.0f - law.kn / law.kn2));
    const V fu = mul(set1(law.kn2), sub(delta, d0));
    fel = sel(lt(fu, fel), fu, fel);
    fel = _mm256_and_ps(gt(fel, zero), fel);
    st(b.dmax, dm);
  }
  V fn = sub(fel, fd);
  fn = _mm256_and_ps(gt(fn, zero), fn);  // fn > 0 ? fn : 0
  const V vtx = sub(vx, mul(nx, vn)), vty = sub(vy, mul(ny, vn)), vtz = sub(vz, mul(nz, vn));

  V xx = ld(b.xix), xy = ld(b.xiy), xz = ld(b.xiz);
  {
    const V xi2 = dot3(xx, xy, xz, xx, xy, xz);
    const V has = gt(xi2, zero);
    if (any(has)) {
      // rotate into the new tangent plane, rescale to the old length
      const V s = dot3(xx, xy, xz, nx, ny, nz);
      const V rx = sub(xx, mul(nx, s)), ry = sub(xy, mul(ny, s)), rz = sub(xz, mul(nz, s));
      const V xr2 = dot3(rx, ry, rz, rx, ry, rz);
      const V pos = gt(xr2, zero);
      const V q = sel(pos, dvd(xi2, xr2), zero);
      const V sc = sel(lt(q, set1(1.001f)), mul(half, add(one, q)), sqr(q));
      const V nx2 = sel(pos, mul(rx, sc), zero), ny2 = sel(pos, mul(ry, sc), zero), nz2 = sel(pos, mul(rz, sc), zero);
      xx = sel(has, nx2, xx);
      xy = sel(has, ny2, xy);
      xz = sel(has, nz2, xz);
    }
  }
  xx = add(xx, mul(vtx, dt));
  xy = add(xy, mul(vty, dt));
  xz = add(xz, mul(vtz, dt));
  const V cap = mul(mu, fn);
  const V cap2 = mul(cap, cap);
  {
    const V xl2 = dot3(xx, xy, xz, xx, xy, xz);
    const V slip = gt(mul(mul(kt, kt), xl2), cap2);
    if (any(slip)) {
      const V f = dvd(cap, mul(kt, sqr(xl2)));
      xx = sel(slip, mul(xx, f), xx);
      xy = sel(slip, mul(xy, f), xy);
      xz = sel(slip, mul(xz, f), xz);
    }
  }
  const V mct = _mm256_xor_ps(ct, sign);  // -c_t
  const V ax = mul(xx, mkt), ay = mul(xy, mkt), az = mul(xz, mkt);
  const V bx = mul(vtx, mct), by = mul(vty, mct), bz = mul(vtz, mct);
  V ftx = add(ax, bx), fty = add(ay, by), ftz = add(az, bz);
  {
    const V ft2 = dot3(ftx, fty, ftz, ftx, fty, ftz);
    const V over = gt(ft2, cap2);
    if (any(over)) {
      // largest beta in [0, 1] with |a + beta b| <= cap
      const V bb = dot3(bx, by, bz, bx, by, bz), ab = dot3(ax, ay, az, bx, by, bz), aa = dot3(ax, ay, az, ax, ay, az);
      const V disc = sub(mul(ab, ab), mul(bb, sub(aa, cap2)));
      const V root = sqr(sel(gt(disc, zero), disc, zero));
      V beta = sel(gt(bb, zero), dvd(add(_mm256_xor_ps(ab, sign), root), bb), zero);
      beta = sel(lt(beta, zero), zero, sel(gt(beta, one), one, beta));
      ftx = sel(over, add(ax, mul(bx, beta)), ftx);
      fty = sel(over, add(ay, mul(by, beta)), fty);
      ftz = sel(over, add(az, mul(bz, beta)), ftz);
    }
  }
  // f = fn n + f_t, and n x f_t
  st(b.fx, add(mul(nx, fn), ftx));
  st(b.fy, add(mul(ny, fn), fty));
  st(b.fz, add(mul(nz, fn), ftz));
  st(b.cx, sub(mul(ny, ftz), mul(nz, fty)));
  st(b.cy, sub(mul(nz, ftx), mul(nx, ftz)));
  st(b.cz, sub(mul(nx, fty), mul(ny, ftx)));
  st(b.xix, xx);
  st(b.xiy, xy);
  st(b.xiz, xz);
}

}  // namespace sandpatch::simd
