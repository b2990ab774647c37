// Predictive activation: see lod.hpp.
#include "manager/lod.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace sandpatch {

double max_height_under(const Heightfield& hf, double x0, double z0, double x1, double z1) {
  const double sp = hf.spacing();
  // Sample indices bracketing the rectangle (the bilinear surface inside a cell is bounded by
  // its corner samples, so the bracketing samples bound the surface over the rectangle).
  const int i0 = std::max(0, int(std::floor((x0 - hf.origin_x()) / sp)));
  const int i1 = std::min(hf.samples_x() - 1, int(std::ceil((x1 - hf.origin_x()) / sp)));
  const int j0 = std::max(0, int(std::floor((z0 - hf.origin_z()) / sp)));
  const int j1 = std::min(hf.samples_z() - 1, int(std::ceil((z1 - hf.origin_z()) / sp)));
  if (i0 > i1 || j0 > j1) return -std::numeric_limits<double>::infinity();
  float m = -std::numeric_limits<float>::infinity();
  for (int j = j0; j <= j1; ++j)
    for (int i = i0; i <= i1; ++i) m = std::max(m, hf.height(i, j));
  return hf.origin_y() + double(m);
}

std::vector<PatchRequest> predict_contacts(const Heightfield& hf, const std::vector<BodyMotion>& bodies,
                                           const Eigen::Vector3d& g, const LodDef& def) {
  std::vector<PatchRequest> out;
  const int n = std::max(1, def.samples);
  const double h = def.horizon / n;  // s between samples
  for (int b = 0; b < int(bodies.size()); ++b) {
    const BodyMotion& m = bodies[b];
    for (int k = 0; k <= n; ++k) {
      const double t = k * h;
      // Bounds over [t, t + h]: the union of the bounds at both ends, plus g h²/8, the most a
      // parabola can bulge beyond its chord within the interval.
      auto shift = [&](double tt) -> Eigen::Vector3d { return m.velocity * tt + 0.5 * g * tt * tt; };
      const double t1 = k < n ? t + h : t;
      const Eigen::Vector3d bulge = g.cwiseAbs() * (h * h / 8.0);
      const Eigen::Vector3d lo = (m.lo + shift(t)).cwiseMin(m.lo + shift(t1)) - bulge;
      const Eigen::Vector3d hi = (m.hi + shift(t)).cwiseMax(m.hi + shift(t1)) + bulge;
      const double ground = max_height_under(hf, lo.x(), lo.z(), hi.x(), hi.z());
      if (!std::isfinite(ground)) continue;  // off the terrain at this time
      if (lo.y() <= ground + def.margin) {
        PatchRequest r;
        r.x0 = lo.x() - def.apron;
        r.z0 = lo.z() - def.apron;
        r.x1 = hi.x() + def.apron;
        r.z1 = hi.z() + def.apron;
        r.time_to_contact = t;
        r.apron = def.apron;
        r.speed = (m.velocity + g * t).norm();
        r.bodies = {b};
        out.push_back(std::move(r));
        break;
      }
    }
  }
  return out;
}

std::vector<PatchRequest> merge_requests(std::vector<PatchRequest> rs, double max_side) {
  // Repeatedly merge any overlapping pair whose union fits; O(n^2) per pass, n is small
  // (bodies near the ground in one frame).
  for (bool merged = true; merged;) {
    merged = false;
    for (std::size_t a = 0; a < rs.size() && !merged; ++a) {
      for (std::size_t b = a + 1; b < rs.size() && !merged; ++b) {
        if (!rs[a].overlaps(rs[b])) continue;
        PatchRequest u;
        u.x0 = std::min(rs[a].x0, rs[b].x0);
        u.z0 = std::min(rs[a].z0, rs[b].z0);
        u.x1 = std::max(rs[a].x1, rs[b].x1);
        u.z1 = std::max(rs[a].z1, rs[b].z1);
        if (u.width() > max_side || u.depth() > max_side) continue;
        u.time_to_contact = std::min(rs[a].time_to_contact, rs[b].time_to_contact);
        u.apron = std::min(rs[a].apron, rs[b].apron);
        u.speed = std::max(rs[a].speed, rs[b].speed);
        u.bodies = rs[a].bodies;
        u.bodies.insert(u.bodies.end(), rs[b].bodies.begin(), rs[b].bodies.end());
        std::sort(u.bodies.begin(), u.bodies.end());
        rs[a] = std::move(u);
        rs.erase(rs.begin() + std::ptrdiff_t(b));
        merged = true;
      }
    }
  }
  std::sort(rs.begin(), rs.end(), [](const PatchRequest& p, const PatchRequest& q) {
    if (p.time_to_contact != q.time_to_contact) return p.time_to_contact < q.time_to_contact;
    return p.speed > q.speed;
  });
  return rs;
}

}  // namespace sandpatch
