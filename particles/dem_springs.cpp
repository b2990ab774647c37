// Contact springs read and set from outside (dem.hpp ContactSpring; docs/dem.md "Carried
// springs"): the tangential springs and largest overlaps of touching granule contacts, by
// granule and sphere, so a bed rebuilt in another simulation from its positions keeps the
// forces that held it at rest.
#include <algorithm>
#include <cmath>
#include <string>

#include "particles/dem.hpp"
#include "particles/dem_control.hpp"
#include "particles/dem_impl.hpp"

namespace sandpatch {

std::vector<ContactSpring> Simulation::contact_springs() const {
  const Impl& s = *impl_;
  std::vector<ContactSpring> out;
  const std::uint32_t* F = s.b.flags.data();
  auto granule = [&](int i) { return (F[s.p.body[i]] & (kBodyGranule | kBodyParked)) == kBodyGranule; };
  auto sphere_of = [&](int i) { return s.p.id[i] - s.b.first[s.p.body[i]]; };
  // (spheres added since the last sort are at its end, in no list yet)
  const int listed = s.nstart.empty() ? 0 : std::min(s.np, int(s.nstart.size()) - 1);
  for (int i = 0; i < listed; ++i) {
    if (!granule(i)) continue;
    for (int e = s.nstart[i]; e < s.nstart[i + 1]; ++e) {
      const int j = s.nbr[e];
      if (!s.pairs.touch[e] || !granule(j)) continue;
      ContactSpring c;
      c.a = BodyId{s.p.body[i]}, c.sphere_a = sphere_of(i);
      c.b = BodyId{s.p.body[j]}, c.sphere_b = sphere_of(j);
      c.xi = {s.pairs.xi[3 * e], s.pairs.xi[3 * e + 1], s.pairs.xi[3 * e + 2]};
      c.dmax = s.pairs.dmax[e];
      out.push_back(c);
    }
  }
  for (int i = 0; i < s.np; ++i) {
    if (!granule(i) || !s.p.wall_mask[i]) continue;
    for (int k = 0; k < kWallSlots; ++k) {
      if (!(s.p.wall_mask[i] & (1u << k))) continue;
      const float* x = &s.p.wall_xi[(std::size_t(i) * kWallSlots + k) * 3];
      ContactSpring c;
      c.a = BodyId{s.p.body[i]}, c.sphere_a = sphere_of(i);
      c.plane = k;
      c.xi = {x[0], x[1], x[2]};
      c.dmax = s.p.wall_dmax[std::size_t(i) * kWallSlots + k];
      out.push_back(c);
    }
  }
  return out;
}

Status Simulation::set_contact_springs(const std::vector<ContactSpring>& springs) {
  Impl& s = *impl_;
  // Checked whole before anything is set (dem_control.hpp, as the GL backend).
  if (Status st = check_contact_springs(springs, s.nb, [&](int b) { return s.b.flags[b]; }, [&](int b) { return s.b.count[b]; }); !st)
    return st;
  for (const ContactSpring& c : springs) {
    const std::int32_t ia = s.b.first[c.a.index] + c.sphere_a;
    if (c.plane >= 0) {
      s.set_planes.push_back({std::int64_t(ia) * kWallSlots + c.plane, {{c.xi.x, c.xi.y, c.xi.z}, c.dmax}});
      continue;
    }
    const std::int32_t ib = s.b.first[c.b.index] + c.sphere_b;
    const float sgn = ia < ib ? 1.0f : -1.0f;  // kept as the lower id's
    s.set_pairs.push_back({ia < ib ? Impl::spring_key(ia, ib) : Impl::spring_key(ib, ia),
                           {{sgn * c.xi.x, sgn * c.xi.y, sgn * c.xi.z}, c.dmax}});
  }
  if (!springs.empty()) s.need_sort = true;  // taken by the next sort's list (build_list)
  return Ok{};
}

void Simulation::Impl::take_set_springs() {
  for (const auto& [key, sp] : set_planes) {
    const std::int64_t id = key / kWallSlots;
    const int k = int(key % kWallSlots);
    if (id >= np) continue;
    const int i = slot_of[std::size_t(id)];
    p.wall_mask[i] |= 1u << k;
    for (int c = 0; c < 3; ++c) p.wall_xi[(std::size_t(i) * kWallSlots + k) * 3 + c] = sp.xi[c];
    p.wall_dmax[std::size_t(i) * kWallSlots + k] = sp.dmax;
  }
  set_planes.clear();
  set_pairs.clear();
  set_row.clear();
  set_hi.clear();
  set_spring.clear();
}

// The set pairs by lower id (a CSR over ids [0, n)); of a pair set twice, the later. Pairs
// of an id at or past n (no such sphere) are dropped, as the plane springs are.
void Simulation::Impl::index_set_pairs(int n) {
  // (stable: the pairs of one key stay in the order set, and the last of them is kept)
  std::stable_sort(set_pairs.begin(), set_pairs.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  set_row.assign(std::size_t(n) + 1, 0);
  set_hi.clear();
  set_spring.clear();
  for (std::size_t k = 0; k < set_pairs.size(); ++k) {
    if (k + 1 < set_pairs.size() && set_pairs[k + 1].first == set_pairs[k].first) continue;  // (a later one wins)
    const std::int32_t lo = std::int32_t(set_pairs[k].first >> 32), hi = std::int32_t(set_pairs[k].first & 0xffffffffu);
    if (lo >= n || hi >= n) continue;
    ++set_row[std::size_t(lo) + 1];
    set_hi.push_back(hi);
    set_spring.push_back(set_pairs[k].second);
  }
  for (int i = 0; i < n; ++i) set_row[std::size_t(i) + 1] += set_row[std::size_t(i)];
}

}  // namespace sandpatch
