// Granule DEM, CPU/OpenMP reference backend. The stages are listed in dem.hpp; the force
// laws are in contact.hpp, the material formulas in material.hpp.
#include "particles/dem.hpp"

#include <omp.h>
#include <xmmintrin.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <numbers>

#include "common/hash.hpp"
#include "particles/contact.hpp"
#include "particles/contact_simd.hpp"
#include "particles/dem_control.hpp"
#include "particles/dem_physics.hpp"
#include "particles/fields.hpp"

namespace sandpatch {

namespace {

// Tangential springs against the boundaries, per sphere: floor, walls x0, x1, z0, z1, terrain.
constexpr int kWallSlots = 6;
// Per sphere, the pair pass's sums (kAcc floats; Simulation::Impl::acc): contact force (N) in 0-2,
// the sum of n x f_t (N) in 4-6 (the torque about the centre is -r times it); 3 and 7 stay 0.
constexpr std::size_t kAcc = 8;

// Structure-of-arrays generated from fields.hpp, the CPU's fields only (the GL backend's
// per-sphere force sums are neither allocated nor sorted here): a field of n components is
// (cap x n). The particle arrays include the per-sphere contact history (the boundary-plane
// springs), so the sort permutes it with them.
struct ParticleArrays {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, std::vector<type> name;)
  SANDPATCH_PARTICLE_FIELDS(SP_DECL)
  SANDPATCH_SPHERE_CONTACT_FIELDS(SP_DECL)
#undef SP_DECL
  void resize(std::size_t cap) {
#define SP_RESIZE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, name.assign(cap * (n), type{});)
    SANDPATCH_PARTICLE_FIELDS(SP_RESIZE)
    SANDPATCH_SPHERE_CONTACT_FIELDS(SP_RESIZE)
#undef SP_RESIZE
  }
};

struct BodyArrays {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, std::vector<type> name;)
  SANDPATCH_BODY_FIELDS(SP_DECL)
#undef SP_DECL
  void resize(std::size_t cap) {
#define SP_RESIZE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, name.assign(cap * (n), type{});)
    SANDPATCH_BODY_FIELDS(SP_RESIZE)
#undef SP_RESIZE
  }
};

// The contact history of the neighbour list, one element per list entry (fields.hpp
// SANDPATCH_PAIR_CONTACT_FIELDS), carried over by partner id when the list is rebuilt.
struct PairArrays {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, std::vector<type> name;)
  SANDPATCH_PAIR_CONTACT_FIELDS(SP_DECL)
#undef SP_DECL
  void assign(std::size_t entries) {
#define SP_RESIZE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, name.assign(entries * (n), type{});)
    SANDPATCH_PAIR_CONTACT_FIELDS(SP_RESIZE)
#undef SP_RESIZE
  }
  void swap(PairArrays& o) {
#define SP_SWAP(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, name.swap(o.name);)
    SANDPATCH_PAIR_CONTACT_FIELDS(SP_SWAP)
#undef SP_SWAP
  }
};

inline Vec3 ld3(const std::vector<float>& a, std::size_t i) { return {a[4 * i], a[4 * i + 1], a[4 * i + 2]}; }
inline void st3(std::vector<float>& a, std::size_t i, Vec3 v) {
  a[4 * i] = v.x;
  a[4 * i + 1] = v.y;
  a[4 * i + 2] = v.z;
}
inline Quat ldq(const std::vector<float>& a, std::size_t i) { return {a[4 * i], a[4 * i + 1], a[4 * i + 2], a[4 * i + 3]}; }
inline void stq(std::vector<float>& a, std::size_t i, Quat q) {
  a[4 * i] = q.x;
  a[4 * i + 1] = q.y;
  a[4 * i + 2] = q.z;
  a[4 * i + 3] = q.w;
}

// Vec3 formulas in 4-wide SSE2 registers (x, y, z, lane 3): every lane does the float
// operations of math.hpp's formula in its order, so the results are the same bit for bit.
inline __m128 xyz_mask() { return _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0)); }
inline __m128 xyz0(__m128 a) { return _mm_and_ps(a, xyz_mask()); }  // lane 3 = +0
// lanes x, y, z of a and lane 3 of keep (a field's 4th component is stored back unchanged)
inline __m128 xyz_keep_w(__m128 a, __m128 keep) {
  return _mm_or_ps(_mm_and_ps(xyz_mask(), a), _mm_andnot_ps(xyz_mask(), keep));
}
// cross(a, b) of math.hpp: lane k = a_(k+1) b_(k+2) - a_(k+2) b_(k+1); lane 3 = a3 b3 - a3 b3
inline __m128 cross4(__m128 a, __m128 b) {
  const __m128 a_yzx = _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 0, 2, 1)), a_zxy = _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 1, 0, 2));
  const __m128 b_yzx = _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 0, 2, 1)), b_zxy = _mm_shuffle_ps(b, b, _MM_SHUFFLE(3, 1, 0, 2));
  return _mm_sub_ps(_mm_mul_ps(a_yzx, b_zxy), _mm_mul_ps(a_zxy, b_yzx));
}
inline Vec3 to_vec3(__m128 a) {
  alignas(16) float f[4];
  _mm_store_ps(f, a);
  return {f[0], f[1], f[2]};
}
inline __m128 from_vec3(Vec3 v) { return _mm_setr_ps(v.x, v.y, v.z, 0.0f); }
// Orientation after dt (s) at angular velocity w (rad/s, world frame): q + (dt/2) (w, 0) q,
// normalised (the body stage's integrator, granules' and shells').
inline Quat advance_orientation(Quat q, Vec3 w, float dt) {
  const Quat qd = Quat{w.x, w.y, w.z, 0.0f} * q;
  return normalized(Quat{q.x + 0.5f * dt * qd.x, q.y + 0.5f * dt * qd.y, q.z + 0.5f * dt * qd.z, q.w + 0.5f * dt * qd.w});
}
// dot(a, a) of math.hpp: (x x + y y) + z z
inline float norm2(__m128 a) {
  const __m128 aa = _mm_mul_ps(a, a);
  return (_mm_cvtss_f32(aa) + _mm_cvtss_f32(_mm_shuffle_ps(aa, aa, 1))) + _mm_cvtss_f32(_mm_shuffle_ps(aa, aa, 2));
}

}  // namespace

bool simd::use_avx2_pair_kernel() {
#ifdef SANDPATCH_AVX2_KERNEL
  const char* k = std::getenv("SANDPATCH_DEM_KERNEL");
  return simd::avx2_available() && !(k && std::strcmp(k, "scalar") == 0);
#else
  return false;
#endif
}

// ---------------------------------------------------------------------------------------
// Terrain grid
// (shaders/dem/physics_common.glsl, shared with the GL force kernel)
float TerrainGrid::height(float x, float z) const { return physics::terrain_height(*this, x, z); }
Vec3 TerrainGrid::normal(float x, float z) const { return physics::terrain_normal(*this, x, z); }

// ---------------------------------------------------------------------------------------
struct Simulation::Impl {
  SimulationDef def;
  GranuleShape shape;
  Vec3 gravity;            // sim units, m/s^2
  int threads = 1;
  // The pair pass evaluates touching pairs 8 at a time with the AVX2 kernel of
  // contact_avx2.cpp (same results bit for bit as contact_force, contact_simd.hpp) when the
  // CPU has AVX2 and the law is SpringHistory; SANDPATCH_DEM_KERNEL=scalar forces the scalar
  // path (tests run on both), =avx2 asks for the kernel (ignored without AVX2).
  bool simd_pairs = false;

  // bodies (creation order) and particles (cell-sorted order)
  int nb = 0, np = 0;
  BodyArrays b;
  ParticleArrays p;
  std::vector<std::int32_t> slot_of;   // particle id -> sorted index
  std::vector<std::int32_t> cell;      // sorted index -> cell at the last sort
  std::vector<float> pos_at_sort;      // sorted index -> xyz (stride 4) at the last sort
  // Bodies in the order of their first sphere in the sorted particle order (set by sort()):
  // the body stage walks them in this order so that consecutive bodies reach spheres that are
  // close in memory (a 64,000-sphere bed does not fit in L2). Each body's sums do not depend
  // on the order, so neither do the results.
  std::vector<std::int32_t> body_order;
  bool need_sort = true;
  float shape_offsets[16] = {};        // the granule's 4 sphere offsets (x, y, z, 0), m, body frame

  // Verlet neighbour list (CSR, sorted order, no cap), one entry per pair: for sphere i the
  // entries [nstart[i], nstart[i+1]) hold every sphere j of another body with
  // |x_i - x_j| < r_i + r_j + skin at the last rebuild for which i is the pair's owner: the
  // sphere with the lower stable id, or the only side with a list (a static partner has none).
  // Each entry carries the pair's tangential spring (3 floats).
  std::vector<std::int32_t> nstart;    // np + 1
  std::vector<std::int32_t> nbr;       // sorted index of the partner
  std::vector<std::int32_t> nbr_id;    // stable id of the partner (history carry-over)
  // The pairs' contact history (fields.hpp): xi, the tangential spring (3 per entry, m), and
  // touch, 1 if the pair touched at the last substep (a touching pair without it is in its
  // first substep, new_contact).
  PairArrays pairs;
  // The pair pass computes each pair once and adds its result to both spheres' sums in acc
  // (kAcc per sphere, sorted order; the body stage reads and zeroes them). No atomics and the
  // same order of additions for any thread count: the spheres are split into slabs of two
  // z-layers of cells (contiguous in the sorted order, z outermost; chunk_start), fixed by the
  // grid, not by the threads. A pair reaches at most one layer up or down, so slabs of the same
  // parity never write the same sphere: the even slabs run in parallel, then the odd ones, each
  // slab on one thread front to back. (Before: each pair's result was stored per list entry and
  // every sphere gathered its entries, the partner's mirrored one included; 2 list entries
  // per pair, and the gather's loads of the mirrored results were 20 % of the body stage's
  // samples on 64,000 spheres. docs/BENCHMARKS.md, session 8.)
  struct alignas(32) SphereSums {
    float v[kAcc];
  };
  std::vector<SphereSums> acc;  // one per sphere, 32-byte aligned: one cache line holds it
  std::vector<std::int32_t> chunk_start;  // slabs + 1: sorted index where each slab begins
  // (the boundary-plane springs are particle arrays: p.wall_xi, p.wall_mask, fields.hpp)

  // grid
  float r_max = 0, h = 0, inv_h = 0, skin = 0;
  int gx = 1, gy = 1, gz = 1;
  std::vector<std::int32_t> cell_start;  // gx*gy*gz + 1

  // guard
  double min_point_mass = std::numeric_limits<double>::infinity();  // kg, dynamic bodies
  double zeta = 0;
  // overlap guard, per body (creation order; not state, not hashed): point effective mass
  // (kg, 0 for static/kinematic), farthest sphere centre from the COM (m), smallest radius (m)
  std::vector<float> guard_pt_mass, guard_arm, guard_rmin;

  // state
  double time = 0;
  bool asleep = false;
  double below_time = 0;
  float granule_vmax = 0;              // max granule speed after the last substep, m/s
  float pred_gain = 0.5f;              // velocity predictor gain of this substep (predictor_gain)
  bool first_law = false;              // this substep applies the first-substep dashpot (timing_on)
  StepStats stats;

  // ---- setup
  void size_grid() {
    h = 2.0f * r_max + skin;
    inv_h = 1.0f / h;
    Vec3 ext = def.bounds_max - def.bounds_min;
    gx = std::max(1, int(std::ceil(ext.x * inv_h)));
    gy = std::max(1, int(std::ceil(ext.y * inv_h)));
    gz = std::max(1, int(std::ceil(ext.z * inv_h)));
    cell_start.assign(std::size_t(gx) * gy * gz + 1, 0);
    need_sort = true;
  }
  int cell_coord(float v, float lo, int n) const {
    int c = int(std::floor((v - lo) * inv_h));
    return c < 0 ? 0 : (c >= n ? n - 1 : c);
  }
  int cell_of(Vec3 x) const {
    int cx = cell_coord(x.x, def.bounds_min.x, gx), cy = cell_coord(x.y, def.bounds_min.y, gy),
        cz = cell_coord(x.z, def.bounds_min.z, gz);
    return (cz * gy + cy) * gx + cx;
  }

  // Rebuild the spheres of body i from its pose and velocity; returns the largest squared
  // displacement of one of them since the last sort.
  float rebuild_body(int i) { return rebuild_body(i, ld3(b.vel, i), ld3(b.omega, i)); }
  // The same with the velocities v, w (m/s, rad/s) the spheres' contacts are to see: the body
  // stage passes them predicted to the next contact stage's time (see `bodies`).
  // In 4-wide SSE2 registers (baseline x86-64), every lane doing the float operations of the
  // Vec3 formulas in their order: arm = R o with R's columns, lane k = dot(row k, o);
  // cross(a, b) lane-wise as math.hpp's. Lane 3 is unused (the radius and the inverse mass
  // are kept in the stores).
  float rebuild_body(int i, Vec3 v, Vec3 w) {
    return rebuild_body(i, from_vec3(ld3(b.pos, i)), ldq(b.quat, i), from_vec3(v), from_vec3(w));
  }
  // The same with the body's pose x4 (lane 3 unused), q and v4, w4 (lane 3 = 0) in registers.
  __attribute__((always_inline)) float rebuild_body(int i, const __m128 x4, const Quat q, const __m128 v4,
                                                    const __m128 w4) {
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
    for (int k = 0, first = b.first[i], cnt = b.count[i]; k < cnt; ++k) {
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

  // Counting sort of the particles by cell (stable, serial: deterministic), permuting every
  // particle field, then the neighbour list is rebuilt and the springs carried over.
  void sort() {
    std::vector<std::int32_t> old_slot(slot_of.begin(), slot_of.begin() + np);
    std::fill(cell_start.begin(), cell_start.end(), 0);
    std::vector<std::int32_t> c(np);
    for (int s = 0; s < np; ++s) {
      c[s] = cell_of(ld3(p.pos, s));
      cell_start[c[s] + 1]++;
    }
    for (std::size_t i = 1; i < cell_start.size(); ++i) cell_start[i] += cell_start[i - 1];
    std::vector<std::int32_t> fill(cell_start.begin(), cell_start.end() - 1), dest(np);
    for (int s = 0; s < np; ++s) dest[s] = fill[c[s]]++;
    auto permute = [&](auto& arr, int n) {
      auto tmp = arr;
      for (int s = 0; s < np; ++s)
        for (int k = 0; k < n; ++k) tmp[std::size_t(dest[s]) * n + k] = arr[std::size_t(s) * n + k];
      arr.swap(tmp);
    };
#define SP_PERMUTE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, permute(p.name, n);)
    SANDPATCH_PARTICLE_FIELDS(SP_PERMUTE)
    SANDPATCH_SPHERE_CONTACT_FIELDS(SP_PERMUTE)
#undef SP_PERMUTE
    cell.resize(np);
    for (int s = 0; s < np; ++s) cell[dest[s]] = c[s];
    for (int s = 0; s < np; ++s) slot_of[p.id[s]] = s;
    pos_at_sort.assign(p.pos.begin(), p.pos.end());
    {
      std::vector<std::uint8_t> seen(nb, 0);
      body_order.clear();
      body_order.reserve(nb);
      for (int s2 = 0; s2 < np; ++s2)
        if (!seen[p.body[s2]]) {
          seen[p.body[s2]] = 1;
          body_order.push_back(p.body[s2]);
        }
      for (int i = 0; i < nb; ++i)  // bodies without spheres (none today) keep their place at the end
        if (!seen[i]) body_order.push_back(i);
    }
    // slabs of two z-layers of cells (the pair pass's chunks)
    chunk_start.clear();
    for (int z = 0; z < gz; z += 2) chunk_start.push_back(cell_start[std::size_t(z) * gx * gy]);
    chunk_start.push_back(np);
    // the sums are zero between substeps (the body stage zeroes what it reads; this also clears
    // what a step that failed half-way left)
    std::fill(acc.begin(), acc.begin() + np, SphereSums{});
    need_sort = false;
    stats.resorts++;
    build_list(old_slot);
  }

  // Visits the spheres j of other bodies within r_i + r_j + skin of sphere i, in a fixed
  // order (cells z, y, x, then sorted index).
  template <class F>
  void for_near(int i, F&& f) const {
    const float* P = p.pos.data();
    const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
    const float ri = P[4 * i + 3];
    const std::int32_t bi = p.body[i];
    const bool dyn_i = p.vel[4 * i + 3] > 0.0f;
    const int c = cell[i];
    const int cx = c % gx, cy = (c / gx) % gy, cz = c / (gx * gy);
    const int x0 = cx > 0 ? cx - 1 : 0, x1 = cx < gx - 1 ? cx + 1 : gx - 1;
    for (int zz = (cz > 0 ? cz - 1 : 0); zz <= (cz < gz - 1 ? cz + 1 : gz - 1); ++zz)
      for (int yy = (cy > 0 ? cy - 1 : 0); yy <= (cy < gy - 1 ? cy + 1 : gy - 1); ++yy) {
        const int row = (zz * gy + yy) * gx;
        for (int j = cell_start[row + x0], j1 = cell_start[row + x1 + 1]; j < j1; ++j) {
          const float dx = pi.x - P[4 * j], dy = pi.y - P[4 * j + 1], dz = pi.z - P[4 * j + 2];
          const float rs = ri + P[4 * j + 3] + skin;
          if (dx * dx + dy * dy + dz * dz >= rs * rs || p.body[j] == bi) continue;
          if (!dyn_i && p.vel[4 * j + 3] == 0.0f) continue;  // neither moves under forces
          f(j);
        }
      }
  }

  // Rebuilds the CSR neighbour list (two parallel passes: count, fill) and carries each
  // pair's spring over from the old list (found by partner id).
  void build_list(const std::vector<std::int32_t>& old_slot) {
    std::vector<std::int32_t> ostart, onbr_id;
    PairArrays old;
    ostart.swap(nstart);
    onbr_id.swap(nbr_id);
    old.swap(pairs);
    const int n = np;
    const int old_np = ostart.empty() ? 0 : int(ostart.size()) - 1;
    nstart.assign(n + 1, 0);
    // i owns the pair with j: a static partner has no list, else the lower stable id
    auto owns = [&](int i, int j) { return (b.flags[p.body[j]] & kBodyStatic) || p.id[i] < p.id[j]; };
#pragma omp parallel for num_threads(threads) schedule(dynamic, 256) if (n > 4096)
    for (int i = 0; i < n; ++i) {
      if (b.flags[p.body[i]] & kBodyStatic) continue;
      int cnt = 0;
      for_near(i, [&](int j) { cnt += owns(i, j); });
      nstart[i + 1] = cnt;
    }
    for (int i = 0; i < n; ++i) nstart[i + 1] += nstart[i];
    nbr.resize(nstart[n]);
    nbr_id.resize(nstart[n]);
    pairs.assign(std::size_t(nstart[n]));
#pragma omp parallel for num_threads(threads) schedule(dynamic, 256) if (n > 4096)
    for (int i = 0; i < n; ++i) {
      if (b.flags[p.body[i]] & kBodyStatic) continue;
      int e = nstart[i];
      const int id = p.id[i];
      const int oi = id < int(old_slot.size()) ? old_slot[id] : -1;
      const bool has_old = oi >= 0 && oi < old_np;
      for_near(i, [&](int j) {
        if (!owns(i, j)) return;
        nbr[e] = j;
        nbr_id[e] = p.id[j];
        if (has_old)
          for (int k = ostart[oi]; k < ostart[oi + 1]; ++k)
            if (onbr_id[k] == p.id[j]) {
              pairs.xi[3 * e] = old.xi[3 * k];
              pairs.xi[3 * e + 1] = old.xi[3 * k + 1];
              pairs.xi[3 * e + 2] = old.xi[3 * k + 2];
              pairs.touch[e] = old.touch[k];
              break;
            }
        ++e;
      });
      assert(e == nstart[i + 1]);
    }
  }

  // ---- guard
  double guard_meff() const {
    double mp = std::min(min_point_mass,
                         point_effective_mass(shape.mass, shape.inertia, shape.centre_distance));
    return 0.5 * mp;
  }
  double body_pair_meff() const { return 0.5 * double(shape.mass); }
  double contact_time_() const {
    double m = guard_meff();
    double c = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) * body_pair_meff());
    double rad = def.material.normal_stiffness / m - (c / (2 * m)) * (c / (2 * m));
    return rad > 0 ? std::numbers::pi / std::sqrt(rad) : std::numbers::pi * std::sqrt(m / def.material.normal_stiffness);
  }
  // Lightest dynamic point mass (kg): granules' and dynamic shells'.
  double lightest_point_mass() const {
    return std::min(min_point_mass, point_effective_mass(shape.mass, shape.inertia, shape.centre_distance));
  }
  double max_impact_speed(double m_pt) const {
    const double f = def.max_overlap_fraction;
    if (!(f > 0)) return std::numeric_limits<double>::infinity();
    if (!(m_pt > 0)) m_pt = lightest_point_mass();
    return f * def.particle_radius * std::sqrt(double(def.material.normal_stiffness) / m_pt);
  }
  // The body's overlap (m) if it hit something immovable at its current speed, with what the
  // error message needs.
  struct ImpactCheck {
    double speed, m, r, overlap;  // m/s, kg (point mass), m (smallest sphere radius), m
  };
  ImpactCheck impact_of(int i, double kn, double m_light) const {
    ImpactCheck c;
    c.speed = length(ld3(b.vel, i)) + length(ld3(b.omega, i)) * guard_arm[i];
    c.m = (b.flags[i] & kBodyDynamic) ? double(guard_pt_mass[i]) : m_light;
    c.r = std::min(double(guard_rmin[i]), double(def.particle_radius));
    c.overlap = c.speed * std::sqrt(c.m / kn);
    return c;
  }
  // The overlap guard before a step: every moving body's speed against the immovable case.
  // The scan is parallel (it ran on one thread and was ~5 % of a two-thread step of a
  // 64,000-sphere bed); the error names the lowest body index that fails, as a serial scan would.
  Status check_impacts() const {
    const double f = def.max_overlap_fraction;
    if (!(f > 0)) return Ok{};
    const double kn = def.material.normal_stiffness, m_light = lightest_point_mass();
    int first_bad = nb;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(min : first_bad) if (nb > 2048)
    for (int i = 0; i < nb; ++i) {
      if (b.flags[i] & kBodyStatic) continue;
      const ImpactCheck c = impact_of(i, kn, m_light);
      if (c.overlap > f * c.r) first_bad = std::min(first_bad, i);
    }
    if (first_bad == nb) return Ok{};
    const int i = first_bad;
    const ImpactCheck c = impact_of(i, kn, m_light);
    const double speed = c.speed, m = c.m, r = c.r, overlap = c.overlap;
    const double k_needed = kn * (overlap / (f * r)) * (overlap / (f * r));
    return Error{"", "step.body[" + std::to_string(i) + "].speed", format_number(speed) + " m/s",
                 "must be <= " + format_number(f * r * std::sqrt(kn / m)) +
                     " m/s: hitting something immovable it would overlap by speed sqrt(m_pt/k_n) = " +
                     format_number(overlap) + " m > max_overlap_fraction x r = " + format_number(f * r) +
                     " m and could pass through (m_pt = " + format_number(m) + " kg, k_n = " + format_number(kn) +
                     " N/m)",
                 "raise SimulationDef.material.normal_stiffness to >= " + format_number(k_needed) +
                     " N/m (and max_substeps), slow the body, or set max_overlap_fraction = 0 to accept it"};
  }
  // Gain p of the velocity predictor (`bodies`: the spheres get v + p (v - v_old)) for a
  // substep dt: 1/2 (v at the contact stage's time) while the dashpot's damping per substep,
  // h = c_n dt / m_eff = 2 zeta w0 dt of a granule pair, is at most 0.2, falling linearly to 0
  // at h = 0.25. Extrapolating the velocity with the last acceleration (which holds the damping
  // forces) shrinks the explicit damper's stability region: for one contact the predicted
  // dashpot needs h < 1 instead of 2, less for the stiffer, more damped modes of a body caged
  // by several contacts. Measured (5x5x5 granule bed, 0.8-1.6 s after the drop): with p = 1/2
  // at e = 0.1 (h = 0.14) it settled like the plain step; at e = 0.01 (h = 0.27) and e = 0.02
  // (h = 0.37) it kept moving at 0.008-0.15 m/s (also with p = 0.46 and 0.26) against
  // 0.001-0.008 m/s with p = 0. The head-on case (e = 0.1, dt = t_contact/50) has
  // h = 0.11 (0.15 against the floor). docs/dem.md "Step size".
  bool timing_on(double /*dt*/) const {
    switch (def.contact_timing) {
      case SimulationDef::ContactTiming::On: return true;
      case SimulationDef::ContactTiming::Off: return false;
      default: return def.accuracy_steps_per_contact >= 50;  // the guard keeps dt <= t_c/50
    }
  }
  double predictor_gain(double dt) const {
    if (!timing_on(dt)) return 0.0;
    const double hd = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) / body_pair_meff()) * dt;
    return hd <= 0.2 ? 0.5 : (hd >= 0.25 ? 0.0 : 0.5 * (0.25 - hd) / 0.05);
  }
  double max_dt() const {
    double m = guard_meff();
    double tc = std::min(contact_time_(), std::numbers::pi * std::sqrt(m / def.material.normal_stiffness));
    double dt = tc / def.accuracy_steps_per_contact;
    double c = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) * body_pair_meff());
    if (c > 0) dt = std::min(dt, m / c);  // explicit damper: dt < 2 m/c, with a factor 2 margin
    return dt;
  }

  // ---- contact stage, pair pass: each pair is computed once, by its owner's entry, and added
  // to both spheres' sums (acc; read by gather_sphere in the body stage), slab by slab
  void contacts(float dt) {
    const Material& mat = def.material;
    const float kn = mat.normal_stiffness;
    const float cn0 = float(2.0 * zeta * std::sqrt(double(mat.normal_stiffness)));  // c_n = cn0 sqrt(m_eff)
    const float kt = mat.normal_stiffness * mat.tangential_stiffness_ratio;
    const float ctr = mat.tangential_damping_ratio;
    const float mu = mat.friction;
    const float* P = p.pos.data();
    const float* V = p.vel.data();
    const float* W = p.omega.data();
    const std::int32_t* NS = nstart.data();
    const std::int32_t* NB = nbr.data();
    const std::int32_t* CS = chunk_start.data();
    const int nchunks = int(chunk_start.size()) - 1;
    float* XI = pairs.xi.data();
    float* ACC = acc.data()->v;
    std::uint8_t* TCH = pairs.touch.data();
    std::int64_t npairs = 0;
    const int n = np;
    law = {kn, cn0, kt, ctr, mu};  // for gather_sphere

    // not touching: the spring is forgotten
    auto part = [&](int e, float* xe) __attribute__((always_inline)) {
      TCH[e] = 0;
      if (xe[0] != 0.0f || xe[1] != 0.0f || xe[2] != 0.0f) xe[0] = xe[1] = xe[2] = 0.0f;
    };
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
#pragma omp parallel num_threads(threads) if (n > 4096)
    {
    if (simd_pairs) {
    // pair pass, AVX2: the same walk; touching pairs are collected per thread into batches of
    // 8 and evaluated by the kernel (same results, contact_simd.hpp), then added to the sums in
    // pair order (the pass reads no sum, so the additions are those of the scalar pass). A
    // slab is one task, its last batch evaluated before the slab ends.
    const simd::PairLaw plaw{kn, cn0, kt, ctr, mu, dt};
    simd::PairBatch bt;
    int bi[simd::kPairLanes], bj[simd::kPairLanes];
    auto flush = [&]() {
      const int cnt = bt.count;
      for (int k = cnt; k < simd::kPairLanes; ++k) {  // idle lanes: a copy of lane 0
        bt.dx[k] = bt.dx[0], bt.dy[k] = bt.dy[0], bt.dz[k] = bt.dz[0], bt.d2[k] = bt.d2[0], bt.rs[k] = bt.rs[0];
        bt.dux[k] = bt.dux[0], bt.duy[k] = bt.duy[0], bt.duz[k] = bt.duz[0];
        bt.rwx[k] = bt.rwx[0], bt.rwy[k] = bt.rwy[0], bt.rwz[k] = bt.rwz[0];
        bt.invm[k] = bt.invm[0], bt.newc[k] = bt.newc[0];
        bt.xix[k] = bt.xix[0], bt.xiy[k] = bt.xiy[0], bt.xiz[k] = bt.xiz[0];
      }
#ifdef SANDPATCH_AVX2_KERNEL
      simd::spring_pairs_avx2(plaw, bt);
#endif
      for (int k = 0; k < cnt; ++k) {
        float* xe = XI + 3 * std::size_t(bt.entry[k]);
        xe[0] = bt.xix[k], xe[1] = bt.xiy[k], xe[2] = bt.xiz[k];
        add_pair(bi[k], bj[k], _mm_setr_ps(bt.fx[k], bt.fy[k], bt.fz[k], 0.0f),
                 _mm_setr_ps(bt.cx[k], bt.cy[k], bt.cz[k], 0.0f));
      }
      bt.count = 0;
    };
    for (int parity = 0; parity < 2; ++parity) {
#pragma omp for schedule(dynamic, 1) reduction(+ : npairs)
    for (int c = parity; c < nchunks; c += 2) {
      bt.count = 0;
      for (int i = CS[c], i1 = CS[c + 1]; i < i1; ++i) {
        const int e0 = NS[i], e1 = NS[i + 1];
        if (e0 == e1) continue;
        const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
        const float ri = P[4 * i + 3];
        const Vec3 ui{V[4 * i], V[4 * i + 1], V[4 * i + 2]};
        const float invm_i = V[4 * i + 3];
        const Vec3 rwi = ri * Vec3{W[4 * i], W[4 * i + 1], W[4 * i + 2]};
        for (int e = e0; e < e1; ++e) {
          const int j = NB[e];
          const float dx = pi.x - P[4 * j], dy = pi.y - P[4 * j + 1], dz = pi.z - P[4 * j + 2];
          const float rj = P[4 * j + 3];
          const float rs = ri + rj;
          const float d2 = dx * dx + dy * dy + dz * dz;
          float* xe = XI + 3 * std::size_t(e);
          if (d2 >= rs * rs || d2 <= 0.0f) {
            part(e, xe);
            continue;
          }
          ++npairs;
          const int k = bt.count++;
          const Vec3 du = ui - Vec3{V[4 * j], V[4 * j + 1], V[4 * j + 2]};
          const Vec3 rw = rwi + rj * Vec3{W[4 * j], W[4 * j + 1], W[4 * j + 2]};
          bt.dx[k] = dx, bt.dy[k] = dy, bt.dz[k] = dz, bt.d2[k] = d2, bt.rs[k] = rs;
          bt.dux[k] = du.x, bt.duy[k] = du.y, bt.duz[k] = du.z;
          bt.rwx[k] = rw.x, bt.rwy[k] = rw.y, bt.rwz[k] = rw.z;
          bt.invm[k] = invm_i + V[4 * j + 3];
          bt.newc[k] = first_law && TCH[e] == 0 ? 1.0f : 0.0f;  // first substep (ContactParams::new_contact)
          TCH[e] = 1;
          bt.xix[k] = xe[0], bt.xiy[k] = xe[1], bt.xiz[k] = xe[2];
          bt.entry[k] = e;
          bi[k] = i, bj[k] = j;
          if (bt.count == simd::kPairLanes) flush();
        }
      }
      if (bt.count > 0) flush();
    }
    }
    } else {
    // pair pass: each entry computes its pair once
    for (int parity = 0; parity < 2; ++parity) {
#pragma omp for schedule(dynamic, 1) reduction(+ : npairs)
    for (int c = parity; c < nchunks; c += 2) {
    for (int i = CS[c], i1 = CS[c + 1]; i < i1; ++i) {
      const int e0 = NS[i], e1 = NS[i + 1];
      if (e0 == e1) continue;
      const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
      const float ri = P[4 * i + 3];
      const Vec3 ui{V[4 * i], V[4 * i + 1], V[4 * i + 2]};
      const float invm_i = V[4 * i + 3];
      const Vec3 rwi = ri * Vec3{W[4 * i], W[4 * i + 1], W[4 * i + 2]};
      float last_invm_j = -1.0f, last_cn = 0.0f;
      for (int e = e0; e < e1; ++e) {
        const int j = NB[e];
        const float dx = pi.x - P[4 * j], dy = pi.y - P[4 * j + 1], dz = pi.z - P[4 * j + 2];
        const float rj = P[4 * j + 3];
        const float rs = ri + rj;
        const float d2 = dx * dx + dy * dy + dz * dz;
        float* xe = XI + 3 * std::size_t(e);
        if (d2 >= rs * rs || d2 <= 0.0f) {
          part(e, xe);
          continue;
        }
        ++npairs;
        const float inv = 1.0f / std::sqrt(d2);
        const float dist = d2 * inv;
        const Vec3 nrm{dx * inv, dy * inv, dz * inv};
        const Vec3 uj{V[4 * j], V[4 * j + 1], V[4 * j + 2]};
        const Vec3 rwj = rj * Vec3{W[4 * j], W[4 * j + 1], W[4 * j + 2]};
        // contact-point velocity (physics_common.glsl); the spheres' velocities are the
        // bodies' predicted to this substep's time (`bodies`)
        const Vec3 v = physics::pair_contact_velocity(ui, uj, nrm, rwi + rwj);
        // c_n = 2 zeta sqrt(k_n m_eff); granule beds repeat the same mass pair, so the
        // last value is reused when the partner's inverse mass is the same
        const float invm_j = V[4 * j + 3];
        if (invm_j != last_invm_j) {
          last_invm_j = invm_j;
          last_cn = cn0 / std::sqrt(invm_i + invm_j);
        }
        const float cn = last_cn;
        Vec3 xi{xe[0], xe[1], xe[2]};  // zero for a new contact; carried over on rebuilds
        const ContactParams cp{kn, cn, kt, ctr * cn, mu, dt, first_law && TCH[e] == 0};  // new_contact: first substep
        TCH[e] = 1;
        ContactForce cf = contact_force(cp, nrm, rs - dist, v, xi);
        xe[0] = xi.x;
        xe[1] = xi.y;
        xe[2] = xi.z;
        add_pair(i, j, from_vec3(cf.f), from_vec3(cross(nrm, cf.ft)));
      }
    }
    }
    }
    }  // scalar pair pass
    }  // omp parallel
    stats.contacts = npairs;
    stats.neighbour_entries = nstart.empty() ? 0 : nstart[np];
  }

  // ---- sphere stage (called by the body stage for each sphere of a body): sphere i takes the
  // pair pass's sums (and zeroes them) and adds the boundaries; returns the sphere's force and
  // torque (the body stage sums them straight into the body: the particle fields force/torque
  // are the GL backend's).
  struct LawConstants {
    float kn, cn0, kt, ctr, mu;  // N/m, c_n = cn0 / sqrt(1/m_i + 1/m_j), N/m, c_t/c_n, -
  } law{};
  struct SphereSum {
    Vec3 F, T;  // N, N m (about the sphere centre)
    Vec3 x;     // the sphere's centre, m
  };
  // What gather_sphere reads, copied to a local of the body stage once per substep: held in
  // members, these were loaded again after every float store (the compiler cannot tell a
  // store to a force from one to a member), ~20 instructions per sphere-step.
  struct GatherCtx {
    LawConstants law;
    const float *P, *V, *W;
    float* ACC;
    float* WX;
    std::uint32_t* WM;
    physics::Boundaries bounds;
    float floor_y;
    bool first_law;
    // A sphere with x0 + r <= x <= x1 - r, z0 + r <= z <= z1 - r and y >= floor_y + r touches
    // no boundary (m): the side walls' or the fill rectangle's sides (the terrain), +-inf
    // without either; boundary_contacts is only called for the others.
    float x0, x1, z0, z1;
  };
  GatherCtx gather_ctx() const {
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
            physics::Boundaries{def.floor_height, def.side_walls, !def.terrain.empty(), def.bounds_min, def.bounds_max},
            def.floor_height, first_law, x0, x1, z0, z1};
  }
  // Sphere i's force F4 and torque T4 about its centre (lane 3 = 0); returns its centre (lane 3 = 0).
  __attribute__((always_inline)) __m128 gather_sphere4(const GatherCtx& g, const int i, const float dt,
                                                       std::int64_t& nwall, __m128& F4, __m128& T4) {
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
      if (py - g.floor_y < ri || px - g.x0 < ri || g.x1 - px < ri || pz - g.z0 < ri || g.z1 - pz < ri) {
        Vec3 F = to_vec3(F4), T = to_vec3(T4);
        boundary_contacts(g, i, dt, F, T, nwall);
        F4 = from_vec3(F), T4 = from_vec3(T);
      } else if (g.WM[i] != 0) {
        g.WM[i] = 0;
      }
    }
    return xyz0(P4);
  }
  __attribute__((always_inline)) SphereSum gather_sphere(const GatherCtx& g, const int i, const float dt,
                                                         std::int64_t& nwall) {
    __m128 F4, T4;
    const __m128 x4 = gather_sphere4(g, i, dt, nwall, F4, T4);
    return {to_vec3(F4), to_vec3(T4), to_vec3(x4)};
  }
  // Boundaries of sphere i (dynamic): the planes of physics::boundary_plane (floor, side walls,
  // the terrain outside the fill and the fill's sides; shaders/dem/physics_common.glsl, shared
  // with the GL force kernel) in slot order; adds their force and torque (about the sphere
  // centre) to F, T. WM[i] has bit k set while plane k touched the sphere at the last substep;
  // a plane contact that was not in the mask starts with a fresh spring. Out of line: 4 % of
  // sphere-steps reach it in a bed.
  __attribute__((noinline)) void boundary_contacts(const GatherCtx& g, const int i, const float dt, Vec3& F, Vec3& T,
                                                   std::int64_t& nwall) {
    const float kn = g.law.kn, cn0 = g.law.cn0, kt = g.law.kt, ctr = g.law.ctr, mu = g.law.mu;
    const float* P = g.P;
    const float* V = g.V;
    const float* W = g.W;
    const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
    const float ri = P[4 * i + 3];
    const Vec3 ui{V[4 * i], V[4 * i + 1], V[4 * i + 2]};
    const float invm_i = V[4 * i + 3];
    const Vec3 wi{W[4 * i], W[4 * i + 1], W[4 * i + 2]};
    float* wx = g.WX + std::size_t(i) * 3 * kWallSlots;
    const std::uint32_t old_mask = g.WM[i];
    std::uint32_t mask = 0;
    for (int slot = 0; slot < kWallSlots; ++slot) {
      Vec3 nrm;
      float dist;
      if (!physics::boundary_plane(g.bounds, def.terrain, slot, pi, ri, nrm, dist)) continue;
      float* xe = wx + 3 * slot;
      ++nwall;
      mask |= 1u << slot;
      const Vec3 v = physics::plane_contact_velocity(ui, wi, nrm, ri);
      const bool fresh = !(old_mask & (1u << slot));
      Vec3 xi{};
      if (!fresh) xi = {xe[0], xe[1], xe[2]};
      const float cnw = cn0 / std::sqrt(invm_i);
      // new_contact: the first substep of this plane contact
      const ContactParams cp{kn, cnw, kt, ctr * cnw, mu, dt, g.first_law && fresh};
      const ContactForce cf = contact_force(cp, nrm, ri - dist, v, xi);
      xe[0] = xi.x;
      xe[1] = xi.y;
      xe[2] = xi.z;
      F = F + cf.f;
      T = T + cross(nrm * (-ri), cf.ft);
    }
    if (mask != old_mask) g.WM[i] = mask;
  }

  // The body stage for granule i (dynamic, isotropic inertia): the formulas of the general
  // path below in 4-wide SSE2 registers, each lane doing the scalar code's float operations in
  // its order (the same results bit for bit, ~1/3 fewer instructions).
  __attribute__((always_inline)) void granule_update(const GatherCtx& gctx, const int i, const float dt,
                                                     std::int64_t& nwall, float& d2max, float& vmax, int& bad) {
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

  // ---- body stage: gather each sphere (gather_sphere), sum the spheres' forces in id order,
  // integrate, rebuild the spheres
  bool bodies(float dt, float* d2max_out) {
    const Vec3 g = gravity;
    const float reach = shape.centre_distance + shape.radius;
    float d2max = 0, vmax = 0;
    int bad = 0;
    std::int64_t nwall = 0;
    const int n = nb;
    const bool ordered = int(body_order.size()) == n;
    const std::int32_t* order = body_order.data();
    const GatherCtx gctx = gather_ctx();
#pragma omp parallel for num_threads(threads) schedule(dynamic, 128) reduction(max : d2max, vmax) reduction(+ : bad, nwall) if (n > 2048 || np > 4096)
    for (int t = 0; t < n; ++t) {
      const int i = ordered ? order[t] : t;
      const std::uint32_t fl = b.flags[i];
      const Vec3 x = ld3(b.pos, i);
      Vec3 F{}, T{};
      if (fl & kBodyStatic) {  // no force on a static body (its spheres' sums are only cleared)
        st3(b.force, i, F);
        st3(b.torque, i, T);
        for (int k = 0, first = b.first[i], cnt = b.count[i]; k < cnt; ++k)
          acc[std::size_t(slot_of[first + k])] = SphereSums{};
        continue;
      }
      if (fl & kBodyGranule) {  // (granules are dynamic)
        granule_update(gctx, i, dt, nwall, d2max, vmax, bad);
        continue;
      }
      for (int k = 0, first = b.first[i], cnt = b.count[i]; k < cnt; ++k) {
        const int s = slot_of[first + k];
        const SphereSum ss = gather_sphere(gctx, s, dt, nwall);
        const Vec3 f = ss.F;
        F = F + f;
        T = T + ss.T + cross(ss.x - x, f);
      }
      st3(b.force, i, F);
      st3(b.torque, i, T);
      Vec3 v = ld3(b.vel, i), w = ld3(b.omega, i);
      const Vec3 v_old = v;
      Quat q = ldq(b.quat, i);
      if (fl & kBodyDynamic) {
        const float invm = b.mass[4 * i + 1];
        v = v + dt * (F * invm + g);
        const Vec3 iI = ld3(b.inv_inertia, i);
        if (fl & kBodyGranule) {
          w = w + T * (dt * iI.x);  // isotropic inertia
        } else {
          // body frame: I dw/dt = T - w x I w
          Vec3 wb = rotate_inv(q, w), tb = rotate_inv(q, T);
          Vec3 Iw{iI.x > 0 ? wb.x / iI.x : 0, iI.y > 0 ? wb.y / iI.y : 0, iI.z > 0 ? wb.z / iI.z : 0};
          Vec3 rhs = tb - cross(wb, Iw);
          wb = wb + dt * Vec3{rhs.x * iI.x, rhs.y * iI.y, rhs.z * iI.z};
          w = rotate(q, wb);
        }
        st3(b.vel, i, v);
        st3(b.omega, i, w);
        if (fl & kBodyGranule) vmax = std::max(vmax, std::sqrt(dot(v, v)) + std::sqrt(dot(w, w)) * reach);
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
      d2max = std::max(d2max, rebuild_body(i, v + pred_gain * (v - v_old), w));
    }
    *d2max_out = d2max;
    granule_vmax = vmax;
    stats.wall_contacts = nwall;
    return bad == 0;
  }

  // The substep's stages, each timed into stats (StepStats::*_seconds).
  Status substep(float dt) {
    using Clock = std::chrono::steady_clock;
    auto since = [](Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); };
    pred_gain = float(predictor_gain(dt));
    first_law = timing_on(dt);
    auto t0 = Clock::now();
    if (need_sort) {
      sort();
      stats.sort_seconds += since(t0);
      t0 = Clock::now();
    }
    contacts(dt);
    stats.pair_seconds += since(t0);
    t0 = Clock::now();
    float d2max = 0;
    const bool finite = bodies(dt, &d2max);
    stats.body_seconds += since(t0);
    if (!finite)
      return Error{"", "step", "NaN", "a body state became non-finite in the integrate stage",
                   "reduce the frame dt or material.normal_stiffness, or check the inputs"};
    if (4.0f * d2max > skin * skin) need_sort = true;
    if (need_sort) {
      t0 = Clock::now();
      sort();
      stats.sort_seconds += since(t0);
    }
    time += dt;
    return Ok{};
  }

  double max_granule_speed() const {
    double m = 0;
    for (int i = 0; i < nb; ++i) {
      if (!(b.flags[i] & kBodyGranule)) continue;
      double s = length(ld3(b.vel, i)) + length(ld3(b.omega, i)) * (shape.centre_distance + shape.radius);
      m = std::max(m, s);
    }
    return m;
  }

  // Asleep: move the kinematic bodies; true if one of their spheres would touch a dynamic one.
  bool kinematic_touch(double dt) {
    for (int i = 0; i < nb; ++i) {
      if (!(b.flags[i] & kBodyKinematic)) continue;
      Vec3 v = ld3(b.vel, i), w = ld3(b.omega, i);
      if (dot(v, v) == 0.0f && dot(w, w) == 0.0f) continue;
      Vec3 x = ld3(b.pos, i) + float(dt) * v;
      Quat q = ldq(b.quat, i);
      Quat qd = Quat{w.x, w.y, w.z, 0} * q;
      float hd = 0.5f * float(dt);
      q = normalized(Quat{q.x + hd * qd.x, q.y + hd * qd.y, q.z + hd * qd.z, q.w + hd * qd.w});
      for (int k = 0; k < b.count[i]; ++k) {
        int s = slot_of[b.first[i] + k];
        Vec3 xs = x + rotate(q, ld3(p.offset, s));
        float r = p.pos[4 * s + 3];
        int c = cell_of(xs);
        int cx = c % gx, cy = (c / gx) % gy, cz = c / (gx * gy);
        for (int zz = std::max(0, cz - 1); zz <= std::min(gz - 1, cz + 1); ++zz)
          for (int yy = std::max(0, cy - 1); yy <= std::min(gy - 1, cy + 1); ++yy)
            for (int xx = std::max(0, cx - 1); xx <= std::min(gx - 1, cx + 1); ++xx) {
              int cc = (zz * gy + yy) * gx + xx;
              for (int j = cell_start[cc]; j < cell_start[cc + 1]; ++j) {
                if (p.vel[4 * j + 3] == 0.0f) continue;
                Vec3 d = xs - ld3(p.pos, j);
                float rs = r + p.pos[4 * j + 3] + 0.5f * skin;
                if (dot(d, d) < rs * rs) return true;
              }
            }
      }
    }
    return false;
  }

  void move_kinematic(double dt) {
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
  int push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm, Vec3 inv_inertia,
                const Vec3* offsets, const float* radii, int count, bool one_radius) {
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
    st3(b.pos, i, x);
    stq(b.quat, i, normalized(q));
    st3(b.vel, i, v);
    st3(b.omega, i, w);
    b.mass[4 * i] = mass;
    b.mass[4 * i + 1] = invm;
    st3(b.inv_inertia, i, inv_inertia);
    b.flags[i] = flags;
    b.first[i] = np;
    b.count[i] = count;
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
    asleep = false;
    below_time = 0;
    return i;
  }
};

// ---------------------------------------------------------------------------------------
Simulation::Simulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;
Simulation::~Simulation() = default;

Result<Simulation> Simulation::create(const SimulationDef& d) {
  std::vector<Error> es;
  auto bad = [&](const std::string& f, double v, const char* allowed) {
    es.push_back(Error{"", "SimulationDef." + f, format_number(v), allowed, ""});
  };
  if (d.max_bodies < 1 || d.max_bodies > (1 << 28)) bad("max_bodies", d.max_bodies, "must be in [1, 2^28]");
  if (d.max_particles < 1 || d.max_particles > (1 << 28))
    bad("max_particles", d.max_particles, "must be in [1, 2^28]");
  if (!(d.particle_radius > 0) || !std::isfinite(d.particle_radius))
    bad("particle_radius", d.particle_radius, "must be a finite number > 0 (m)");
  if (!(d.granule_edge_factor >= 0.5f && d.granule_edge_factor <= 1.0f))
    bad("granule_edge_factor", d.granule_edge_factor, "must be in [0.5, 1] (edge = 2 r s)");
  if (auto st = validate(d.material, "SimulationDef.material"); !st)
    for (auto& e : st.errors()) es.push_back(e);
  const char* axes[3] = {"x", "y", "z"};
  float lo[3] = {d.bounds_min.x, d.bounds_min.y, d.bounds_min.z};
  float hi[3] = {d.bounds_max.x, d.bounds_max.y, d.bounds_max.z};
  for (int a = 0; a < 3; ++a)
    if (!(hi[a] > lo[a]) || !std::isfinite(lo[a]) || !std::isfinite(hi[a]))
      bad(std::string("bounds_max.") + axes[a], hi[a], "must be finite and > bounds_min");
  // Float positions resolve |x| 2^-23 (m): keep that below 1e-3 r, i.e. |x| <= 8389 r (42 m at
  // r = 5 mm). Farther patches keep their simulation near 0 and put the offset in
  // scale.origin (a double).
  if (es.empty()) {
    const double far = 8388.608 * double(d.particle_radius);
    for (int a = 0; a < 3; ++a)
      for (int m = 0; m < 2; ++m) {
        const double v = m == 0 ? lo[a] : hi[a];
        if (std::abs(v) > far) {
          es.push_back(Error{"", std::string(m == 0 ? "SimulationDef.bounds_min." : "SimulationDef.bounds_max.") + axes[a],
                             format_number(v) + " m",
                             "must be within 8389 particle_radius = " + format_number(far) +
                                 " m of the simulation origin (float positions resolve |x| 2^-23 m, 1e-3 r there)",
                             "simulate patch-relative near 0 and put the patch offset in SimulationDef.scale origin "
                             "(ParticleScale::create(scale, origin), double)"});
          a = 3;
          break;
        }
      }
  }
  if (!std::isfinite(d.floor_height)) bad("floor_height", d.floor_height, "must be finite (m)");
  if (!std::isfinite(d.gravity_world.x + d.gravity_world.y + d.gravity_world.z))
    bad("gravity_world", 0, "must be finite (m/s^2)");
  if (!(d.cell_skin >= 0) || !std::isfinite(d.cell_skin)) bad("cell_skin", d.cell_skin, "must be >= 0 (m)");
  if (d.accuracy_steps_per_contact < 2)
    bad("accuracy_steps_per_contact", d.accuracy_steps_per_contact, "must be >= 2 (20 or more for accuracy)");
  if (d.max_substeps < 1) bad("max_substeps", d.max_substeps, "must be >= 1");
  if (!(d.max_overlap_fraction >= 0) || !std::isfinite(d.max_overlap_fraction))
    bad("max_overlap_fraction", d.max_overlap_fraction, "must be a finite number >= 0 (0 = guard off)");
  if (!(d.sleep_speed >= 0)) bad("sleep_speed", d.sleep_speed, "must be >= 0 (m/s)");
  if (!(d.sleep_time >= 0)) bad("sleep_time", d.sleep_time, "must be >= 0 (s)");
  if (d.threads < 0) bad("threads", d.threads, "must be >= 0 (0 = OpenMP default)");
  if (!d.terrain.empty()) {
    const TerrainGrid& t = d.terrain;
    if (t.nx < 2 || t.nz < 2 || std::size_t(t.nx) * std::size_t(t.nz) != t.heights.size())
      bad("terrain.heights", double(t.heights.size()), "must hold nx * nz >= 4 samples (nx, nz >= 2)");
    if (!(t.spacing > 0)) bad("terrain.spacing", t.spacing, "must be > 0 (m)");
  }
  if (!es.empty()) return es;

  auto im = std::make_unique<Impl>();
  Impl& s = *im;
  s.def = d;
  s.shape = make_granule_shape(d.particle_radius, d.granule_edge_factor, d.material.density);
  for (int k = 0; k < 4; ++k) {
    s.shape_offsets[4 * k] = s.shape.offsets[k].x;
    s.shape_offsets[4 * k + 1] = s.shape.offsets[k].y;
    s.shape_offsets[4 * k + 2] = s.shape.offsets[k].z;
  }
  s.gravity = d.scale.gravity_to_sim(d.gravity_world);
  s.threads = d.threads > 0 ? d.threads : omp_get_max_threads();
  s.simd_pairs = simd::use_avx2_pair_kernel();
  s.zeta = damping_ratio_from_restitution(d.material.restitution);
  s.r_max = d.particle_radius;
  s.skin = d.cell_skin > 0 ? d.cell_skin : 0.2f * d.particle_radius;
  {
    float h = 2.0f * s.r_max + s.skin;
    Vec3 ext = d.bounds_max - d.bounds_min;
    double cells = std::ceil(ext.x / h) * std::ceil(ext.y / h) * std::ceil(ext.z / h);
    if (cells > double(1 << 26))
      return Error{"", "SimulationDef.bounds_max", format_number(cells) + " grid cells",
                   "the grid (cell = 2 particle_radius + cell_skin) must have <= 2^26 cells",
                   "shrink the bounds or raise particle_radius"};
  }
  s.b.resize(d.max_bodies);
  s.p.resize(d.max_particles);
  s.slot_of.assign(d.max_particles, -1);
  s.cell.assign(d.max_particles, 0);
  s.pos_at_sort.assign(std::size_t(d.max_particles) * 4, 0.0f);
  s.acc.assign(std::size_t(d.max_particles), Impl::SphereSums{});
  s.guard_pt_mass.assign(d.max_bodies, 0.0f);
  s.guard_arm.assign(d.max_bodies, 0.0f);
  s.guard_rmin.assign(d.max_bodies, 0.0f);
  s.size_grid();
  return Simulation(std::move(im));
}

Result<BodyId> Simulation::add_granule(Vec3 x, Quat q, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (s.nb + 1 > s.def.max_bodies)
    return Error{"", "SimulationDef.max_bodies", format_number(s.def.max_bodies), "is full: raise max_bodies",
                 "add_granule needs 1 more body"};
  if (s.np + 4 > s.def.max_particles)
    return Error{"", "SimulationDef.max_particles", format_number(s.def.max_particles), "is full: raise max_particles",
                 "add_granule needs 4 more particles"};
  if (!std::isfinite(x.x + x.y + x.z + q.x + q.y + q.z + q.w + v.x + v.y + v.z + w.x + w.y + w.z))
    return Error{"", "add_granule", "non-finite", "position, orientation and velocities must be finite", ""};
  const GranuleShape& g = s.shape;
  float r = g.radius;
  float inv_i = 1.0f / g.inertia;
  int i = s.push_body(kBodyGranule | kBodyDynamic, x, q, v, w, g.mass, 1.0f / g.mass, {inv_i, inv_i, inv_i},
                      g.offsets.data(), &r, 4, true);
  return BodyId{i};
}

Result<ShellPlan> plan_shell(const ShellDef& sh, int bodies_used, int max_bodies, int particles_used,
                             int max_particles) {
  ShellPlan p;
  p.count = int(sh.offsets.size());
  const int count = p.count;
  if (count < 1) return Error{"", "ShellDef.offsets", "0 spheres", "must hold at least one sphere", ""};
  p.one_radius = sh.radii.size() == 1;
  if (!p.one_radius && int(sh.radii.size()) != count)
    return Error{"", "ShellDef.radii", format_number(double(sh.radii.size())) + " radii",
                 "must hold one radius, or one per offset (" + std::to_string(count) + ")", ""};
  if (bodies_used + 1 > max_bodies)
    return Error{"", "SimulationDef.max_bodies", format_number(max_bodies), "is full: raise max_bodies",
                 "add_shell needs 1 more body"};
  if (particles_used + count > max_particles)
    return Error{"", "SimulationDef.max_particles", format_number(max_particles), "is full: raise max_particles",
                 "add_shell needs " + std::to_string(count) + " more particles"};
  for (int k = 0; k < count; ++k) {
    const float r = p.one_radius ? sh.radii[0] : sh.radii[k];
    if (!(r > 0) || !std::isfinite(r))
      return Error{"", "ShellDef.radii[" + std::to_string(p.one_radius ? 0 : k) + "]", format_number(r),
                   "must be > 0 (m)", ""};
    if (!std::isfinite(sh.offsets[k].x + sh.offsets[k].y + sh.offsets[k].z))
      return Error{"", "ShellDef.offsets[" + std::to_string(k) + "]", "non-finite", "must be finite (m)", ""};
    p.max_radius = std::max(p.max_radius, r);
    p.arm = std::max(p.arm, length(sh.offsets[k]));
  }
  if (sh.motion == MotionType::Dynamic) {
    if (!(sh.mass > 0) || !std::isfinite(sh.mass))
      return Error{"", "ShellDef.mass", format_number(sh.mass), "must be > 0 (kg)", ""};
    if (!(sh.inertia.x > 0 && sh.inertia.y > 0 && sh.inertia.z > 0))
      return Error{"", "ShellDef.inertia", format_number(std::min({sh.inertia.x, sh.inertia.y, sh.inertia.z})),
                   "principal moments must be > 0 (kg m^2)", ""};
    p.flags = kBodyDynamic;
    p.inv_mass = 1.0f / sh.mass;
    p.inv_inertia = {1.0f / sh.inertia.x, 1.0f / sh.inertia.y, 1.0f / sh.inertia.z};
  } else {
    p.flags = sh.motion == MotionType::Static ? kBodyStatic : kBodyKinematic;
  }
  return p;
}

Result<BodyId> Simulation::add_shell(const ShellDef& sh) {
  Impl& s = *impl_;
  auto plan = plan_shell(sh, s.nb, s.def.max_bodies, s.np, s.def.max_particles);
  if (!plan) return plan.errors();
  const int count = plan->count;
  const bool one = plan->one_radius;
  const float rmax = plan->max_radius, arm = plan->arm, invm = plan->inv_mass;
  const std::uint32_t flags = plan->flags;
  const Vec3 iI = plan->inv_inertia;
  // overlap guard: the body's weight shared by all its spheres (the most favourable case)
  if (sh.motion == MotionType::Dynamic && s.def.max_overlap_fraction > 0) {
    float rmin = std::numeric_limits<float>::infinity();
    for (int k = 0; k < count; ++k) rmin = std::min(rmin, one ? sh.radii[0] : sh.radii[k]);
    const double r = std::min(double(rmin), double(s.def.particle_radius));
    const double g = length(s.gravity), kn = s.def.material.normal_stiffness, f = s.def.max_overlap_fraction;
    const double overlap = double(sh.mass) * g / (count * kn);
    if (overlap > f * r)
      return Error{"", "ShellDef.mass", format_number(sh.mass) + " kg",
                   "must be <= " + format_number(f * r * count * kn / g) + " kg: its weight on its " +
                       std::to_string(count) + " spheres overlaps each contact by >= m |g| / (n k_n) = " +
                       format_number(overlap) + " m > max_overlap_fraction x r = " + format_number(f * r) +
                       " m, so it would sink through the bed and the floor",
                   "raise SimulationDef.material.normal_stiffness to >= " + format_number(kn * overlap / (f * r)) +
                       " N/m, give the shell more spheres, or lower its mass"};
  }
  // a new dynamic body may shorten the contact time (the guard uses the lightest body)
  if (sh.motion == MotionType::Dynamic) {
    double imin = std::min({sh.inertia.x, sh.inertia.y, sh.inertia.z});
    s.min_point_mass = std::min(s.min_point_mass, point_effective_mass(sh.mass, imin, arm));
  }
  if (rmax > s.r_max) {  // bigger spheres: bigger (fewer) grid cells
    s.r_max = rmax;
    s.size_grid();
  }
  int i = s.push_body(flags, sh.position, sh.orientation, sh.velocity, sh.angular_velocity,
                      sh.motion == MotionType::Dynamic ? sh.mass : 0.0f, invm, iI, sh.offsets.data(),
                      sh.radii.data(), count, one);
  return BodyId{i};
}

Status Simulation::set_kinematic_velocity(BodyId id, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (id.index < 0 || id.index >= s.nb || !(s.b.flags[id.index] & kBodyKinematic))
    return Error{"", "set_kinematic_velocity.body", std::to_string(id.index), "must be a kinematic shell", ""};
  st3(s.b.vel, id.index, v);
  st3(s.b.omega, id.index, w);
  return Ok{};
}

Result<int> Simulation::substeps_for(double dt_frame) const {
  const Impl& s = *impl_;
  if (!(dt_frame > 0) || !std::isfinite(dt_frame))
    return Error{"", "step.dt_frame", format_number(dt_frame), "must be a finite number > 0 (s)", ""};
  double mdt = s.max_dt();
  double n = std::ceil(dt_frame / mdt * (1.0 - 1e-9));
  if (n < 1) n = 1;
  if (n > s.def.max_substeps)
    return Error{"", "step.dt_frame", format_number(dt_frame),
                 "needs " + format_number(n) + " substeps of <= " + format_number(mdt) + " s (t_c = " + format_number(s.contact_time_()) +
                     " s / " + std::to_string(s.def.accuracy_steps_per_contact) + ") but max_substeps = " +
                     std::to_string(s.def.max_substeps),
                 "lower dt_frame, raise SimulationDef.max_substeps, or lower material.normal_stiffness"};
  return int(n);
}

Status Simulation::step(double dt_frame) {
  Impl& s = *impl_;
  auto ns = substeps_for(dt_frame);
  if (!ns) return ns.errors();
  const auto t_guard = std::chrono::steady_clock::now();
  if (!s.asleep)
    if (auto st = s.check_impacts(); !st) return st;
  s.stats = StepStats{};
  s.stats.guard_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_guard).count();
  s.stats.substeps = *ns;
  s.stats.substep_dt = dt_frame / *ns;
  if (s.asleep) {
    if (!s.kinematic_touch(dt_frame)) {
      s.move_kinematic(dt_frame);
      s.time += dt_frame;
      s.stats.slept = true;
      s.stats.substeps = 0;
      return Ok{};
    }
    s.asleep = false;
    s.below_time = 0;
  }
  const float dt = float(dt_frame / *ns);
  for (int k = 0; k < *ns; ++k)
    if (auto st = s.substep(dt); !st) return st;
  update_sleep(s.def, s.granule_vmax, dt_frame, s.below_time, s.asleep);  // dem_control.hpp
  return Ok{};
}

double Simulation::contact_time() const { return impl_->contact_time_(); }
double Simulation::max_impact_speed(double m_pt) const { return impl_->max_impact_speed(m_pt); }
double Simulation::max_substep_dt() const { return impl_->max_dt(); }
double Simulation::velocity_predictor_gain(double dt) const { return impl_->predictor_gain(dt); }
bool Simulation::contact_timing_on(double dt) const { return impl_->timing_on(dt); }
bool Simulation::asleep() const { return impl_->asleep; }
void Simulation::wake() {
  impl_->asleep = false;
  impl_->below_time = 0;
}
int Simulation::body_count() const { return impl_->nb; }
int Simulation::particle_count() const { return impl_->np; }
Vec3 Simulation::body_position(BodyId b) const { return ld3(impl_->b.pos, b.index); }
Quat Simulation::body_orientation(BodyId b) const { return ldq(impl_->b.quat, b.index); }
Vec3 Simulation::body_velocity(BodyId b) const { return ld3(impl_->b.vel, b.index); }
Vec3 Simulation::body_angular_velocity(BodyId b) const { return ld3(impl_->b.omega, b.index); }
Vec3 Simulation::body_force(BodyId b) const { return ld3(impl_->b.force, b.index); }
Vec3 Simulation::body_torque(BodyId b) const { return ld3(impl_->b.torque, b.index); }
const StepStats& Simulation::last_step() const { return impl_->stats; }
Status Simulation::set_threads(int threads) {
  if (threads < 0)
    return Error{"", "Simulation::set_threads.threads", std::to_string(threads), "must be >= 0 (0 = OpenMP's default)", ""};
  impl_->threads = threads > 0 ? threads : omp_get_max_threads();
  return Ok{};
}
const SimulationDef& Simulation::def() const { return impl_->def; }
const GranuleShape& Simulation::granule_shape() const { return impl_->shape; }
double Simulation::time() const { return impl_->time; }
double Simulation::max_granule_speed() const { return impl_->max_granule_speed(); }

std::vector<Vec3> Simulation::particle_positions() const {
  const Impl& s = *impl_;
  std::vector<Vec3> out(s.np);
  for (int id = 0; id < s.np; ++id) out[id] = ld3(s.p.pos, s.slot_of[id]);
  return out;
}

double Simulation::kinetic_energy() const {
  const Impl& s = *impl_;
  double e = 0;
  for (int i = 0; i < s.nb; ++i) {
    if (!(s.b.flags[i] & kBodyDynamic)) continue;
    Vec3 v = ld3(s.b.vel, i);
    e += 0.5 * s.b.mass[4 * i] * double(dot(v, v));
    Vec3 wb = rotate_inv(ldq(s.b.quat, i), ld3(s.b.omega, i));
    Vec3 iI = ld3(s.b.inv_inertia, i);
    e += 0.5 * (double(wb.x) * wb.x / iI.x + double(wb.y) * wb.y / iI.y + double(wb.z) * wb.z / iI.z);
  }
  return e;
}

double Simulation::potential_energy() const {
  const Impl& s = *impl_;
  double e = 0;
  // gravity
  for (int i = 0; i < s.nb; ++i) {
    if (!(s.b.flags[i] & kBodyDynamic)) continue;
    e -= double(s.b.mass[4 * i]) * double(dot(s.gravity, ld3(s.b.pos, i)));
  }
  // elastic: normal springs at the current positions, tangential springs from the history
  const Material& m = s.def.material;
  const float kn = m.normal_stiffness, kt = m.normal_stiffness * m.tangential_stiffness_ratio;
  for (int i = 0; i < s.np; ++i) {
    Vec3 pi = ld3(s.p.pos, i);
    float ri = s.p.pos[4 * i + 3];
    bool dyn_i = s.p.vel[4 * i + 3] > 0;
    int c = s.cell_of(pi);
    int cx = c % s.gx, cy = (c / s.gx) % s.gy, cz = c / (s.gx * s.gy);
    for (int zz = std::max(0, cz - 1); zz <= std::min(s.gz - 1, cz + 1); ++zz)
      for (int yy = std::max(0, cy - 1); yy <= std::min(s.gy - 1, cy + 1); ++yy)
        for (int xx = std::max(0, cx - 1); xx <= std::min(s.gx - 1, cx + 1); ++xx) {
          int cc = (zz * s.gy + yy) * s.gx + xx;
          for (int j = s.cell_start[cc]; j < s.cell_start[cc + 1]; ++j) {
            if (s.p.body[j] == s.p.body[i]) continue;
            if (!dyn_i && s.p.vel[4 * j + 3] == 0) continue;
            float d = length(pi - ld3(s.p.pos, j));
            float del = ri + s.p.pos[4 * j + 3] - d;
            if (del > 0) e += 0.25 * kn * double(del) * del;  // half of the pair, counted twice
          }
        }
    if (dyn_i) {
      auto plane = [&](float dist) {
        if (dist < ri) e += 0.5 * kn * double(ri - dist) * (ri - dist);
      };
      plane(pi.y - s.def.floor_height);
      if (s.def.side_walls) {
        plane(pi.x - s.def.bounds_min.x);
        plane(s.def.bounds_max.x - pi.x);
        plane(pi.z - s.def.bounds_min.z);
        plane(s.def.bounds_max.z - pi.z);
      }
    }
    if (i < int(s.nstart.size()) - 1) {
      for (int k = s.nstart[i]; k < s.nstart[i + 1]; ++k) {  // one entry per pair
        const float* x = &s.pairs.xi[3 * std::size_t(k)];
        e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
      }
      for (int k = 0; k < kWallSlots; ++k) {
        if (!(s.p.wall_mask[i] & (1u << k))) continue;
        const float* x = &s.p.wall_xi[(std::size_t(i) * kWallSlots + k) * 3];
        e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
      }
    }
  }
  return e;
}

std::uint64_t Simulation::state_hash() const {
  const Impl& s = *impl_;
  Hasher h;
  h.pod(s.nb);
  h.pod(s.np);
#define SP_HASH_B(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.b.name.data(), sizeof(type) * std::size_t(n) * s.nb);)
  SANDPATCH_BODY_FIELDS(SP_HASH_B)
#undef SP_HASH_B
#define SP_HASH_P(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.p.name.data(), sizeof(type) * std::size_t(n) * s.np);)
  SANDPATCH_PARTICLE_FIELDS(SP_HASH_P)
  SANDPATCH_SPHERE_CONTACT_FIELDS(SP_HASH_P)
#undef SP_HASH_P
  // the pairs' contact history, in list order (the list is the same for any thread count)
  const std::size_t entries = s.nstart.empty() ? 0 : std::size_t(s.nstart[s.np]);
#define SP_HASH_C(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.pairs.name.data(), sizeof(type) * std::size_t(n) * entries);)
  SANDPATCH_PAIR_CONTACT_FIELDS(SP_HASH_C)
#undef SP_HASH_C
  return h.value();
}

// ---- control from the terrain manager ----

Status Simulation::reset(const SimulationDef& d) {
  const SimulationDef& cur = impl_->def;
  if (d.max_bodies > cur.max_bodies)
    return Error{"", "reset.max_bodies", std::to_string(d.max_bodies),
                 "must not exceed the slot's capacity " + std::to_string(cur.max_bodies), ""};
  if (d.max_particles > cur.max_particles)
    return Error{"", "reset.max_particles", std::to_string(d.max_particles),
                 "must not exceed the slot's capacity " + std::to_string(cur.max_particles), ""};
  auto fresh = create(d);
  if (!fresh) return fresh.errors();
  *this = std::move(*fresh);
  return Ok{};
}

Status Simulation::set_body_state(BodyId id, Vec3 x, Quat q, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (id.index < 0 || id.index >= s.nb)
    return Error{"", "set_body_state.body", std::to_string(id.index), "must be a body of this simulation", ""};
  if (s.b.flags[id.index] & kBodyParked)
    return Error{"", "set_body_state.body", std::to_string(id.index), "is disabled; enable it first", ""};
  st3(s.b.pos, id.index, x);
  stq(s.b.quat, id.index, normalized(q));
  st3(s.b.vel, id.index, v);
  st3(s.b.omega, id.index, w);
  // Its spheres follow at once, and the neighbour list is rebuilt for the new place.
  s.rebuild_body(id.index);
  s.need_sort = true;
  wake();
  return Ok{};
}

Status Simulation::set_body_enabled(BodyId id, bool enabled) {
  Impl& s = *impl_;
  if (id.index < 0 || id.index >= s.nb)
    return Error{"", "set_body_enabled.body", std::to_string(id.index), "must be a body of this simulation", ""};
  std::uint32_t& f = s.b.flags[id.index];
  const bool parked = f & kBodyParked;
  if (enabled == !parked) return Ok{};
  if (!enabled) {
    f = parked_flags(f);  // dem_control.hpp, as the GL backend
    st3(s.b.pos, id.index, parking_position(s.def));
    st3(s.b.vel, id.index, Vec3{});
    st3(s.b.omega, id.index, Vec3{});
  } else {
    f = unparked_flags(f);
  }
  s.rebuild_body(id.index);
  s.need_sort = true;
  wake();
  return Ok{};
}

}  // namespace sandpatch
