// Sleeping regions of the CPU backend (SimulationDef::sleep_regions): which granules of an
// awake simulation are frozen where they lie because nothing near them moves: still (within
// kStillDrift sphere radii of one place) for sleep_time, column by column of the bed; the rest
// is in dem_impl.hpp ("sleeping regions") and docs/dem.md "Sleeping regions".
#include <algorithm>
#include <cmath>

#include "particles/dem_impl.hpp"

namespace sandpatch {

void Simulation::Impl::refresh_sphere_dozing() {
  for (int s = 0; s < np; ++s) sphere_dozing[std::size_t(s)] = dozing[std::size_t(p.body[s])];
  ++work_epoch;
}

void Simulation::Impl::update_regions(double dt_frame) {
  // (the still time: region_sleep_time, or sleep_time where it is 0; 0 then: never)
  const float still_time = def.region_sleep_time > 0 ? def.region_sleep_time : def.sleep_time;
  if (!def.sleep_regions || nb == 0 || !(still_time > 0)) return;
  // columns of kRegionColumn granule reaches over the domain (x, z), sim units
  const float reach = shape.centre_distance + shape.radius;
  const float x0 = def.bounds_min.x, z0 = def.bounds_min.z;
  const float ex = def.bounds_max.x - x0, ez = def.bounds_max.z - z0;
  float col = kRegionColumn * reach;
  int ncx = 1, ncz = 1;
  for (;;) {
    ncx = std::max(1, int(std::ceil(ex / col)));
    ncz = std::max(1, int(std::ceil(ez / col)));
    if (double(ncx) * double(ncz) <= double(kMaxRegionColumns)) break;
    col *= 2.0f;
  }
  const float inv = 1.0f / col;
  auto cx_of = [&](float x) { return std::clamp(int(std::floor((x - x0) * inv)), 0, ncx - 1); };
  auto cz_of = [&](float z) { return std::clamp(int(std::floor((z - z0) * inv)), 0, ncz - 1); };
  const std::size_t ncol = std::size_t(ncx) * std::size_t(ncz);
  col_active.assign(ncol, 0);
  col_top.assign(ncol, -INFINITY);
  auto col_of = [&](float x, float z) { return std::size_t(cz_of(z)) * ncx + cx_of(x); };
  // the granules: still times, the columns holding one that is not still, each column's top
  const float drift2 = still_drift * still_drift;
  for (int i = 0; i < nb; ++i) {
    const std::uint32_t fl = b.flags[i];
    if (!(fl & kBodyGranule) || (fl & kBodyParked)) continue;
    const std::size_t bi = std::size_t(i);
    const float* x = &b.pos[4 * bi];
    const std::size_t c = col_of(x[0], x[2]);
    col_top[c] = std::max(col_top[c], x[1] + reach);
    if (dozing[bi]) continue;  // (still, velocity 0)
    // still: within still_drift of where its still time began
    float* a = &anchor[4 * bi];
    const float dx = x[0] - a[0], dy = x[1] - a[1], dz = x[2] - a[2];
    if (dx * dx + dy * dy + dz * dz > drift2) {
      a[0] = x[0], a[1] = x[1], a[2] = x[2];
      still_for[bi] = 0;
    } else {
      still_for[bi] += float(dt_frame);
    }
    if (still_for[bi] < still_time) col_active[c] = 1;
  }
  // the moving shells (dynamic or kinematic; a static one does not move the bed): each sphere
  // makes active the columns within its radius grown by how far it can move this frame,
  // (|v| + |w| arm) dt_frame, and half a column, whose granules' top it can reach
  for (int i = 0; i < nb; ++i) {
    const std::uint32_t fl = b.flags[i];
    if (fl & (kBodyGranule | kBodyParked | kBodyStatic)) continue;
    const Vec3 v = ld3(b.vel, i), w = ld3(b.omega, i);
    const float grow = float((length(v) + length(w) * guard_arm[std::size_t(i)]) * dt_frame) + 0.5f * col;
    for (int k = 0, first = b.first[i]; k < b.count[i]; ++k) {
      const float* x = &p.pos[4 * std::size_t(slot_of[first + k])];
      const float r = x[3] + grow;
      for (int cz = cz_of(x[2] - r), cz1 = cz_of(x[2] + r); cz <= cz1; ++cz)
        for (int cx = cx_of(x[0] - r), cx1 = cx_of(x[0] + r); cx <= cx1; ++cx) {
          const std::size_t c = std::size_t(cz) * ncx + cx;
          if (x[1] - r < col_top[c]) col_active[c] = 1;
        }
    }
  }
  // each granule: asleep when no column within one of its own is active
  for (int i = 0; i < nb; ++i) {
    const std::uint32_t fl = b.flags[i];
    if (!(fl & kBodyGranule) || (fl & kBodyParked)) continue;
    const int cx = cx_of(b.pos[4 * i]), cz = cz_of(b.pos[4 * i + 2]);
    bool near = false;
    for (int zz = std::max(0, cz - 1); zz <= std::min(ncz - 1, cz + 1) && !near; ++zz)
      for (int xx = std::max(0, cx - 1); xx <= std::min(ncx - 1, cx + 1); ++xx)
        if (col_active[std::size_t(zz) * ncx + xx]) {
          near = true;
          break;
        }
    const std::size_t bi = std::size_t(i);
    if (dozing[bi] == std::uint8_t(!near)) continue;
    dozing[bi] = std::uint8_t(!near);
    if (!near) {
      // falls asleep at rest: its spheres carry velocity 0 into its awake partners' contacts,
      // and it reports no contact force while it sleeps
      st3(b.vel, bi, Vec3{});
      st3(b.omega, bi, Vec3{});
      st3(b.force, bi, Vec3{});
      st3(b.torque, bi, Vec3{});
      rebuild_body(i);
      ++dozing_granules;
    } else {
      --dozing_granules;
    }
    for (int k = 0; k < b.count[i]; ++k) sphere_dozing[std::size_t(slot_of[b.first[i] + k])] = dozing[bi];
    ++work_epoch;
  }
}

}  // namespace sandpatch
