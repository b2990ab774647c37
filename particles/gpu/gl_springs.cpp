// Contact springs read and set from outside on the GL backend (dem.hpp ContactSpring, as
// particles/dem_springs.cpp on the CPU): the tangential springs (m) and largest overlaps (m) of
// touching granule contacts, by granule and sphere, so a bed rebuilt from positions keeps the
// forces that held it at rest. The GL keeps the history by particle id (shaders/dem/common.glsl):
// per sphere a count and K slots of (xi bits, partner id) with their dmax, double-buffered (the
// next substep reads buffer kS0 + cur_s), every pair held by both its spheres (xi from each one's
// side: the two are exact negatives); per sphere a plane mask and 6 plane springs (xyz xi, w
// dmax). A slot present, or a mask bit set, is a contact that touched at the last substep (no
// first-substep dashpot). gl_impl.hpp.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "particles/dem_control.hpp"
#include "particles/gpu/gl_impl.hpp"

namespace sandpatch::gpu {

namespace {
// Sorted ids split into runs [first, last] whose gaps are at most kRunGap ids: each run is
// read back and written whole (a few writes instead of one per sphere).
constexpr std::int32_t kRunGap = 64;
template <class Ids>
std::vector<std::pair<std::int32_t, std::int32_t>> runs_of(const Ids& sorted_ids) {
  std::vector<std::pair<std::int32_t, std::int32_t>> runs;
  for (std::int32_t id : sorted_ids) {
    if (runs.empty() || id > runs.back().second + kRunGap) runs.push_back({id, id});
    else runs.back().second = id;
  }
  return runs;
}
std::uint64_t pair_key(std::int32_t lo, std::int32_t hi) {
  return (std::uint64_t(std::uint32_t(lo)) << 32) | std::uint32_t(hi);
}
}  // namespace

std::vector<ContactSpring> GlSimulation::contact_springs() const {
  const Impl& s = *impl_;
  const int n = s.np_gpu;  // staged spheres have no contacts yet
  std::vector<ContactSpring> out;
  if (n == 0) return out;
  const std::size_t K = std::size_t(s.K), N = std::size_t(n);
  // particle id -> body and sphere (ids are given body by body, in body order)
  std::vector<std::int32_t> body(N), sphere(N);
  for (int b = 0, id = 0; b < s.nb_gpu && id < n; ++b)
    for (int k = 0; k < s.host_count[std::size_t(b)] && id < n; ++k, ++id) body[std::size_t(id)] = b, sphere[std::size_t(id)] = k;
  auto granule = [&](std::int32_t id) {
    return (s.host_flags[std::size_t(body[std::size_t(id)])] & (kBodyGranule | kBodyParked)) == kBodyGranule;
  };
  const Impl::Buf springs = Impl::Buf(Impl::kS0 + s.cur_s);  // as the next substep reads them
  std::vector<std::uint32_t> count(N), slot(N * K * 4);
  std::vector<float> dmax(N * K);
  s.read(springs, 0, N * 4, count.data());
  s.read(springs, s.springs_head(), slot.size() * 4, slot.data());
  s.read(springs, s.springs_dmax(), dmax.size() * 4, dmax.data());
  auto holds = [&](std::size_t id, std::uint32_t partner) {
    for (std::size_t k = 0; k < count[id]; ++k)
      if (slot[(id * K + k) * 4 + 3] == partner) return true;
    return false;
  };
  for (std::size_t id = 0; id < N; ++id) {
    if (count[id] == 0 || !granule(std::int32_t(id))) continue;
    for (std::size_t k = 0; k < std::min<std::size_t>(count[id], K); ++k) {
      const std::uint32_t* sl = &slot[(id * K + k) * 4];
      const std::uint32_t j = sl[3];
      if (j >= N || !granule(std::int32_t(j))) continue;
      if (j < id && holds(j, std::uint32_t(id))) continue;  // given from the lower id's side
      ContactSpring c;
      c.a = BodyId{body[id]}, c.sphere_a = sphere[id];
      c.b = BodyId{body[j]}, c.sphere_b = sphere[j];
      std::memcpy(&c.xi.x, &sl[0], 4);
      std::memcpy(&c.xi.y, &sl[1], 4);
      std::memcpy(&c.xi.z, &sl[2], 4);
      c.dmax = dmax[id * K + k];
      out.push_back(c);
    }
  }
  std::vector<std::uint32_t> mask(N);
  std::vector<float> wxi(N * kWallSlots * 4);
  s.read(Impl::kW, 0, N * 4, mask.data());
  s.read(Impl::kW, s.springs_head(), wxi.size() * 4, wxi.data());
  for (std::size_t id = 0; id < N; ++id) {
    if (!mask[id] || !granule(std::int32_t(id))) continue;
    for (int k = 0; k < kWallSlots; ++k) {
      if (!(mask[id] & (1u << k))) continue;
      const float* x = &wxi[(id * kWallSlots + std::size_t(k)) * 4];
      ContactSpring c;
      c.a = BodyId{body[id]}, c.sphere_a = sphere[id];
      c.plane = k;
      c.xi = {x[0], x[1], x[2]};
      c.dmax = x[3];
      out.push_back(c);
    }
  }
  return out;
}

Status GlSimulation::set_contact_springs(const std::vector<ContactSpring>& springs) {
  Impl& s = *impl_;
  // Checked whole before anything is set (dem_control.hpp, as the CPU backend).
  if (Status st = check_contact_springs(
          springs, s.nb, [&](int b) { return s.host_flags[std::size_t(b)]; }, [&](int b) { return s.host_count[std::size_t(b)]; });
      !st)
    return st;
  // every body's first particle id (ids are given body by body, in body order)
  std::vector<std::int32_t> first(std::size_t(s.nb) + 1, 0);
  for (int b = 0; b < s.nb; ++b) first[std::size_t(b) + 1] = first[std::size_t(b)] + s.host_count[std::size_t(b)];
  // the pairs of this call, the spring as the lower id's (a later entry of one pair wins)
  std::map<std::uint64_t, Impl::SetSpring> pairs;
  for (const ContactSpring& c : springs) {
    if (c.plane >= 0) continue;
    const std::int32_t ia = first[std::size_t(c.a.index)] + c.sphere_a, ib = first[std::size_t(c.b.index)] + c.sphere_b;
    const float sgn = ia < ib ? 1.0f : -1.0f;
    pairs[ia < ib ? pair_key(ia, ib) : pair_key(ib, ia)] = {{sgn * c.xi.x, sgn * c.xi.y, sgn * c.xi.z}, c.dmax};
  }
  // each sphere holds its pairs in K slots: more set on one sphere cannot be kept
  std::map<std::int32_t, int> per_sphere;
  for (const auto& [key, sp] : pairs) {
    for (std::int32_t id : {std::int32_t(key >> 32), std::int32_t(key & 0xffffffffu)})
      if (++per_sphere[id] > s.K)
        return Error{"", "GlOptions.max_contacts_per_sphere", std::to_string(s.K),
                     "is fewer than the pairs set_contact_springs gives particle " + std::to_string(id) +
                         ": raise max_contacts_per_sphere",
                     "each sphere keeps its pairs' springs in that many slots"};
  }
  for (const auto& [key, sp] : pairs) s.set_pairs[key] = sp;
  for (const ContactSpring& c : springs)
    if (c.plane >= 0)
      s.set_planes[std::int64_t(first[std::size_t(c.a.index)] + c.sphere_a) * kWallSlots + c.plane] = {
          {c.xi.x, c.xi.y, c.xi.z}, c.dmax};
  return Ok{};
}

// The waiting springs whose spheres are uploaded, into the history the next substep reads
// (buffer kS0 + cur_s and the wall block): per run of particle ids, the counts, slots and dmax
// (masks and plane springs) are read back, the set springs written over the slots of the same
// partner (planes) or added, and the run written back through write() (the staging buffer and
// copy_words.comp). A sphere's other slots stay while its K slots have room. The first
// read-back waits for the GPU: a step that takes springs pays that wait once.
void GlSimulation::Impl::take_set_springs() {
  struct Entry {
    std::uint32_t partner;
    SetSpring sp;  // from this sphere's side
  };
  std::map<std::int32_t, std::vector<Entry>> per;
  for (auto it = set_pairs.begin(); it != set_pairs.end();) {
    const std::int32_t lo = std::int32_t(it->first >> 32), hi = std::int32_t(it->first & 0xffffffffu);
    if (hi >= np_gpu) {  // a sphere still staged: a later step takes it
      ++it;
      continue;
    }
    const SetSpring& sp = it->second;
    per[lo].push_back({std::uint32_t(hi), sp});
    per[hi].push_back({std::uint32_t(lo), {{-sp.xi[0], -sp.xi[1], -sp.xi[2]}, sp.dmax}});
    it = set_pairs.erase(it);
  }
  const std::size_t Ks = std::size_t(K);
  const Buf springs = Buf(kS0 + cur_s);
  std::vector<std::int32_t> ids;
  for (const auto& e : per) ids.push_back(e.first);
  for (const auto& [a, b] : runs_of(ids)) {
    const std::size_t n = std::size_t(b - a + 1), a0 = std::size_t(a);
    std::vector<std::uint32_t> count(n), slot(n * Ks * 4);
    std::vector<float> dmax(n * Ks);
    read(springs, 4 * a0, n * 4, count.data());
    read(springs, springs_head() + 16 * a0 * Ks, slot.size() * 4, slot.data());
    read(springs, springs_dmax() + 4 * a0 * Ks, dmax.size() * 4, dmax.data());
    for (auto it = per.lower_bound(a); it != per.end() && it->first <= b; ++it) {
      const std::size_t r = std::size_t(it->first - a);
      std::uint32_t* sl = &slot[r * Ks * 4];
      float* dm = &dmax[r * Ks];
      // the set springs first, then the old slots of other partners while there is room
      std::vector<std::uint32_t> keep;
      std::vector<float> keep_dm;
      for (std::size_t k = 0; k < std::min<std::size_t>(count[r], Ks); ++k) {
        bool set = false;
        for (const Entry& e : it->second) set = set || e.partner == sl[4 * k + 3];
        if (set) continue;
        keep.insert(keep.end(), sl + 4 * k, sl + 4 * k + 4);
        keep_dm.push_back(dm[k]);
      }
      std::size_t m = 0;
      for (const Entry& e : it->second) {
        if (m == Ks) break;
        std::memcpy(&sl[4 * m], e.sp.xi, 12);
        sl[4 * m + 3] = e.partner;
        dm[m++] = e.sp.dmax;
      }
      for (std::size_t k = 0; k < keep_dm.size() && m < Ks; ++k, ++m) {
        std::memcpy(&sl[4 * m], &keep[4 * k], 16);
        dm[m] = keep_dm[k];
      }
      count[r] = std::uint32_t(m);
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(springs, 4 * a0, n * 4, count.data());
    write(springs, springs_head() + 16 * a0 * Ks, slot.size() * 4, slot.data());
    write(springs, springs_dmax() + 4 * a0 * Ks, dmax.size() * 4, dmax.data());
  }

  // planes: the mask bit set (touched) and the spring written
  std::vector<std::int32_t> pids;
  for (const auto& [key, sp] : set_planes)
    if (key / kWallSlots < np_gpu && (pids.empty() || pids.back() != std::int32_t(key / kWallSlots)))
      pids.push_back(std::int32_t(key / kWallSlots));
  for (const auto& [a, b] : runs_of(pids)) {
    const std::size_t n = std::size_t(b - a + 1), a0 = std::size_t(a);
    std::vector<std::uint32_t> mask(n);
    std::vector<float> wxi(n * kWallSlots * 4);
    read(kW, 4 * a0, n * 4, mask.data());
    read(kW, springs_head() + 16 * a0 * kWallSlots, wxi.size() * 4, wxi.data());
    const auto end = set_planes.lower_bound(std::int64_t(b + 1) * kWallSlots);
    for (auto it = set_planes.lower_bound(std::int64_t(a) * kWallSlots); it != end; it = set_planes.erase(it)) {
      const std::size_t r = std::size_t(it->first / kWallSlots - a);
      const int k = int(it->first % kWallSlots);
      mask[r] |= 1u << k;
      float* x = &wxi[(r * kWallSlots + std::size_t(k)) * 4];
      x[0] = it->second.xi[0], x[1] = it->second.xi[1], x[2] = it->second.xi[2], x[3] = it->second.dmax;
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kW, 4 * a0, n * 4, mask.data());
    write(kW, springs_head() + 16 * a0 * kWallSlots, wxi.size() * 4, wxi.data());
  }
}

}  // namespace sandpatch::gpu
