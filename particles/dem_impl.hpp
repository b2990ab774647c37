// The CPU backend's internal state (Simulation::Impl) and the helpers its files share; the
// step's stages are listed in dem.hpp. Internal to particles/: the backend is split by
// responsibility into
//   dem.cpp             Simulation's methods: create, add bodies, step and substep, queries,
//                       energies, state hash, control from the terrain manager
//   dem_grid.cpp        cell grid, counting sort, Verlet neighbour list (and its spring carry-over)
//   dem_contacts.cpp    contact stage, pair pass (scalar, or 8 pairs at a time by the AVX2 kernel)
//   dem_bodies.cpp      body stage: sphere sums, integration, sphere rebuild; push_body
//   dem_boundaries.cpp  boundary planes and terrain (shaders/dem/physics_common.glsl)
//   dem_guard.cpp       step-size and overlap guards, contact timing (velocity predictor)
// The physics shared with the GL kernels is particles/dem_physics.hpp; the host-side rules
// shared with the GL backend (adding bodies, the body record, parking, sleep) are
// particles/dem_control.hpp.
#pragma once

#include <xmmintrin.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "common/error.hpp"
#include "particles/dem.hpp"
#include "particles/dem_physics.hpp"
#include "particles/fields.hpp"

namespace sandpatch {

// Tangential springs against the boundaries, per sphere: floor, walls x0, x1, z0, z1, terrain
// (the plane slots of physics_common.glsl).
constexpr int kWallSlots = physics::kPlaneSlots;
// Per sphere, the pair pass's sums (kAcc floats; Simulation::Impl::acc): contact force (N) in 0-2,
// the sum of n x f_t (N) in 4-6 (the torque about the centre is -r times it); 3 and 7 stay 0.
constexpr std::size_t kAcc = 8;

// v as `size` copies of x: when it holds `size` already, only its first `used` entries are
// set (a reused simulation's arrays, Simulation::reset: the rest were never written since).
template <class T>
inline void refill(std::vector<T>& v, std::size_t size, T x, std::size_t used) {
  if (v.size() == size) std::fill(v.begin(), v.begin() + std::min(used, size), x);
  else v.assign(size, x);
}

// Structure-of-arrays generated from fields.hpp, the CPU's fields only (the GL backend's
// per-sphere force sums are neither allocated nor sorted here): a field of n components is
// (cap x n). The particle arrays include the per-sphere contact history (the boundary-plane
// springs), so the sort permutes it with them.
struct ParticleArrays {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, std::vector<type> name;)
  SANDPATCH_PARTICLE_FIELDS(SP_DECL)
  SANDPATCH_SPHERE_CONTACT_FIELDS(SP_DECL)
#undef SP_DECL
  // Every field cap entries of zeros, writing only the first `used` of a field that holds cap
  // (refill).
  void resize(std::size_t cap, std::size_t used = 0) {
#define SP_RESIZE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, refill(name, cap * (n), type{}, used * (n));)
    SANDPATCH_PARTICLE_FIELDS(SP_RESIZE)
    SANDPATCH_SPHERE_CONTACT_FIELDS(SP_RESIZE)
#undef SP_RESIZE
  }
};

struct BodyArrays {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, std::vector<type> name;)
  SANDPATCH_BODY_FIELDS(SP_DECL)
#undef SP_DECL
  void resize(std::size_t cap, std::size_t used = 0) {  // (as ParticleArrays::resize)
#define SP_RESIZE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, refill(name, cap * (n), type{}, used * (n));)
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
inline Quat ldq(const std::vector<float>& a, std::size_t i) {
  return {a[4 * i], a[4 * i + 1], a[4 * i + 2], a[4 * i + 3]};
}
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

struct Simulation::Impl {
  SimulationDef def;
  GranuleShape shape;
  Vec3 gravity;            // sim units, m/s^2
  int threads = 1;
  // The pair pass evaluates touching pairs 8 at a time with the AVX2 kernel of
  // contact_avx2.cpp (same results bit for bit as contact_force, contact_simd.hpp) when the
  // CPU has AVX2; SANDPATCH_DEM_KERNEL=scalar forces the scalar path (tests run on both),
  // =avx2 asks for the kernel (ignored without AVX2).
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
  // The threads' shares of the two parallel stages, one contiguous run of about equal work a
  // thread, so a thread walks in the pair pass about the part of the bed whose spheres it
  // writes in the body stage: the body stage's runs of body_order (`bodies`), and each
  // parity's runs of the pair pass's slabs (`contacts`; a slab's work: its spheres and list
  // entries, a sleeping sphere's less). Planned again after a sort or a change of the sleeping
  // regions (work_epoch counts them).
  std::vector<int> body_runs;
  std::vector<std::int64_t> slab_work;
  std::vector<int> slab_runs;  // parity p's runs: [p (runs + 1), (p + 1) (runs + 1)), positions k of slabs p + 2 k
  std::uint64_t work_epoch = 1, body_runs_epoch = 0, slab_work_epoch = 0;
  void plan_body_runs(int runs, int n_order, const std::int32_t* order);
  void plan_slab_runs(int runs);
  // Items [0, n) of work w(k) >= 0 in `runs` contiguous runs of about equal work: run r is
  // [R[r], R[r + 1]), R[0] = 0, R[runs] = n.
  template <class Work>
  static void split_in_runs(int n, int runs, int* R, Work&& w) {
    std::int64_t total = 0;
    for (int k = 0; k < n; ++k) total += w(k);
    R[0] = 0;
    for (int r = 1; r <= runs; ++r) R[r] = n;
    std::int64_t done = 0;
    for (int k = 0, r = 1; k < n && r < runs; ++k) {
      done += w(k);
      while (r < runs && done * runs >= total * r) R[r++] = k + 1;
    }
  }
  // Wide shells: a shell (a body that is not a granule) of more than kWideShell spheres is
  // summed and rebuilt by the body stage in chunks of kWideChunk spheres spread over the
  // threads (`bodies`), not by one thread; set by sort(), in body index order. Each chunk sums
  // its spheres in their order and the body adds its chunks in chunk order, so the result is
  // the same for any thread count. (On one thread the two larger crates of
  // leach_2_three_scales, 7,842 and 3,152 spheres, are 24 % of their patches' body stage,
  // which one thread did whatever the thread count: docs/BENCHMARKS.md "Wide shells over the
  // threads".)
  static constexpr int kWideShell = 2048;
  static constexpr int kWideChunk = 512;
  struct WideChunk {
    std::int32_t body, k0, k1;  // the body's spheres [k0, k1) (in the body's own order)
    std::int32_t wide;          // the body's index in wide_bodies
  };
  struct WideBody {
    std::int32_t body, c0, c1;  // its chunks [c0, c1) of wide_chunks
  };
  std::vector<WideChunk> wide_chunks;
  std::vector<WideBody> wide_bodies;
  struct alignas(16) WidePart {
    float F[4], T[4];  // N, N m about the body's centre (lane 3 = 0)
  };
  std::vector<WidePart> wide_parts;  // chunk -> its sums (scratch of `bodies`)
  struct WideMotion {
    Vec3 v, w;  // m/s, rad/s: the velocities its spheres are rebuilt with (a static shell's are not)
  };
  std::vector<WideMotion> wide_motion;  // wide body -> (scratch of `bodies`)
  bool need_sort = true;
  // Lists built ahead of the next step (Simulation::build_lists_now): its stats count them.
  struct EarlyLists {
    int resorts = 0, shell_lists = 0;
    double sort_seconds = 0;
  } early_lists;
  float shape_offsets[16] = {};        // the granule's 4 sphere offsets (x, y, z, 0), m, body frame

  // Verlet neighbour list (CSR, sorted order, no cap), one entry per pair: for sphere i the
  // entries [nstart[i], nstart[i+1]) hold every sphere j of another body with
  // |x_i - x_j| < r_i + r_j + skin at the last rebuild for which i is the pair's owner, the
  // lower sorted index (at least one of the two moves under forces; parked bodies have none).
  // Each entry carries the pair's tangential spring (3 floats).
  std::vector<std::int32_t> nstart;    // np + 1
  std::vector<std::int32_t> nbr;       // sorted index of the partner
  std::vector<std::int32_t> nbr_id;    // stable id of the partner (history carry-over)
  // build_list's scratch, kept between rebuilds: the partners found by each block of
  // kListBlock spheres, in sphere order
  static constexpr int kListBlock = 256;
  // The stages run on `threads` OpenMP threads above this many spheres (the body stage also
  // above half as many bodies); smaller simulations run them on one. Measured on two cores
  // (docs/BENCHMARKS.md "Patches of 1,000-4,000 spheres on two threads"): from 4,096 down to
  // 1,024 the default scene's DEM took 37 % less time and leach_3's 40 % less, with the same
  // final states; at 512 no better.
  static constexpr int kParallelSpheres = 1024;
  std::vector<std::vector<std::int32_t>> list_blocks;
  // The shell list: every pair with a sphere of a shell (a body that is not a granule: a
  // Bullet body's surface, a tool, a static obstacle), apart from the granules' list above,
  // one row per shell sphere (stable ids ascending, rows kept while the bodies are), each
  // with its partners within r_i + r_j + shell_skin: granules, and spheres of other shells
  // with a higher id. A shell moving over the sand (a rolling wheel's rim moves at twice the
  // car's speed) reaches the skin long before the granules around it; it rebuilt the whole
  // list every few substeps (in a car's patch 96 % of the rebuilds were tripped by a shell
  // sphere). Now only this list is rebuilt when a shell sphere has moved
  // shell_trip = min(shell_skin/2, shell_skin - skin) since its last build (a granule moves
  // at most skin between two builds: skin/2 from the sort each side), found through the
  // granules' grid. The granules' list is rebuilt by the granules alone, and rebuilds this
  // list too. Its pairs are computed after the slabs' pass, in list order on one thread
  // (dem_contacts.cpp). docs/dem.md "Neighbour search, contact store, threads".
  static constexpr float kShellSkinFactor = 2.0f;  // shell_skin / skin
  float shell_skin = 0, shell_trip = 0;            // m
  bool need_shell_list = true;
  // SANDPATCH_DEM_SHELL_LIST=each rebuilds the shell list every substep (the reference the
  // tests compare the trip with: the same touching pairs in the same order, so the same state)
  bool shell_list_each_substep = false;
  std::vector<std::int32_t> srow_id;     // row -> the shell sphere's stable id
  std::vector<std::int32_t> srow;        // row -> its sorted index (until the next sort)
  std::vector<std::int32_t> sstart;      // rows + 1
  std::vector<std::int32_t> snbr;        // sorted index of the partner (until the next sort)
  std::vector<std::int32_t> snbr_id;     // stable id of the partner (history carry-over)
  PairArrays spairs;                     // the shell pairs' contact history
  // Rebuilds the shell list from the current positions (serial, deterministic) and carries
  // each pair's spring over by (row id, partner id); sets the shells' pos_at_sort.
  void build_shell_list();
  // The trip tests: sets need_sort / need_shell_list from the largest squared displacements (m^2)
  // of a granule's sphere since the sort and of a shell's since the shell list's build.
  void note_moved(float d2_granule, float d2_shell);
  // Rebuilds what is stale: the grid and both lists (sort), or the shell list alone.
  void refresh_lists();
  std::vector<std::uint32_t> sort_scratch;  // sort()'s copy of one particle field (4-byte values)
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
  // samples on 64,000 spheres. docs/BENCHMARKS.md.)
  struct alignas(32) SphereSums {
    float v[kAcc];
  };
  std::vector<SphereSums> acc;  // one per sphere, 32-byte aligned: one cache line holds it
  std::vector<std::int32_t> chunk_start;  // slabs + 1: sorted index where each slab begins
  // (the boundary-plane springs are particle arrays: p.wall_xi, p.wall_mask, fields.hpp)

  // Springs set from outside (set_contact_springs, dem_springs.cpp), taken by the next sort:
  // pairs by spring_key(lower id, higher id), the spring as the lower id's, in the order set
  // (a later one of a pair wins); plane springs by sphere id and plane.
  struct SetSpring {
    float xi[3];
    float dmax;
  };
  std::vector<std::pair<std::uint64_t, SetSpring>> set_pairs;
  // The set pairs as the list build reads them (index_set_pairs): by lower id, the rows of a
  // CSR (set_row: n + 1 starts; set_hi: the higher id; set_spring). A pair is looked up in the
  // few rows of its lower id, as the old list's entries are (a hash map's look-up per list
  // entry took 0.5 ms of a car's track patch's first step: docs/BENCHMARKS.md).
  std::vector<std::int32_t> set_row, set_hi;
  std::vector<SetSpring> set_spring;
  void index_set_pairs(int n);
  const SetSpring* set_pair(std::int32_t lo, std::int32_t hi) const {
    if (lo < 0 || lo + 1 >= std::int32_t(set_row.size())) return nullptr;
    for (std::int32_t k = set_row[std::size_t(lo)]; k < set_row[std::size_t(lo) + 1]; ++k)
      if (set_hi[std::size_t(k)] == hi) return &set_spring[std::size_t(k)];
    return nullptr;
  }
  std::vector<std::pair<std::int64_t, SetSpring>> set_planes;  // (id * kWallSlots + plane, spring)
  static std::uint64_t spring_key(std::int32_t lo, std::int32_t hi) {
    return (std::uint64_t(std::uint32_t(lo)) << 32) | std::uint32_t(hi);
  }
  // The set plane springs written at their spheres' sorted places (after the sort); both sets emptied.
  void take_set_springs();

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
  // Energy ledger (Simulation::set_energy_ledger; diagnostic, not state): J dissipated since it
  // was switched on by the normal spring-dashpot (dashpot and, hysteretic, the spring's
  // loss) and by friction (slip and tangential damper), pairs and boundary planes; and the
  // normal springs' recoverable energy at the last substep. While on, the pair pass takes the
  // scalar law.
  bool ledger = false;
  double ledger_normal = 0, ledger_friction = 0;
  double ledger_spring_pairs = 0, ledger_spring_walls = 0;  // J at the last substep
  // The work one contact of contact_force_h dissipated this substep (J), v its contact velocity
  // (v_n = v.n, the overlap changing by -v_n dt): normal: the work of the normal force on the
  // pair, -f_n v_n dt, less the change of the normal spring's recoverable energy U(delta, dmax)
  // (1/2 k_n delta^2, or hysteretic f_el^2 / (2 kn2)) from the overlap delta + v_n dt before
  // (with dmax_old) to delta now (with dmax); friction: -f_t . v dt less the tangential
  // spring's energy change (xi2_old = |xi|^2 before). f, ft the contact's total and tangential
  // force (ContactForce). u += U now.
  static double normal_spring_energy(float kn, float kn2, float delta, float dmax) {
    if (!(delta > 0)) return 0;
    if (!(kn2 > kn)) return 0.5 * double(kn) * delta * delta;
    const double d0 = double(dmax) * (1.0 - double(kn) / kn2);
    const double fel = std::max(0.0, std::min(double(kn) * delta, double(kn2) * (delta - d0)));
    return fel * fel / (2.0 * kn2);
  }
  static void ledger_terms(float kn, float kn2, float kt, float delta, float dmax_old, float dmax, Vec3 nrm, Vec3 v,
                           float dt, float xi2_old, Vec3 f, Vec3 ft, Vec3 xi_new, double& dn, double& dfr,
                           double& u) {
    const double vn = dot(v, nrm), fn = dot(f, nrm);
    const double u_now = normal_spring_energy(kn, kn2, delta, dmax);
    const double u_before = normal_spring_energy(kn, kn2, float(delta + vn * dt), dmax_old);
    dn += -fn * vn * dt - (u_now - u_before);
    u += u_now;
    dfr += -double(dot(ft, v)) * dt - 0.5 * double(kt) * (double(dot(xi_new, xi_new)) - xi2_old);
  }

  // ---- setup
  void size_grid();
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
  float rebuild_body(int i);
  // The same with the velocities v, w (m/s, rad/s) the spheres' contacts are to see: the body
  // stage passes them predicted to the next contact stage's time (see `bodies`).
  // In 4-wide SSE2 registers (baseline x86-64), every lane doing the float operations of the
  // Vec3 formulas in their order: arm = R o with R's columns, lane k = dot(row k, o);
  // cross(a, b) lane-wise as math.hpp's. Lane 3 is unused (the radius and the inverse mass
  // are kept in the stores).
  float rebuild_body(int i, Vec3 v, Vec3 w);
  // The same with the body's pose x4 (lane 3 unused), q and v4, w4 (lane 3 = 0) in registers,
  // for its spheres [k0, k1) (its own order; k1 < 0: to the last).
  float rebuild_body(int i, const __m128 x4, const Quat q, const __m128 v4, const __m128 w4, int k0 = 0, int k1 = -1);
  // The same for the body's spheres [k0, k1) only (its own order), from its stored pose.
  float rebuild_spheres(int i, int k0, int k1, Vec3 v, Vec3 w);

  // Counting sort of the particles by cell (stable, serial: deterministic), permuting every
  // particle field, then the neighbour list is rebuilt and the springs carried over.
  void sort();

  // Visits the spheres j > i (sorted order) of other bodies within r_i + r_j + skin of sphere
  // i, in a fixed order: each pair of the grid once (dem_grid.cpp).
  template <class F>
  void for_forward(int i, F&& f) const;

  // Rebuilds the CSR neighbour list (one parallel search into list_blocks, then a parallel
  // fill) and carries each pair's spring over from the old list (found by partner id, turned
  // round where the owner changed).
  void build_list(const std::vector<std::int32_t>& old_slot);

  // ---- sleeping regions (SimulationDef::sleep_regions; dem_regions.cpp)
  // The bed is divided into columns (x, z) of kRegionColumn granule reaches (centre distance +
  // sphere radius) a side. Once a frame, before its substeps (update_regions), a column is
  // active when one of its granules has not been still (kStillDrift) for sleep_time, or a
  // sphere of a moving shell (dynamic or kinematic, not parked) reaches its granules' top
  // within its radius grown by the shell's motion over the frame and half a column; a granule
  // sleeps when neither its column nor any of the 8 around it is active, and wakes when one is. A sleeping granule is not integrated (velocity 0), its
  // spheres take no boundary contacts, and its pairs with other sleeping granules are skipped
  // by the pair pass but kept in the list with their history (springs, touch flags), so a
  // region wakes as it fell asleep; its pairs with awake spheres are computed as before
  // (it is a fixed obstacle to them). A woken granule keeps its still time: it makes its column
  // active only once it moves.
  static constexpr float kRegionColumn = 2.0f;   // granule reaches per column side
  // A granule is still while it stays within kStillDrift sphere radii of where its still time
  // began (its anchor), not while it is slower than sleep_speed: a bed under a moving load
  // rings elastically through the whole patch at 1-30 mm/s (measured under the car of
  // scenes/vehicle_drive.json: half the granules faster than 1 cm/s at any instant, a few
  // with 0.1 mm amplitude), and a speed test kept 88 % of them awake however far the load was.
  static constexpr float kStillDrift = 0.1f;
  static constexpr int kMaxRegionColumns = 1 << 20;  // columns at most (larger columns beyond)
  std::vector<float> still_for;                   // body -> s its granule has stayed within still_drift of its anchor
  std::vector<std::uint8_t> dozing;               // body -> 1 while the granule sleeps
  std::vector<std::uint8_t> sphere_dozing;        // sorted index -> its body's dozing
  std::vector<std::uint8_t> col_active;           // update_regions' scratch: column -> active
  std::vector<float> col_top;                     // column -> its granules' highest reach, m
  int dozing_granules = 0;
  float still_drift = 0;  // m: a granule is still while it stays within this of its anchor
  std::vector<float> anchor;  // body -> where its still time began (x, y, z, -), m
  // Once a frame of dt_frame s, before its substeps: which granules sleep.
  void update_regions(double dt_frame);
  // sphere_dozing from dozing (after a sort permuted the spheres).
  void refresh_sphere_dozing();
  // A granule's body state changed from outside (set_body_state): awake, not still.
  void rouse(int body) {
    if (!def.sleep_regions || !(b.flags[body] & kBodyGranule)) return;
    still_for[std::size_t(body)] = 0;
    for (int k = 0; k < 3; ++k) anchor[4 * std::size_t(body) + k] = b.pos[4 * std::size_t(body) + k];
    if (dozing[std::size_t(body)]) {
      dozing[std::size_t(body)] = 0;
      --dozing_granules;
      for (int k = 0; k < b.count[body]; ++k) sphere_dozing[std::size_t(slot_of[b.first[body] + k])] = 0;
    }
  }

  // ---- guard
  double guard_meff() const;
  double body_pair_meff() const { return 0.5 * double(shape.mass); }
  double contact_time_() const;
  // Lightest dynamic point mass (kg): granules' and dynamic shells'.
  double lightest_point_mass() const;
  double max_impact_speed(double m_pt) const;
  // The body's overlap (m) if it hit something immovable at its current speed, with what the
  // error message needs.
  struct ImpactCheck {
    double speed, m, r, overlap;  // m/s, kg (point mass), m (smallest sphere radius), m
  };
  ImpactCheck impact_of(int i, double kn, double m_light) const;
  // The overlap guard before a step: every moving body's speed against the immovable case.
  // The scan is parallel (it ran on one thread and was ~5 % of a two-thread step of a
  // 64,000-sphere bed); the error names the lowest body index that fails, as a serial scan would.
  Status check_impacts() const;
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
  bool timing_on(double /*dt*/) const;
  double predictor_gain(double dt) const;
  double max_dt() const;

  // ---- contact stage, pair pass: each pair is computed once, by its owner's entry, and added
  // to both spheres' sums (acc; read by gather_sphere4 in the body stage), slab by slab
  void contacts(float dt);

  // ---- sphere stage (called by the body stage for each sphere of a body): sphere i takes the
  // pair pass's sums (and zeroes them) and adds the boundaries; returns the sphere's force and
  // torque (the body stage sums them straight into the body: the particle fields force/torque
  // are the GL backend's).
  struct LawConstants {
    float kn, cn0, kt, ctr, mu;  // N/m, c_n = cn0 / sqrt(1/m_i + 1/m_j), N/m, c_t/c_n, -
  } law{};
  // What gather_sphere4 reads, copied to a local of the body stage once per substep: held in
  // members, these were loaded again after every float store (the compiler cannot tell a
  // store to a force from one to a member), ~20 instructions per sphere-step.
  struct GatherCtx {
    LawConstants law;
    const float *P, *V, *W;
    float* ACC;
    float* WX;
    std::uint32_t* WM;
    float* WD;   // wall_dmax (6 per sphere)
    float kn2;   // N/m, unloading stiffness of the hysteretic normal spring (= law.kn: linear)
    physics::Boundaries bounds;
    float floor_y;
    bool first_law;
    // A sphere with x0 + r <= x <= x1 - r, z0 + r <= z <= z1 - r and y >= floor_y + r touches
    // no boundary (m): the side walls' or the fill rectangle's sides (the terrain), +-inf
    // without either; boundary_contacts is only called for the others.
    float x0, x1, z0, z1;
  };
  GatherCtx gather_ctx() const;
  // Sphere i's force F4 and torque T4 about its centre (lane 3 = 0); returns its centre (lane 3 = 0).
  __m128 gather_sphere4(const GatherCtx& g, const int i, const float dt, std::int64_t& nwall, __m128& F4,
                        __m128& T4);
  // Boundaries of sphere i (dynamic): the planes of physics::boundary_plane (floor, side walls,
  // the terrain outside the fill and the fill's sides; shaders/dem/physics_common.glsl, shared
  // with the GL force kernel) in slot order; adds their force and torque (about the sphere
  // centre) to F, T. WM[i] has bit k set while plane k touched the sphere at the last substep;
  // a plane contact that was not in the mask starts with a fresh spring. Out of line: 4 % of
  // sphere-steps reach it in a bed. `slots`: bit k for each plane the sphere may touch (the
  // floor when within r of it, a side when within r of it, the terrain outside the fill when
  // within r of a side: gather_sphere4); the others cannot, and are not tested.
  void boundary_contacts(const GatherCtx& g, const int i, const float dt, std::uint32_t slots, Vec3& F, Vec3& T,
                         std::int64_t& nwall);

  // The body stage for granule i (dynamic, isotropic inertia): the formulas of the general
  // path below in 4-wide SSE2 registers, each lane doing the scalar code's float operations in
  // its order (the same results bit for bit, ~1/3 fewer instructions).
  void granule_update(const GatherCtx& gctx, const int i, const float dt, std::int64_t& nwall, float& d2max,
                      float& vmax, int& bad);

  // Adds the forces of body i's spheres [k0, k1) to F and their torques about its centre to T
  // (SSE2, lane 3 = 0; the float operations of the Vec3 sum in its order).
  void sum_spheres(const GatherCtx& gctx, const int i, const int k0, const int k1, const float dt, std::int64_t& nwall,
                   __m128& F, __m128& T);
  // A shell's step from its spheres' force F and torque T (about its centre): stores them,
  // integrates a dynamic one (symplectic Euler, the body-frame Euler equations) and moves a
  // kinematic one; counts a non-finite state in `bad`. Returns the velocity the spheres are
  // rebuilt with (the predictor below) and the angular velocity in *w.
  Vec3 integrate_shell(int i, Vec3 F, Vec3 T, float dt, Vec3* w, int& bad);

  // ---- body stage: gather each sphere (gather_sphere4), sum the spheres' forces in id order,
  // integrate, rebuild the spheres
  // The largest squared displacement (m^2) of a granule's sphere since the sort into
  // *d2max_out, of a shell's since the shell list's build into *d2shell_out.
  bool bodies(float dt, float* d2max_out, float* d2shell_out);

  // The substep's stages, each timed into stats (StepStats::*_seconds).
  Status substep(float dt);

  double max_granule_speed() const;

  // Asleep: move the kinematic bodies; true if one of their spheres would touch a dynamic one.
  bool kinematic_touch(double dt);

  void move_kinematic(double dt);

  // Appends a body and its spheres; the caller has checked the capacities.
  int push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm, Vec3 inv_inertia,
                const Vec3* offsets, const float* radii, int count, bool one_radius);
};

}  // namespace sandpatch
