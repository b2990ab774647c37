// The terrain manager's demotion (Stage::Demotion): a patch's granules rendered top-down into
// the heightfield (manager/depth_conversion.hpp), the bodies it carried set down on the new
// heights, its ledger closed, its slot back to the pool. See terrain_manager_impl.hpp.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>
#include <numbers>

#include "heightfield/filter.hpp"
#include "manager/terrain_manager_impl.hpp"

namespace sandpatch {

using manager_detail::body_key;
using manager_detail::Clock;
using manager_detail::ms_since;

namespace {

constexpr float kNoUnderside = std::numeric_limits<float>::infinity();

// Where a carried body lies over the samples [i0, i0 + ni) x [j0, j0 + nj): `lowest` (its lowest
// point, m, heightfield-local) at the samples under it, kNoUnderside elsewhere. Under it = within
// a sphere radius rw (horizontally) of one of its DEM shell's spheres, which are centred on its
// surface. A flat floor at the lowest point, not the body's curved underside: the shell's
// centres give the underside only to within the slope times their spacing, and a height above
// the body makes Bullet push it out (measured: a 0.5 m ball on heights from the shell's centres
// lowered by rw/2 was kicked up at 0.24 m/s, and 10 cm spheres resting side by side kept waking
// their patches). `pos`: the slot's spheres by id (Simulation::particle_positions); rw: the
// granule sphere radius in the world (m).
std::vector<float> floor_under_body(const Slot& slot, const Carried& c, const std::vector<Vec3>& pos, const Heightfield& hf, double rw,
                                  float lowest, int i0, int j0, int ni, int nj) {
  std::vector<float> out(std::size_t(ni) * std::size_t(nj), kNoUnderside);
  // the shell's spheres: particle ids follow the bodies' creation order
  std::size_t first = 0;
  for (int b = 0; b < c.shell.index; ++b) first += std::size_t(slot.sim->body_particle_count(BodyId{b}));
  const std::size_t n = std::size_t(slot.sim->body_particle_count(c.shell));
  if (n == 0 || first + n > pos.size()) return out;
  const double sp = hf.spacing();
  const double r2 = rw * rw;
  for (std::size_t k = first; k < first + n; ++k) {
    const auto w = slot.sim->def().scale.position_to_world(pos[k]);
    const double x = w[0] - hf.origin_x(), z = w[2] - hf.origin_z();
    const int ia = std::max(i0, int(std::ceil((x - rw) / sp))), ib = std::min(i0 + ni - 1, int(std::floor((x + rw) / sp)));
    const int ja = std::max(j0, int(std::ceil((z - rw) / sp))), jb = std::min(j0 + nj - 1, int(std::floor((z + rw) / sp)));
    for (int j = ja; j <= jb; ++j)
      for (int i = ia; i <= ib; ++i) {
        const double dx = i * sp - x, dz = j * sp - z;
        if (dx * dx + dz * dz > r2) continue;
        out[std::size_t(j - j0) * std::size_t(ni) + std::size_t(i - i0)] = 0.0f;  // under the body
      }
  }
  for (float& u : out)
    if (u != kNoUnderside) u = lowest;
  return out;
}

}  // namespace

// One part a frame, of one patch: a demotion is three renders' and writes' worth of work (the
// fill's surface, the surface now, the heights written), and doing it all in one frame was
// the longest frame of a run. A patch asleep does not move, so its parts may come in any
// frames; one that wakes before the last part starts again (couple: step_patches).
// Only in a frame in which no other conversion part ran (activate: promotions and releases
// go first).
Status TerrainManager::Impl::demote_idle(double time) {
  if (work.conversion_parts > 0) return Ok{};
  Slot* next = nullptr;
  for (auto& s : slots)
    if (s.state == SlotState::Asleep && !s.demotion.releasing && s.asleep_for >= def.idle_timeout &&
        (!next || s.demotion.stage > next->demotion.stage))
      next = &s;
  if (next) return demote(*next, time, true, /*staged=*/true);
  return Ok{};
}

Status TerrainManager::Impl::demote_every(double time) {
  for (auto& s : slots) {
    if (s.state == SlotState::Filling) {
      if (!s.cut)
        if (Status st = cut(s, time, kWhole); !st) return st;
      if (Status st = upload(s, s.pending.size(), time); !st) return st;
    }
    if (s.state != SlotState::Free)
      if (Status st = demote(s, time); !st) return st;
  }
  return Ok{};
}

// Appends the slot's granule spheres (x, y, z, r; m, heightfield-local). Granules are the
// first bodies of a patch, so their spheres have the first 4 × granules particle ids.
void TerrainManager::Impl::granule_spheres(const Slot& slot, std::vector<float>& xyzr) const {
  const std::vector<Vec3> pos = slot.sim->particle_positions();
  const std::size_t n = std::min(pos.size(), std::size_t(4) * std::size_t(record(slot).granules));
  const float rw = radius_world(slot);
  for (std::size_t k = 0; k < n; ++k) {
    const auto w = slot.sim->def().scale.position_to_world(pos[k]);
    xyzr.insert(xyzr.end(), {float(w[0] - hf->origin_x()), float(w[1] - hf->origin_y()), float(w[2] - hf->origin_z()), rw});
  }
}

// `gl_ok`: the depth render may use GL (false: the CPU depth render, same contract). A
// patch grown mid-frame (extend) is demoted on the CPU: demoting on GL there left the
// manager's context in a state where the next GL depth render failed with
// GL_INVALID_OPERATION (measured on llvmpipe; cause not found yet).
Status TerrainManager::Impl::demote(Slot& slot, double time, bool gl_ok, bool staged) {
  const auto t0 = Clock::now();
  PatchRecord& rec = record(slot);
  Slot::Demotion& w = slot.demotion;
  const double sp = hf->spacing();
  // Granule spheres in heightfield-local coordinates (m), now and as filled.
  std::vector<float> xyzr;
  granule_spheres(slot, xyzr);
  std::vector<float> filled = rec.fill_spheres;
  // Spheres grown by the probe radius, tops lowered by it after the render (lower_by_probe).
  const float rw = radius_world(slot);
  const float probe = float(def.surface_probe) * rw;
  for (std::size_t k = 3; k < xyzr.size(); k += 4) xyzr[k] += probe;
  for (std::size_t k = 3; k < filled.size(); k += 4) filled[k] += probe;
  float top = float(slot.floor_local) + rw + probe;
  for (std::size_t k = 1; k < xyzr.size(); k += 4) top = std::max(top, xyzr[k] + rw + probe);
  for (std::size_t k = 1; k < filled.size(); k += 4) top = std::max(top, filled[k] + rw + probe);
  const GridRegion& a = slot.apron;
  RenderBox box;
  box.x0 = float((a.i0 - 0.5) * sp), box.z0 = float((a.j0 - 0.5) * sp);
  box.x1 = float((a.i0 + a.ni - 0.5) * sp), box.z1 = float((a.j0 + a.nj - 0.5) * sp);
  box.floor = float(slot.floor_local);
  box.top = top;
  box.probe = probe;
  // Part 1: the surface of the fill (the baseline below), 2: the surface now.
  if (w.stage == 0) {
    if (!rec.fill_spheres.empty()) {
      auto was = render_surface(slot, box, filled, gl_ok, &w.on_gl);
      if (!was) return was.errors();
      ++work.depth_renders;
      w.was = std::move(*was);
    }
    w.stage = 1;
    ++work.demotion_parts;
    ++work.conversion_parts;
    w.ms += ms_since(t0);
    if (staged) return Ok{};
  }
  if (w.stage == 1) {
    const auto t1 = Clock::now();
    auto img = render_surface(slot, box, xyzr, gl_ok, &w.on_gl);
    if (!img) return img.errors();
    ++work.depth_renders;
    w.now = std::move(*img);
    w.stage = 2;
    ++work.demotion_parts;
    ++work.conversion_parts;
    w.ms += ms_since(t1);
    if (staged) return Ok{};
  }
  // Part 3: the heights written. Where the surface did not move, the heights of before the
  // promotion come back exactly (write_to_heightfield's RenderBaseline; docs/manager.md
  // "Round trip").
  const auto t2 = Clock::now();
  const RenderBaseline base{&w.was, &rec.before_heights, rw, rec.fill_rise};
  const bool have_base = !rec.fill_spheres.empty() && rec.before_heights.size() == std::size_t(a.ni) * a.nj;
  // The border band reaches one sample beyond the apron.
  GridRegion d{std::max(0, a.i0 - 1), std::max(0, a.j0 - 1), 0, 0};
  d.ni = std::min(hf->samples_x(), a.i0 + a.ni + 1) - d.i0;
  d.nj = std::min(hf->samples_z(), a.j0 + a.nj + 1) - d.j0;
  DemotionSteps steps;
  steps.ring = d;
  auto read_ring = [&](std::vector<float>& v) {
    v.resize(std::size_t(d.ni) * d.nj);
    hf->read(d, v.data());
  };
  read_ring(steps.pre);
  write_to_heightfield(w.now, a, *hf, 1, have_base ? &base : nullptr, &steps.write);
  read_ring(steps.written);
  // The patch's own edge inside the apron: particles on one side, old terrain (or what
  // spilled onto it) on the other; the same Gaussian band stitches it.
  smooth_border_band(*hf, slot.region, 1);
  read_ring(steps.edged);
  set_bodies_down(slot, time);
  read_ring(steps.set_down);
  conserve_volume(slot, rec, steps, xyzr, box);
  world->terrain_changed();
  read_ring(steps.conserved);
  dirty.push_back(d);
  close_ledger(slot, rec, w.on_gl, xyzr, steps, box);
  for (const Carried& c : slot.carried)
    if (c.enabled && world->alive(c.body)) world->set_terrain_collision(c.body, true);
  events.push_back({PatchEventKind::Demoted, slot.patch, time, w.ms + ms_since(t2), rec.granules});
  ++work.demotion_parts;
  ++work.conversion_parts;
  ++work.demotions;
  slot.state = SlotState::Free;
  rec.granules = 0;
  slot.carried.clear();
  slot.patch = -1;
  slot.demotion = {};
  return Ok{};
}

// Texels a side of a slot's depth render: depth_texels_per_radius over its box, at least 64,
// at most depth_resolution.
int TerrainManager::Impl::render_resolution(const Slot& slot, const RenderBox& box) const {
  if (!(def.depth_texels_per_radius > 0)) return def.depth_resolution;
  const double texel = radius_world(slot) / def.depth_texels_per_radius;  // m
  const double side = std::max(box.x1 - box.x0, box.z1 - box.z0);
  return int(std::clamp(std::ceil(side / texel), 64.0, double(def.depth_resolution)));
}

// The surface of a set of (grown) spheres over the slot's apron, as the heightfield will take
// it: on GL when the manager has a depth renderer and `gl_ok` (then *on_gl is set), else on
// the CPU.
Result<HeightImage> TerrainManager::Impl::render_surface(const Slot& slot, const RenderBox& box, const std::vector<float>& spheres,
                                                         bool gl_ok, bool* on_gl) const {
  const double sp = hf->spacing();
  const int res = render_resolution(slot, box);
  const float x0 = box.x0, z0 = box.z0, x1 = box.x1, z1 = box.z1;
  const float du = (x1 - x0) / float(res), dv = (z1 - z0) / float(res);
  const double rx0 = slot.region.i0 * sp, rx1 = (slot.region.i0 + slot.region.ni - 1) * sp;
  const double rz0 = slot.region.j0 * sp, rz1 = (slot.region.j0 + slot.region.nj - 1) * sp;
  HeightImage img;
  if (depth && gl_ok) {
    if (Status st = gl->make_current(); !st) return st.errors();
    auto r = depth->render(spheres.data(), spheres.size() / 4, x0, z0, x1, z1, box.floor, box.top + 1.0f, res);
    if (!r) return r.errors();
    img = std::move(*r);
    *on_gl = true;
  } else {
    img = render_heights_cpu(spheres.data(), spheres.size() / 4, res, x0, z0, x1, z1, box.floor);
  }
  lower_by_probe(img, box.floor, box.probe);
  // Outside the filled region the terrain was there before: particles add to it, an
  // empty texel keeps it (texels inside the region with no particle read the floor).
  for (int v = 0; v < res; ++v)
    for (int u = 0; u < res; ++u) {
      const float x = x0 + (u + 0.5f) * du, z = z0 + (v + 0.5f) * dv;
      float& h = img.h[std::size_t(v) * res + u];
      // An empty texel reads the floor. Where the old surface lies below it (bare rock under
      // the bedrock plane, floor_of), the rock stays: it is not raised to the floor.
      const bool empty = h <= box.floor;
      if (x >= rx0 && x <= rx1 && z >= rz0 && z <= rz1) {
        if (empty) h = std::min(h, hf->sample(x, z));
        continue;
      }
      h = empty ? hf->sample(x, z) : std::max(h, hf->sample(x, z));
    }
  return img;
}

// A body the patch carried stays where it is on the new surface: under its footprint the
// heights are kept below its lowest point (the Gaussian lifts a narrow crater's floor, and
// Bullet would push the body out with a kick that asked for a new patch). A body resting on
// the granules is set down: its velocities are zeroed, so it stays at rest there, and under
// it the heightfield is a floor at its lowest point (floor_under_body): the top-down render sees
// the granules the body rests on about a granule sphere radius below the body (its DEM shell's
// spheres, centred on its surface, keep them there), and a body set on that render fell by up
// to r and rolled on after demotion. Resting is
// `lying` (coupling.cpp), the manager's test for a body on the terrain: lowest point within a
// granule diameter of the surface under its centre, slower than 10 sleep_speed (linear, and
// angular at its half-diagonal; a body settling into a patch still creeps at a few cm/s when
// sleep_speed is 1 cm/s). Any other body is moving (falling onto the patch, rolling across
// it) and keeps its position and velocities: the demotion hands it back to the heightfield
// as it is (before, every carried body was stopped, and a body in free fall at the end of a
// run was reported at rest in mid-air). Every body over the written heights is then given
// time to settle before it may ask for a patch.
void TerrainManager::Impl::set_bodies_down(const Slot& slot, double time) {
  const double sp = hf->spacing();
  const GridRegion& a = slot.apron;
  // Each carried body: whether it rests (on the surface just written, before any change
  // below), its bounds and samples (the samples of the triangles under it: one more sample
  // around its bounds, within the written apron) and, resting, the heights under it.
  struct Down {
    const Carried* c;
    Eigen::Vector3d lo, hi;
    bool resting;
    float floor_at;  // its lowest point, m, heightfield-local
    int i0, i1, j0, j1;
    std::vector<float> under;
    float at(int i, int j) const {
      return under.empty() ? kNoUnderside : under[std::size_t(j - j0) * std::size_t(i1 - i0 + 1) + std::size_t(i - i0)];
    }
  };
  std::vector<Down> downs;
  std::vector<Vec3> pos;  // the patch's spheres by id (read once, for the first resting body)
  for (const Carried& c : slot.carried) {
    if (!c.enabled || !world->alive(c.body)) continue;  // (a disabled shell: another patch carries it)
    Down d{&c, {}, {}, false, 0, 0, 0, 0, 0, {}};
    world->bounds(c.body, &d.lo, &d.hi);
    d.resting = lying(c.body, d.lo, d.hi);
    d.floor_at = float(d.lo.y() - hf->origin_y());
    d.i0 = std::max(a.i0, int(std::floor((d.lo.x() - hf->origin_x()) / sp))), d.i1 = std::min(a.i0 + a.ni - 1, int(std::ceil((d.hi.x() - hf->origin_x()) / sp)));
    d.j0 = std::max(a.j0, int(std::floor((d.lo.z() - hf->origin_z()) / sp))), d.j1 = std::min(a.j0 + a.nj - 1, int(std::ceil((d.hi.z() - hf->origin_z()) / sp)));
    if (d.resting && d.i1 >= d.i0 && d.j1 >= d.j0) {
      if (pos.empty()) pos = slot.sim->particle_positions();
      d.under = floor_under_body(slot, c, pos, *hf, radius_world(slot), d.floor_at, d.i0, d.j0, d.i1 - d.i0 + 1, d.j1 - d.j0 + 1);
    }
    downs.push_back(std::move(d));
  }
  // Under a resting body: its lowest point, but nowhere above the lowest point of another body
  // over the sample (bounds and one sample around them: bodies touching each other, or one
  // beside the patch), so the heights never rise into another body.
  std::vector<RigidBodyId> others = world->bodies();
  std::vector<Eigen::Vector3d> olo(others.size()), ohi(others.size());
  for (std::size_t k = 0; k < others.size(); ++k) world->bounds(others[k], &olo[k], &ohi[k]);
  for (const Down& d : downs)
    for (int j = d.j0; j <= d.j1; ++j)
      for (int i = d.i0; i <= d.i1; ++i) {
        float u = d.at(i, j);
        if (u == kNoUnderside) continue;
        const double x = hf->origin_x() + i * sp, z = hf->origin_z() + j * sp;
        for (std::size_t k = 0; k < others.size(); ++k)
          if (body_key(others[k]) != body_key(d.c->body) && x > olo[k].x() - sp && x < ohi[k].x() + sp && z > olo[k].z() - sp &&
              z < ohi[k].z() + sp)
            u = std::min(u, float(olo[k].y() - hf->origin_y()));
        hf->set_height(i, j, u);
      }
  // Under every carried body elsewhere: below its lowest point.
  for (const Down& d : downs)
    for (int j = d.j0; j <= d.j1; ++j)
      for (int i = d.i0; i <= d.i1; ++i)
        if (d.at(i, j) == kNoUnderside && hf->height(i, j) > d.floor_at) hf->set_height(i, j, d.floor_at);
  for (const Down& d : downs) {
    if (!d.resting) continue;
    BodyState st = world->state(d.c->body);
    st.linear_velocity.setZero();
    st.angular_velocity.setZero();
    world->set_state(d.c->body, st);
  }
  // (the caller tells Bullet the terrain changed, after conserve_volume)
  // Every body over the written heights (those it carried, and those resting on the
  // heightfield there: Bullet's contacts with the changed tiles are made again, and such a
  // body first falls g dt) is given 0.1 s (6 frames) to settle before it may ask for a patch.
  const double wx0 = hf->origin_x() + (a.i0 - 1) * sp, wx1 = hf->origin_x() + (a.i0 + a.ni) * sp;
  const double wz0 = hf->origin_z() + (a.j0 - 1) * sp, wz1 = hf->origin_z() + (a.j0 + a.nj) * sp;
  for (RigidBodyId b : world->bodies()) {
    Eigen::Vector3d lo, hi;
    world->bounds(b, &lo, &hi);
    if (lo.x() < wx1 && hi.x() > wx0 && lo.z() < wz1 && hi.z() > wz0) set_down_until[body_key(b)] = time + 0.1;
  }
}

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
                                              const RenderBox& box) const {
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
  double risen = 0, adjustable = 0;  // m³
  for (std::size_t k = 0; k < n; ++k) {
    const double rise = std::max(0.0, double(h[k]) - rec.before_heights[k]);
    risen += rise;
    adjustable += m[k] * rise;
  }
  risen *= sp * sp;
  adjustable *= sp * sp;
  // (spheres above it now less those above it at the fill: the fill's top spheres reach above
  // the surface it was cut to, and undisturbed ground comes back at its old height)
  const long long gained = spheres_above(slot, rec, granule_xyzr, box) - spheres_above(slot, rec, rec.fill_spheres, box);
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
                     {"terms", terms}});
}

}  // namespace sandpatch
