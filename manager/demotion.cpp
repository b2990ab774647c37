// The terrain manager's demotion (Stage::Demotion): a patch's granules rendered top-down into
// the heightfield (manager/depth_conversion.hpp), smoothed and stitched, the bodies it carried
// set down on the new heights, its ledger closed (the volume ledger and mass conservation:
// demotion_ledger.cpp), its slot back to the pool. See terrain_manager_impl.hpp.
#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

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
  const auto [first, n] = particle_range(*slot.sim, c.shell);  // the shell's spheres
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

// Rows of a demotion's CPU depth render done in one part. A band's cost grows with the spheres
// it crosses: a 676-texel render of a scale-2 patch of 2,233 granules took 1–6 ms a band of 128
// rows on two cores, the bands through the patch's middle the most, beside the 7–11 ms of the
// patch stepping in the same frame (docs/BENCHMARKS.md "A patch that travels with its body").
constexpr int kDepthRowsPerPart = 64;
// Samples of stale internal-edge info renewed a frame (demote_idle): a strip of whole columns
// of a changed region, computed with a cell more around it (docs/BENCHMARKS.md "Internal edges
// renewed after the write").
constexpr int kEdgeCellsPerPart = 64;

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
    if (s.state == SlotState::Asleep && !s.demotion.releasing && s.successor < 0 && s.rebase_from < 0 &&
        s.asleep_for >= def.idle_timeout &&
        (!next || s.demotion.stage > next->demotion.stage))
      next = &s;
  if (next) return demote(*next, time, true, /*staged=*/true);
  // A full pool keeps a slot ready for the next request: a patch no body wants any more (none
  // carried by it, over or near it, or heading for it) is released now, one part a frame, not
  // when a request needs its slot. Waiting for that, a car turning across a corner of its
  // patches drove on the heightfield while the patch it had left behind was demoted.
  bool full = true;
  for (const Slot& s : slots) full = full && s.state != SlotState::Free && !s.demotion.releasing;
  if (full)  // (else a slot is free, or one is being released)
    for (Slot& s : slots) {
      if (!s.ready() || s.carried.empty() || wanted(s) || wanted_for_release(s) || s.successor >= 0 || s.rebase_from >= 0)
        continue;  // (not reached yet, or travelling: kept)
      ++early_releases;
      return release(s, time);
    }
  // Bullet's internal-edge info of the heights the writes changed, left for later by
  // terrain_changed (about 1 ms for a car's track patch, most of its write): a strip of about
  // kEdgeCellsPerPart cells a frame (0.2-0.3 ms), so stale regions do not pile up. (A body
  // coming near a stale region has it renewed before its step: BulletWorld::ensure_edges.)
  if (world->stale_edge_samples() > 0) {
    const auto t0 = Clock::now();
    world->renew_edges(kEdgeCellsPerPart);
    time_part(Part::Edges, ms_since(t0));
    ++work.conversion_parts;
    return Ok{};
  }
  return render_baselines(time, /*whole=*/false);
}

// Ahead of any demotion: the render of a live patch's fill (the demotion's first stage, the
// baseline of "Round trip") and its hat means, which depend on the fill alone: one part a
// frame in frames no other part takes (demote_idle), or all of them (`whole`: prepare, before
// the first frame).
// On the CPU only (a GL render is one part, at the demotion). A patch taken over by its
// successor then waits that many frames less for its demotion to write the heights the
// successor is rebased on, and a request waits less for a released slot.
Status TerrainManager::Impl::render_baselines(double time, bool whole) {
  if (depth) return Ok{};
  for (Slot& s : slots)
    while (s.ready() && !s.demotion.releasing && !s.superseded && !record(s).fill_spheres.empty() &&
           (s.demotion.stage == 0 || fill_hat_pending(s))) {
      if (Status st = demote(s, time, false, /*staged=*/true); !st) return st;
      if (!whole) return Ok{};
    }
  return Ok{};
}

Status TerrainManager::Impl::demote_every(double time) {
  // Fills first (a successor's takes its predecessor over), then the patches taken over (their
  // heights are their successors' heights before), then the rest.
  for (auto& s : slots)
    if (s.state == SlotState::Filling) {
      if (!s.cut)
        if (Status st = cut(s, time, kWhole); !st) return st;
      if (Status st = upload(s, s.pending.size(), time); !st) return st;
    }
  for (int pass = 0; pass < 2; ++pass)
    for (auto& s : slots)
      if (s.state != SlotState::Free && s.superseded == (pass == 0))
        if (Status st = demote(s, time); !st) return st;
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
  const bool have_base = has_baseline(slot);
  // The hat means of each image over the apron, the write's costliest sums (about half of the
  // write's 3-6 ms on a car's patch), each in a part of its own when staged: the fill's once
  // its render is done (before the render of the surface now; ahead of the demotion, with
  // that render, render_baselines), the surface's after its render.
  const bool hat_of_fill = fill_hat_pending(slot);
  if (staged && (hat_of_fill || w.stage == 2)) {
    const auto t = Clock::now();
    if (hat_of_fill) {
      w.hat_was = hat_means(w.was, slot.apron, float(sp));
    } else {
      w.hat_now = hat_means(w.now, slot.apron, float(sp));
      ++w.stage;
    }
    ++w.parts;
    ++work.demotion_parts;
    ++work.conversion_parts;
    w.ms += ms_since(t);
    time_part(Part::HatMeans, ms_since(t0));
    return Ok{};
  }
  // Granule spheres in heightfield-local coordinates (m), now and as filled. (A staged part of
  // the fill's CPU render needs only the fill: the box's top is the GL render's depth range.)
  std::vector<float> xyzr;
  if (!(staged && w.stage == 0 && !(depth && gl_ok))) granule_spheres(slot, xyzr);
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
  // Parts 1 and 2, one render each: the surface of `spheres` (none: no render) into `into`,
  // one demotion part of the frame, its time (ms) counted from `start`.
  // On the CPU a staged part renders kDepthRowsPerPart rows of the image (the bands of one
  // image over successive parts give the whole render's image); on GL, the whole image.
  auto render_part = [&](const std::vector<float>* spheres, HeightImage& into, Clock::time_point start) -> Status {
    bool done = true;
    if (spheres && depth && gl_ok) {
      auto img = render_surface(slot, box, *spheres, gl_ok, &w.on_gl);
      if (!img) return img.errors();
      ++work.depth_renders;
      into = std::move(*img);
    } else if (spheres) {
      const DepthSize size = render_size(slot, box);
      const int rows = staged ? kDepthRowsPerPart : size.height;
      if (w.row == 0)
        into = render_heights_cpu(nullptr, 0, size.width, size.height, box.x0, box.z0, box.x1, box.z1, box.floor);
      const int v0 = w.row, v1 = std::min(size.height, v0 + rows);
      render_heights_cpu_rows(spheres->data(), spheres->size() / 4, into, v0, v1);
      finish_surface_rows(slot, box, into, v0, v1);
      done = v1 >= size.height;
      w.row = done ? 0 : v1;
      work.depth_renders += done;
    }
    if (done) ++w.stage;
    ++w.parts;
    ++work.demotion_parts;
    ++work.conversion_parts;
    w.ms += ms_since(start);
    if (staged) time_part(Part::Render, ms_since(t0));
    return Ok{};
  };
  // Part 1: the surface of the fill (the baseline below), 2: the surface now.
  if (w.stage == 0) {
    if (Status st = render_part(rec.fill_spheres.empty() ? nullptr : &filled, w.was, t0); !st) return st;
    if (staged) return Ok{};
  }
  if (w.stage == 1) {
    if (Status st = render_part(&xyzr, w.now, Clock::now()); !st) return st;
    if (staged) return Ok{};
  }
  // The last part: the heights written. Where the surface did not move, the heights of before the
  // promotion come back exactly (write_to_heightfield's RenderBaseline; docs/manager.md
  // "Round trip").
  const auto t2 = Clock::now();
  const RenderBaseline base{&w.was, &rec.before_heights, rw, rec.fill_rise};
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
  write_to_heightfield(w.now, a, *hf, 1, have_base ? &base : nullptr, &steps.write, HatMeans{&w.hat_now, &w.hat_was});
  read_ring(steps.written);
  // The patch's own edge inside the apron: particles on one side, old terrain (or what
  // spilled onto it) on the other; the same Gaussian band stitches it.
  smooth_border_band(*hf, slot.region, 1);
  read_ring(steps.edged);
  set_bodies_down(slot, time);
  read_ring(steps.set_down);
  conserve_volume(slot, rec, steps, xyzr, box);
  world->terrain_changed(d);
  read_ring(steps.conserved);
  dirty.push_back(d);
  ++w.parts;
  close_ledger(slot, rec, w.on_gl, xyzr, steps, box);
  for (Slot& b : slots)
    if (b.rebase_from == int(&slot - slots.data())) rebase(b);
  for (const Carried& c : slot.carried)
    if (c.enabled && world->alive(c.body)) world->set_terrain_collision(c.body, true);
  events.push_back({PatchEventKind::Demoted, slot.patch, time, w.ms + ms_since(t2), rec.granules});
  ++work.demotion_parts;
  ++work.conversion_parts;
  ++work.demotions;
  if (staged) time_part(Part::Write, ms_since(t0));
  slot.state = SlotState::Free;
  rec.granules = 0;
  slot.carried.clear();
  slot.patch = -1;
  slot.demotion = {};
  slot.superseded = false;
  slot.successor = slot.predecessor = slot.rebase_from = -1;
  slot.inherited.clear();
  return Ok{};
}

// A successor whose predecessor's demotion has just written its apron (take_over): its
// heights at promotion there become the written ones (the surface of the granules it took
// over, as the heightfield now holds it, and the predecessor's stitches around them), and its
// ledger's volume before is taken again from them over its region.
void TerrainManager::Impl::rebase(Slot& b) {
  b.rebase_from = -1;
  PatchRecord& rb = record(b);
  const GridRegion& ap = b.apron;
  if (rb.before_heights.size() != std::size_t(ap.ni) * ap.nj) return;
  hf->read(ap, rb.before_heights.data());
  const GridRegion& g = b.region;
  const double sp = hf->spacing();
  double v = 0;
  for (int j = g.j0; j < g.j0 + g.nj; ++j)
    for (int i = g.i0; i < g.i0 + g.ni; ++i) {
      const double wi = (i == g.i0 || i == g.i0 + g.ni - 1) ? 0.5 : 1.0, wj = (j == g.j0 || j == g.j0 + g.nj - 1) ? 0.5 : 1.0;
      v += wi * wj * (rb.before_heights[std::size_t(j - ap.j0) * ap.ni + std::size_t(i - ap.i0)] - b.floor_local);
    }
  rb.ledger.before = v * sp * sp;
}

// Texels along x and z (rows) of a slot's depth render: square texels of a
// depth_texels_per_radius-th of a granule sphere's radius over its box, each side at least 64
// and at most depth_resolution (depth_texels_per_radius 0: depth_resolution a side). (A car's
// patch box of 12.5 m by 6.5 m takes 834 × 434 texels; the CPU render's parts go by rows.)
TerrainManager::Impl::DepthSize TerrainManager::Impl::render_size(const Slot& slot, const RenderBox& box) const {
  if (!(def.depth_texels_per_radius > 0)) return {def.depth_resolution, def.depth_resolution};
  const double texel = radius_world(slot) / def.depth_texels_per_radius;  // m
  auto side = [&](double m) { return int(std::clamp(std::ceil(m / texel), 64.0, double(def.depth_resolution))); };
  return {side(box.x1 - box.x0), side(box.z1 - box.z0)};
}

// The surface of a set of (grown) spheres over the slot's apron, as the heightfield will take
// it: on GL when the manager has a depth renderer and `gl_ok` (then *on_gl is set), else on
// the CPU.
Result<HeightImage> TerrainManager::Impl::render_surface(const Slot& slot, const RenderBox& box, const std::vector<float>& spheres,
                                                         bool gl_ok, bool* on_gl) const {
  const DepthSize size = render_size(slot, box);
  const float x0 = box.x0, z0 = box.z0, x1 = box.x1, z1 = box.z1;
  HeightImage img;
  if (depth && gl_ok) {
    if (Status st = gl->make_current(); !st) return st.errors();
    auto r = depth->render(spheres.data(), spheres.size() / 4, x0, z0, x1, z1, box.floor, box.top + 1.0f, size.width,
                           size.height);
    if (!r) return r.errors();
    img = std::move(*r);
    *on_gl = true;
  } else {
    img = render_heights_cpu(spheres.data(), spheres.size() / 4, size.width, size.height, x0, z0, x1, z1, box.floor);
  }
  finish_surface_rows(slot, box, img, 0, img.height);
  return img;
}

// Rows [v0, v1) of a rendered image made into the surface the heightfield takes: the tops
// lowered by the probe (lower_by_probe); outside the filled region the terrain was there
// before: particles add to it, an empty texel keeps it (texels inside the region with no
// particle read the floor).
void TerrainManager::Impl::finish_surface_rows(const Slot& slot, const RenderBox& box, HeightImage& img, int v0,
                                               int v1) const {
  const double sp = hf->spacing();
  const int res = img.width;
  const float x0 = box.x0, z0 = box.z0, x1 = box.x1, z1 = box.z1;
  const float du = (x1 - x0) / float(res), dv = (z1 - z0) / float(img.height);
  const double rx0 = slot.region.i0 * sp, rx1 = (slot.region.i0 + slot.region.ni - 1) * sp;
  const double rz0 = slot.region.j0 * sp, rz1 = (slot.region.j0 + slot.region.nj - 1) * sp;
  for (int v = v0; v < v1; ++v)
    for (int u = 0; u < res; ++u) {
      const float x = x0 + (u + 0.5f) * du, z = z0 + (v + 0.5f) * dv;
      float& h = img.h[std::size_t(v) * res + u];
      // An empty texel reads the floor. Where the old surface lies below it (bare rock under
      // the bedrock plane, floor_of), the rock stays: it is not raised to the floor.
      h = probe_lowered(h, box.floor, box.probe);
      const bool empty = h <= box.floor;
      if (x >= rx0 && x <= rx1 && z >= rz0 && z <= rz1) {
        if (empty) h = std::min(h, hf->sample(x, z));
        continue;
      }
      h = empty ? hf->sample(x, z) : std::max(h, hf->sample(x, z));
    }
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

}  // namespace sandpatch
