// The demotion's volume ledger (Stage::Demotion, after the heights are written): the volume
// the written heights hold against the volume at promotion (ring_change), the granule spheres
// the render does not see or that rose above the old surface (spheres_outside, spheres_above),
// the mass-conserving correction of the heights (conserve_volume) and the patch's closed
// ledger with its terms (close_ledger). Called by demote (demotion.cpp); docs/manager.md "The
// volume ledger". See terrain_manager_impl.hpp.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "manager/terrain_manager_impl.hpp"

namespace sandpatch {

// Volume change (m³) of the heights `ring_h` over steps.ring against the heights at promotion
// (before_heights on the apron; on the ring's outer row, the heights just before the write):
// the change of the bilinear surface's volume, every sample at full weight (a sample's hat
// integrates to one cell).
double TerrainManager::Impl::ring_change(const Slot& slot, const PatchRecord& rec, const DemotionSteps& steps,
                                         const std::vector<float>& ring_h) const {
  const GridRegion& a = slot.apron;
  const GridRegion& g = steps.ring;
  const double sp = hf->spacing();
  double v = 0;
  for (int j = g.j0; j < g.j0 + g.nj; ++j)
    for (int i = g.i0; i < g.i0 + g.ni; ++i) {
      const std::size_t k = std::size_t(j - g.j0) * g.ni + (i - g.i0);
      const bool in_apron = i >= a.i0 && i < a.i0 + a.ni && j >= a.j0 && j < a.j0 + a.nj;
      v += ring_h[k] - (in_apron ? rec.before_heights[std::size_t(j - a.j0) * a.ni + (i - a.i0)] : steps.pre[k]);
    }
  return v * sp * sp;
}

// Granule spheres the demotion's render does not see: centres outside the render box
// (beyond the apron) or below the floor. `xyzr`: heightfield-local, m.
long long TerrainManager::Impl::spheres_outside(const std::vector<float>& xyzr, const RenderBox& box) {
  long long n = 0;
  for (std::size_t k = 0; k + 3 < xyzr.size(); k += 4) {
    const float x = xyzr[k], y = xyzr[k + 1], z = xyzr[k + 2];
    n += x < box.x0 || x > box.x1 || z < box.z0 || z > box.z1 || y < box.floor;
  }
  return n;
}

// Granule spheres inside the render box whose centres lie above the old surface (the apron's
// heights at promotion, bilinear). `xyzr`: heightfield-local, m.
long long TerrainManager::Impl::spheres_above(const Slot& slot, const PatchRecord& rec, const std::vector<float>& xyzr,
                                              const RenderBox& box, const std::vector<char>* columns) const {
  const GridRegion& a = slot.apron;
  const double sp = hf->spacing();
  auto old_height = [&](double x, double z) {
    const double u = std::clamp(x / sp - a.i0, 0.0, double(a.ni - 1)), v = std::clamp(z / sp - a.j0, 0.0, double(a.nj - 1));
    const int i = std::min(int(u), std::max(0, a.ni - 2)), j = std::min(int(v), std::max(0, a.nj - 2));
    const int i1 = std::min(i + 1, a.ni - 1), j1 = std::min(j + 1, a.nj - 1);
    const double fu = u - i, fv = v - j;
    auto h = [&](int ii, int jj) { return double(rec.before_heights[std::size_t(jj) * a.ni + ii]); };
    return (1 - fv) * ((1 - fu) * h(i, j) + fu * h(i1, j)) + fv * ((1 - fu) * h(i, j1) + fu * h(i1, j1));
  };
  long long n = 0;
  for (std::size_t k = 0; k + 3 < xyzr.size(); k += 4) {
    const float x = xyzr[k], y = xyzr[k + 1], z = xyzr[k + 2];
    if (x < box.x0 || x > box.x1 || z < box.z0 || z > box.z1) continue;
    if (columns) {  // only in the columns marked (the apron sample nearest the sphere)
      const int i = int(std::lround(std::clamp(x / sp - a.i0, 0.0, double(a.ni - 1))));
      const int j = int(std::lround(std::clamp(z / sp - a.j0, 0.0, double(a.nj - 1))));
      if (!(*columns)[std::size_t(j) * a.ni + i]) continue;
    }
    n += y > old_height(x, z);
  }
  return n;
}

// Mass conservation (docs/manager.md "The volume ledger"). The heightfield holds soil at the
// packing φ of the pre-settled tiles (a later patch fills it at that packing), so a patch's
// soil comes back as the volume it took less what left it: V_target = V_before − (granule
// spheres outside the apron or below the floor) × v_sphere / φ. The depth render misses that
// by several per cent at coarse particle scales: a loose surface and scattered granules render
// high (a lone sphere drawn with the 2 r probe shows (28/3) π r³ over the ground, about 4
// times its bulk at φ = 0.6), the fill's own render is off, the stitches move volume across
// the region's and apron's edges, and the heights under a body are cut to its lowest point.
// Two steps, on the ground that moved (weight 1 − w, write_to_heightfield's blend), never
// under or within one sample of a body's bounds (their heights hold them up), never on the
// apron's outer row nor on bare rock: 1. the rise over the old surface cut down to what the
// granules that came above it fill at φ; 2. the rest spread in proportion to 1 − w (evenly
// over the region when less than one sample's worth moved), never below the floor. Undisturbed
// ground keeps its old heights. Records target, rise_cut and correction in rec.ledger.
void TerrainManager::Impl::conserve_volume(const Slot& slot, PatchRecord& rec, const DemotionSteps& steps,
                                           const std::vector<float>& granule_xyzr, const RenderBox& box) {
  const GridRegion& a = slot.apron;
  const double sp = hf->spacing();
  const double pf = rec.ledger.packing_fraction;
  const double rw = radius_world(slot);
  const double lost = pf > 0 ? double(spheres_outside(granule_xyzr, box)) * 4.0 / 3.0 * std::numbers::pi * rw * rw * rw / pf : 0.0;
  const double rendered = rec.ledger.before + ring_change(slot, rec, steps, steps.set_down);
  double left = rec.ledger.before - lost - rendered;  // m³ to place
  rec.ledger.target = rec.ledger.before - lost;
  rec.ledger.correction = 0;
  if (!(rec.ledger.before > 0) || !std::isfinite(left)) return;
  // Weights: the moved weight, 0 on the apron's outer row (its stitch to the ground outside)
  // and over every body's bounds grown by one sample.
  const std::size_t n = std::size_t(a.ni) * a.nj;
  std::vector<double> m(n, 0.0);
  const std::vector<float>& wt = steps.write.weight;
  double total = 0;
  for (int j = 1; j + 1 < a.nj; ++j)
    for (int i = 1; i + 1 < a.ni; ++i) total += m[std::size_t(j) * a.ni + i] = wt.size() == n ? 1.0 - wt[std::size_t(j) * a.ni + i] : 1.0;
  std::vector<char> free(n, 1);  // not under or next to a body
  // A sample index from a coordinate (m, world), clamped near the apron before the cast (a
  // body's bounds may be huge or not finite).
  auto index = [&](double x, double o, int lo_i, int n_i) {
    const double u = std::isfinite(x) ? (x - o) / sp : (x > 0 ? 1e9 : -1e9);
    return std::clamp(u, double(lo_i - 2), double(lo_i + n_i + 2));
  };
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    const int i0 = int(std::floor(index(lo.x(), hf->origin_x(), a.i0, a.ni))) - 1, i1 = int(std::ceil(index(hi.x(), hf->origin_x(), a.i0, a.ni))) + 1;
    const int j0 = int(std::floor(index(lo.z(), hf->origin_z(), a.j0, a.nj))) - 1, j1 = int(std::ceil(index(hi.z(), hf->origin_z(), a.j0, a.nj))) + 1;
    for (int j = std::max(j0, a.j0); j <= std::min(j1, a.j0 + a.nj - 1); ++j)
      for (int i = std::max(i0, a.i0); i <= std::min(i1, a.i0 + a.ni - 1); ++i) free[std::size_t(j - a.j0) * a.ni + (i - a.i0)] = 0;
  }
  // Bare rock (old surface at or below the floor: floor_of, docs/extremes.md) is never raised.
  const float floor_h = float(slot.floor_local);
  for (std::size_t k = 0; k < n; ++k)
    if (!(rec.before_heights[k] > floor_h)) free[k] = 0;
  for (std::size_t k = 0; k < n; ++k)
    if (!free[k]) m[k] = 0.0;
  std::vector<float> h(n);
  hf->read(a, h.data());
  // 1. The rise at the granules' packing: what the heights rose above the old surface is
  // what the granules that came above it fill at φ (a loose pile, a rim, scattered granules render
  // higher than that). The moved ground's rise is scaled down to it, never up (granules above
  // the old surface may rest on a body, where no height can take them).
  // Counted in the columns of the moved ground that rose: a trench dug elsewhere in the patch
  // takes its spheres from columns that fell, which must not cancel a pile's.
  std::vector<char> rose(n, 0);
  double risen = 0, adjustable = 0;  // m³, in those columns
  for (std::size_t k = 0; k < n; ++k) {
    const double rise = std::max(0.0, double(h[k]) - rec.before_heights[k]);
    rose[k] = m[k] > 0 && rise > 0;
    if (!rose[k]) continue;
    risen += rise;
    adjustable += m[k] * rise;
  }
  risen *= sp * sp;
  adjustable *= sp * sp;
  // (spheres above it now less those above it at the fill, in those columns: the fill's top
  // spheres reach above the surface it was cut to, and undisturbed ground comes back at its
  // old height)
  const long long gained = spheres_above(slot, rec, granule_xyzr, box, &rose) - spheres_above(slot, rec, rec.fill_spheres, box, &rose);
  const double at_packing = pf > 0 ? double(std::max(0LL, gained)) * 4.0 / 3.0 * std::numbers::pi * rw * rw * rw / pf : risen;
  const double cut = adjustable > 0 ? std::clamp((risen - at_packing) / adjustable, 0.0, 1.0) : 0.0;  // share of the moved rise taken off
  rec.ledger.rise_cut = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const double rise = std::max(0.0, double(h[k]) - rec.before_heights[k]);
    const float nh = float(h[k] - cut * m[k] * rise);
    rec.ledger.rise_cut += double(nh - h[k]) * sp * sp;
    left -= double(nh - h[k]) * sp * sp;
    h[k] = nh;
  }
  // 2. The rest (the heights cut under bodies, the stitches, the render of the crater, the
  // granules that left), spread over the moved ground (if (almost) nothing moved, over the
  // region evenly). A sample lowered to the floor takes no more: what it could not take goes
  // to the rest.
  if (total < 1.0)
    for (int j = slot.region.j0; j < slot.region.j0 + slot.region.nj; ++j)
      for (int i = slot.region.i0; i < slot.region.i0 + slot.region.ni; ++i) {
        const std::size_t k = std::size_t(j - a.j0) * a.ni + (i - a.i0);
        m[k] = free[k] ? 1.0 : 0.0;
      }
  for (int pass = 0; pass < 4 && std::abs(left) > 1e-9; ++pass) {
    double sum = 0;
    for (double x : m) sum += x;
    if (!(sum > 0)) break;
    const double c = left / (sum * sp * sp);  // m per unit weight
    for (std::size_t k = 0; k < n; ++k) {
      if (m[k] <= 0) continue;
      const float nh = std::max(floor_h, float(h[k] + c * m[k]));
      left -= double(nh - h[k]) * sp * sp;
      rec.ledger.correction += double(nh - h[k]) * sp * sp;
      if (nh <= floor_h) m[k] = 0;
      h[k] = nh;
    }
  }
  hf->write(a, h.data());
}

// Ledger: the region above the floor plus what spilled onto the apron, against the volume
// before promotion; appended to the closed ledgers (the report's ledger.patches). With it, what
// the patch raised above its old surface (a rim, a pile a tool poured out): the heightfield's
// rise over the apron (`risen_m3`) against the spheres of the granules whose centres lie above
// the old surface, at the fill's packing. Granules dug from the dense pre-settled bed and
// dropped in a pile rest looser (and a loose granular surface renders higher), so the ledger
// gains `dilation_m3` = risen − spheres / packing; `error_less_dilation_pct` is the ledger
// without it (docs/manager.md "Tools on a planned path"). `granule_xyzr`: the granules'
// spheres (x, y, z heightfield-local, m; radii not read).
void TerrainManager::Impl::close_ledger(const Slot& slot, PatchRecord& rec, bool on_gl, const std::vector<float>& granule_xyzr,
                                       const DemotionSteps& steps, const RenderBox& box) {
  rec.ledger.after = rec.ledger.before + ring_change(slot, rec, steps, steps.conserved);
  const double err = rec.ledger.before > 0 ? 100.0 * (rec.ledger.after - rec.ledger.before) / rec.ledger.before : 0;
  const GridRegion& a = slot.apron;
  const double sp = hf->spacing();
  double risen = 0;  // m³
  for (int j = 0; j < a.nj; ++j)
    for (int i = 0; i < a.ni; ++i)
      risen += std::max(0.0, double(hf->height(a.i0 + i, a.j0 + j)) - rec.before_heights[std::size_t(j) * a.ni + i]) * sp * sp;
  const long long above = spheres_above(slot, rec, granule_xyzr, box);
  const double rw = radius_world(slot);
  const double spheres = double(above) * 4.0 / 3.0 * std::numbers::pi * rw * rw * rw;  // m³
  const double pf = rec.ledger.packing_fraction;
  const double dilation = pf > 0 ? risen - spheres / pf : 0.0;
  const double less = rec.ledger.before > 0 ? 100.0 * (rec.ledger.after - rec.ledger.before - dilation) / rec.ledger.before : 0;
  // Terms (m³): where the ledger's volume went, step by step (each step's change of the
  // heights' volume, ring_change).
  const GridRegion& g = steps.ring;
  auto change = [&](const std::vector<float>& ring_h) { return ring_change(slot, rec, steps, ring_h); };
  // An apron-sized stage (write_to_heightfield's) on the ring: the ring's outer row as before the write.
  auto on_ring = [&](const std::vector<float>& apron_h) {
    std::vector<float> v = steps.pre;
    if (apron_h.size() != std::size_t(a.ni) * a.nj) return v;
    for (int j = 0; j < a.nj; ++j)
      for (int i = 0; i < a.ni; ++i)
        v[std::size_t(a.j0 + j - g.j0) * g.ni + (a.i0 + i - g.i0)] = apron_h[std::size_t(j) * a.ni + i];
    return v;
  };
  const double d_hat = change(on_ring(steps.write.hat));
  double fill_bias = 0, moved = 0;
  if (!steps.write.hat_baseline.empty()) {
    for (std::size_t k = 0; k < steps.write.hat_baseline.size(); ++k) {
      fill_bias += steps.write.hat_baseline[k] + rec.fill_rise - rec.before_heights[k];
      moved += 1.0 - steps.write.weight[k];
    }
    fill_bias *= sp * sp;
    moved *= sp * sp;
  }
  const double d_blend = change(on_ring(steps.write.blended));
  const double d_written = change(steps.written), d_edged = change(steps.edged), d_down = change(steps.set_down);
  // Granule spheres the render did not see (outside the apron's box or under the floor), at the fill's packing.
  const long long outside = spheres_outside(granule_xyzr, box);
  const double sphere_v = 4.0 / 3.0 * std::numbers::pi * rw * rw * rw;
  const double b = rec.ledger.before;
  auto pct = [&](double v) { return b > 0 ? 100.0 * v / b : 0.0; };
  nlohmann::ordered_json terms = {
      {"fill_render_bias_pct", pct(fill_bias)},
      {"render_change_pct", pct(d_hat - fill_bias)},
      {"render_pct", pct(d_hat)},
      {"blend_pct", pct(d_blend - d_hat)},
      {"apron_stitch_pct", pct(d_written - d_blend)},
      {"edge_stitch_pct", pct(d_edged - d_written)},
      {"bodies_set_down_pct", pct(d_down - d_edged)},
      {"rendered_pct", pct(d_down)},
      {"rise_at_packing_pct", pct(rec.ledger.rise_cut)},
      {"conserved_pct", pct(rec.ledger.correction)},
      {"spheres_outside", outside},
      {"outside_pct", pf > 0 ? pct(-double(outside) * sphere_v / pf) : 0.0},
      {"rise_excess_pct", pct(dilation)},
      {"moved_m2", moved},
      {"fill_cut_pct", pct(rec.ledger.active - b)}};
  ledgers.push_back({{"patch", slot.patch},
                     {"particle_scale", slot.scale},
                     {"region", {slot.region.i0, slot.region.j0, slot.region.ni, slot.region.nj}},
                     {"granules", rec.granules},
                     {"volume_before_m3", rec.ledger.before},
                     {"volume_active_m3", rec.ledger.active},
                     {"volume_rendered_m3", rec.ledger.before + d_down},
                     {"volume_target_m3", rec.ledger.target},
                     {"volume_after_m3", rec.ledger.after},
                     {"error_pct", err},
                     {"risen_m3", risen},
                     {"risen_solid_fraction", risen > 0 ? spheres / risen : 0.0},
                     {"packing_fraction", pf},
                     {"dilation_m3", dilation},
                     {"error_less_dilation_pct", less},
                     {"depth_render", on_gl ? "gl" : "cpu"},
                     {"depth_texels", render_size(slot, box).width},
                     {"depth_rows", render_size(slot, box).height},
                     {"demotion_parts", slot.demotion.parts},
                     {"terms", terms}});
}

}  // namespace sandpatch
