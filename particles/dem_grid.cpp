// Granule DEM, CPU backend: the cell grid (cell = 2 r_max + skin), the counting sort of the
// spheres by cell and the Verlet neighbour list with its contact history carried over by
// partner id (dem.hpp steps 2; dem_impl.hpp).
#include "particles/dem_impl.hpp"
#include "particles/grid_simd.hpp"

#include <algorithm>
#include <cassert>
#include <cstring>
#include <limits>
#include <type_traits>

namespace sandpatch {

// ---- setup
void Simulation::Impl::size_grid() {
  h = 2.0f * r_max + skin;
  inv_h = 1.0f / h;
  Vec3 ext = def.bounds_max - def.bounds_min;
  gx = std::max(1, int(std::ceil(ext.x * inv_h)));
  gy = std::max(1, int(std::ceil(ext.y * inv_h)));
  gz = std::max(1, int(std::ceil(ext.z * inv_h)));
  cell_start.assign(std::size_t(gx) * gy * gz + 1, 0);
  need_sort = true;
}

// Counting sort of the particles by cell (stable, serial: deterministic), permuting every
// particle field, then the neighbour list is rebuilt and the springs carried over.
void Simulation::Impl::sort() {
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
  // The np live spheres' values only (the arrays hold the slot's capacity, twice the spheres of
  // a typical patch), through one scratch buffer kept between sorts (no allocation). Every
  // particle field is 4-byte values (fields.hpp).
  auto permute = [&](auto& arr, int n) {
    using T = typename std::decay_t<decltype(arr)>::value_type;
    static_assert(sizeof(T) == sizeof(std::uint32_t));
    const std::size_t values = std::size_t(np) * n;
    if (sort_scratch.size() < values) sort_scratch.resize(values);
    std::memcpy(sort_scratch.data(), arr.data(), values * sizeof(T));
    const std::uint32_t* src = sort_scratch.data();
    for (int s = 0; s < np; ++s)
      std::memcpy(&arr[std::size_t(dest[s]) * n], src + std::size_t(s) * n, std::size_t(n) * sizeof(T));
  };
#define SP_PERMUTE(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(CPU, backend, permute(p.name, n);)
  SANDPATCH_PARTICLE_FIELDS(SP_PERMUTE)
  SANDPATCH_SPHERE_CONTACT_FIELDS(SP_PERMUTE)
#undef SP_PERMUTE
  cell.resize(np);
  for (int s = 0; s < np; ++s) cell[dest[s]] = c[s];
  for (int s = 0; s < np; ++s) slot_of[p.id[s]] = s;
  std::copy(p.pos.begin(), p.pos.begin() + 4 * std::size_t(np), pos_at_sort.begin());
  {
    std::vector<std::uint8_t> seen(nb, 0);
    // the wide shells apart (`bodies` steps them in chunks), in body index order
    wide_chunks.clear();
    wide_bodies.clear();
    for (int i = 0; i < nb; ++i) {
      if ((b.flags[i] & kBodyGranule) || b.count[i] <= kWideShell) continue;
      seen[i] = 1;
      const int w = int(wide_bodies.size()), c0 = int(wide_chunks.size());
      for (int k0 = 0; k0 < b.count[i]; k0 += kWideChunk)
        wide_chunks.push_back({i, k0, std::min(k0 + kWideChunk, b.count[i]), w});
      wide_bodies.push_back({i, c0, int(wide_chunks.size())});
    }
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
  ++work_epoch;
  if (!set_pairs.empty() || !set_planes.empty()) take_set_springs();
  build_shell_list();
}

// The shell list (dem_impl.hpp): rows in stable id order, each row's granules in the grid's
// order (cells by z, y, x, then sorted index), then the spheres of later shells in id order.
// Serial: a car's ~1,700 shell spheres, most far from the sand, against ~6,000 granules.
void Simulation::Impl::build_shell_list() {
  std::vector<std::int32_t> ostart, orow_id, onbr_id;
  PairArrays old;
  ostart.swap(sstart);
  orow_id.swap(srow_id);
  onbr_id.swap(snbr_id);
  old.swap(spairs);
  srow.clear();
  snbr.clear();
  sstart.assign(1, 0);
  need_shell_list = false;
  const std::uint32_t* FL = b.flags.data();
  auto is_shell = [&](int body) { return !(FL[body] & (kBodyGranule | kBodyParked)); };
  // the granules' extent (m): their centres now (their spheres lie within granule_reach of them)
  Vec3 lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
          std::numeric_limits<float>::infinity()};
  Vec3 hi{-lo.x, -lo.y, -lo.z};
  bool shells = false;
  for (int i = 0; i < nb; ++i) {
    if (is_shell(i)) shells = true;
    if ((FL[i] & (kBodyGranule | kBodyParked)) != kBodyGranule) continue;
    const Vec3 x = ld3(b.pos, i);
    lo = Vec3{std::min(lo.x, x.x), std::min(lo.y, x.y), std::min(lo.z, x.z)};
    hi = Vec3{std::max(hi.x, x.x), std::max(hi.y, x.y), std::max(hi.z, x.z)};
  }
  if (!shells) return;
  const float granule_reach = shape.centre_distance + shape.radius;  // m, a granule's spheres from its centre
  const float* P = p.pos.data();
  const std::int32_t* BODY = p.body.data();
  const std::int32_t* GROUP = b.group.data();
  // A granule's cell is the one it had at the sort, and it has moved less than skin/2 since.
  const float drift = 0.5f * skin;
  auto old_entry = [&](int orow, int partner_id) {
    if (orow < 0) return -1;
    for (int k = ostart[std::size_t(orow)]; k < ostart[std::size_t(orow) + 1]; ++k)
      if (onbr_id[std::size_t(k)] == partner_id) return k;
    return -1;
  };
  for (int a = 0; a < nb; ++a) {
    if (!is_shell(a)) continue;
    const bool dyn_a = FL[a] & kBodyDynamic;
    const std::int32_t ga = GROUP[a];
    // the later shells it may meet: bounding spheres about the COM, skin included
    const Vec3 xa = ld3(b.pos, a);
    const float ra = guard_arm[a] + r_max;
    std::vector<int> near_bodies;
    for (int c = a + 1; c < nb; ++c) {
      if (!is_shell(c) || !physics::spheres_interact(a, ga, c, GROUP[c])) continue;
      if (!dyn_a && !(FL[c] & kBodyDynamic)) continue;
      const float reach = ra + guard_arm[c] + r_max + shell_skin;
      const Vec3 d = xa - ld3(b.pos, c);
      if (dot(d, d) < reach * reach) near_bodies.push_back(c);
    }
    for (int k = 0, first = b.first[a]; k < b.count[a]; ++k) {
      const int id = first + k, i = slot_of[id];
      const Vec3 xi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
      const float ri = P[4 * i + 3];
      srow_id.push_back(id);
      srow.push_back(i);
      st3(pos_at_sort, std::size_t(i), xi);  // (the trip is measured from here)
      // the granules: every grid cell within reach of the sphere
      const float reach = ri + r_max + shell_skin + drift;
      if (xi.x + reach >= lo.x - granule_reach && xi.x - reach <= hi.x + granule_reach &&
          xi.y + reach >= lo.y - granule_reach && xi.y - reach <= hi.y + granule_reach &&
          xi.z + reach >= lo.z - granule_reach && xi.z - reach <= hi.z + granule_reach) {
        const int x0 = cell_coord(xi.x - reach, def.bounds_min.x, gx), x1 = cell_coord(xi.x + reach, def.bounds_min.x, gx);
        const int y0 = cell_coord(xi.y - reach, def.bounds_min.y, gy), y1 = cell_coord(xi.y + reach, def.bounds_min.y, gy);
        const int z0 = cell_coord(xi.z - reach, def.bounds_min.z, gz), z1 = cell_coord(xi.z + reach, def.bounds_min.z, gz);
        for (int cz = z0; cz <= z1; ++cz)
          for (int cy = y0; cy <= y1; ++cy) {
            const int row0 = (cz * gy + cy) * gx;
            for (int j = cell_start[std::size_t(row0 + x0)], j1 = cell_start[std::size_t(row0 + x1 + 1)]; j < j1; ++j) {
              const int bj = BODY[j];
              if ((FL[bj] & (kBodyGranule | kBodyParked)) != kBodyGranule) continue;
              if (!physics::spheres_interact(a, ga, bj, GROUP[bj])) continue;
              const float dx = xi.x - P[4 * j], dy = xi.y - P[4 * j + 1], dz = xi.z - P[4 * j + 2];
              const float rs = ri + P[4 * j + 3] + shell_skin;
              if (dx * dx + dy * dy + dz * dz >= rs * rs) continue;
              snbr.push_back(j);
              snbr_id.push_back(p.id[j]);
            }
          }
      }
      // the spheres of the later shells
      for (const int c : near_bodies)
        for (int kc = 0, fc = b.first[c]; kc < b.count[c]; ++kc) {
          const int j = slot_of[fc + kc];
          const float dx = xi.x - P[4 * j], dy = xi.y - P[4 * j + 1], dz = xi.z - P[4 * j + 2];
          const float rs = ri + P[4 * j + 3] + shell_skin;
          if (dx * dx + dy * dy + dz * dz >= rs * rs) continue;
          snbr.push_back(j);
          snbr_id.push_back(fc + kc);
        }
      sstart.push_back(std::int32_t(snbr.size()));
    }
  }
  // the springs, carried over by (row id, partner id)
  spairs.assign(snbr.size());
  if (ostart.empty()) return;
  // (the old rows are in id order: a binary search)
  for (int r = 0, rows = int(srow_id.size()); r < rows; ++r) {
    const auto it = std::lower_bound(orow_id.begin(), orow_id.end(), srow_id[std::size_t(r)]);
    const int orow = it != orow_id.end() && *it == srow_id[std::size_t(r)] ? int(it - orow_id.begin()) : -1;
    if (orow < 0) continue;
    for (int e = sstart[std::size_t(r)]; e < sstart[std::size_t(r) + 1]; ++e) {
      const int k = old_entry(orow, snbr_id[std::size_t(e)]);
      if (k < 0) continue;
      spairs.xi[3 * std::size_t(e)] = old.xi[3 * std::size_t(k)];
      spairs.xi[3 * std::size_t(e) + 1] = old.xi[3 * std::size_t(k) + 1];
      spairs.xi[3 * std::size_t(e) + 2] = old.xi[3 * std::size_t(k) + 2];
      spairs.touch[std::size_t(e)] = old.touch[std::size_t(k)];
      spairs.dmax[std::size_t(e)] = old.dmax[std::size_t(k)];
    }
  }
}

// Visits the spheres j > i (sorted order) of other bodies (not of i's collision group,
// physics_common.glsl spheres_interact) within r_i + r_j + skin of sphere
// i, in a fixed order (the rows below, then sorted index): each pair of the grid is met once,
// from its lower sorted index. The cells after i's own in the grid's (z, y, x) order that
// can hold a partner are i's own cell and the next in its row, the row above (y + 1) and the
// nine rows of the layer above (z + 1): five runs of contiguous sorted indices (three cells
// in x are adjacent in the sort), half the 27-cell search of both sides.
template <class F>
void Simulation::Impl::for_forward(int i, F&& f) const {
  // (locals: f may store through pointers the compiler cannot tell from these, which made it
  // load the skin and the arrays' addresses again for every candidate)
  const float* P = p.pos.data();
  const float* V = p.vel.data();
  const std::int32_t* BODY = p.body.data();
  const std::int32_t* GROUP = b.group.data();
  const std::uint32_t* FLAGS = b.flags.data();
  const std::int32_t* CS = cell_start.data();
  const float sk = skin;
  const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
  const float ri = P[4 * i + 3];
  const std::int32_t bi = BODY[i];
  const std::int32_t gi = GROUP[bi];
  const bool dyn_i = V[4 * i + 3] > 0.0f;
  const int c = cell[i];
  const int cx = c % gx, cy = (c / gx) % gy, cz = c / (gx * gy);
  const int x0 = cx > 0 ? cx - 1 : 0, x1 = cx < gx - 1 ? cx + 1 : gx - 1;
  // the five runs of sorted indices
  std::int32_t runs[5][2];
  int nruns = 0, total = 0;
  auto add_run = [&](int j0, int j1) {
    if (j1 <= j0) return;
    runs[nruns][0] = j0, runs[nruns][1] = j1;
    ++nruns, total += j1 - j0;
  };
  const int row0 = (cz * gy + cy) * gx;
  add_run(i + 1, CS[row0 + x1 + 1]);  // the rest of i's cell and the next one in x
  if (cy < gy - 1) {
    const int row = row0 + gx;
    add_run(CS[row + x0], CS[row + x1 + 1]);
  }
  if (cz < gz - 1)
    for (int yy = (cy > 0 ? cy - 1 : 0); yy <= (cy < gy - 1 ? cy + 1 : gy - 1); ++yy) {
      const int row = ((cz + 1) * gy + yy) * gx;
      add_run(CS[row + x0], CS[row + x1 + 1]);
    }
  // what a near candidate must also be: of another body (not of i's collision group,
  // physics_common.glsl spheres_interact), and one of the two moved by forces
  auto keep = [&](int j) __attribute__((always_inline)) {
    const std::int32_t bj = BODY[j];
    if (!(FLAGS[bj] & kBodyGranule)) return;                          // a shell's: the shell list
    if (!physics::spheres_interact(bi, gi, bj, GROUP[bj])) return;  // same body or group
    if (!dyn_i && V[4 * j + 3] == 0.0f) return;                      // neither moves under forces
    f(j);
  };
#ifdef SANDPATCH_AVX2_KERNEL
  if (simd_pairs) {
    // the distance test 8 candidates at a time (grid_simd.hpp: the same candidates, in order)
    thread_local std::vector<std::int32_t> near;
    if (int(near.size()) < total) near.resize(std::size_t(total));
    const int n = simd::near_spheres_avx2(P, int(p.pos.size() / 4), simd::SearchSphere{pi.x, pi.y, pi.z, ri, sk}, runs,
                                          nruns, near.data());
    for (int k = 0; k < n; ++k) keep(near[std::size_t(k)]);
    return;
  }
#endif
  for (int k = 0; k < nruns; ++k)
    for (int j = runs[k][0], j1 = runs[k][1]; j < j1; ++j) {
      const float dx = pi.x - P[4 * j], dy = pi.y - P[4 * j + 1], dz = pi.z - P[4 * j + 2];
      const float rs = ri + P[4 * j + 3] + sk;
      if (dx * dx + dy * dy + dz * dz >= rs * rs) continue;
      keep(j);
    }
}

// Rebuilds the CSR neighbour list and carries each pair's spring over from the old list. One
// half search (for_forward) per sphere: blocks of kListBlock spheres in parallel, each block's
// partners gathered in sphere order into its own buffer (list_blocks, kept between rebuilds),
// then the counts' prefix sum and a parallel copy into the CSR arrays with the carry-over.
// The pair's owner is its lower sorted index, so it may change at a re-sort: the spring is
// then found in the partner's old list and turned round (xi is along the owner's normal and
// relative velocity, both of which change sign with the side).
void Simulation::Impl::build_list(const std::vector<std::int32_t>& old_slot) {
  std::vector<std::int32_t> ostart, onbr_id;
  PairArrays old;
  ostart.swap(nstart);
  onbr_id.swap(nbr_id);
  old.swap(pairs);
  const int n = np;
  const int old_np = ostart.empty() ? 0 : int(ostart.size()) - 1;
  nstart.assign(n + 1, 0);
  const int blocks = (n + kListBlock - 1) / kListBlock;
  if (int(list_blocks.size()) < blocks) list_blocks.resize(std::size_t(blocks));
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (n > kParallelSpheres)
  for (int blk = 0; blk < blocks; ++blk) {
    std::vector<std::int32_t>& found = list_blocks[std::size_t(blk)];
    found.clear();
    for (int i = blk * kListBlock, i1 = std::min(n, i + kListBlock); i < i1; ++i) {
      // a parked body waits apart, in contact with nothing (dem_control.hpp)
      // (and a shell's pairs are in the shell list)
      if ((b.flags[p.body[i]] & (kBodyGranule | kBodyParked)) != kBodyGranule) continue;
      const std::size_t before = found.size();
      for_forward(i, [&](int j) { found.push_back(j); });
      nstart[i + 1] = std::int32_t(found.size() - before);
    }
  }
  for (int i = 0; i < n; ++i) nstart[i + 1] += nstart[i];
  nbr.resize(nstart[n]);
  nbr_id.resize(nstart[n]);
  pairs.assign(std::size_t(nstart[n]));
  const bool indexed = !set_pairs.empty();
  if (indexed) index_set_pairs(n);
  // the old entry of the pair (owner's old slot oi, partner id), or -1
  auto old_entry = [&](int oi, int partner_id) {
    if (oi < 0 || oi >= old_np) return -1;
    for (int k = ostart[oi]; k < ostart[oi + 1]; ++k)
      if (onbr_id[k] == partner_id) return k;
    return -1;
  };
#pragma omp parallel for num_threads(threads) schedule(dynamic, 1) if (n > kParallelSpheres)
  for (int blk = 0; blk < blocks; ++blk) {
    const std::int32_t* found = list_blocks[std::size_t(blk)].data();
    for (int i = blk * kListBlock, i1 = std::min(n, i + kListBlock); i < i1; ++i) {
      const int id = p.id[i];
      const int oi = id < int(old_slot.size()) ? old_slot[id] : -1;
      for (int e = nstart[i]; e < nstart[i + 1]; ++e) {
        const int j = *found++;
        const int jd = p.id[j];
        nbr[e] = j;
        nbr_id[e] = jd;
        if (indexed) {  // a spring set from outside (set_contact_springs) wins
          if (const SetSpring* sp = id < jd ? set_pair(id, jd) : set_pair(jd, id)) {
            const float sgn = id < jd ? 1.0f : -1.0f;  // (kept as the lower id's)
            for (int c = 0; c < 3; ++c) pairs.xi[3 * e + c] = sgn * sp->xi[c];
            pairs.touch[e] = 1;
            pairs.dmax[e] = sp->dmax;
            continue;
          }
        }
        if (old_np == 0) continue;
        const int oj = jd < int(old_slot.size()) ? old_slot[jd] : -1;
        // the old owner: the lower old sorted index
        const bool same_side = oi >= 0 && (oj < 0 || oi < oj);
        const int k = same_side ? old_entry(oi, jd) : old_entry(oj, id);
        if (k < 0) continue;
        const float sgn = same_side ? 1.0f : -1.0f;
        pairs.xi[3 * e] = sgn * old.xi[3 * k];
        pairs.xi[3 * e + 1] = sgn * old.xi[3 * k + 1];
        pairs.xi[3 * e + 2] = sgn * old.xi[3 * k + 2];
        pairs.touch[e] = old.touch[k];
        pairs.dmax[e] = old.dmax[k];  // (a largest overlap: the same from either side)
      }
    }
  }
}

// Asleep: move the kinematic bodies; true if one of their spheres would touch a dynamic one.
bool Simulation::Impl::kinematic_touch(double dt) {
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
              const int bj = p.body[j];
              if (!physics::spheres_interact(i, b.group[i], bj, b.group[bj])) continue;  // jointed to it
              Vec3 d = xs - ld3(p.pos, j);
              float rs = r + p.pos[4 * j + 3] + 0.5f * skin;
              if (dot(d, d) < rs * rs) return true;
            }
          }
    }
  }
  return false;
}

}  // namespace sandpatch
