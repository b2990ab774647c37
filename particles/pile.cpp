// Poured pile and flank fit; see pile.hpp.
#include "particles/pile.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include "particles/dem.hpp"

#include "common/random.hpp"

namespace sandpatch {

namespace {

// Least-squares line y = icpt + slope·x through (x, y) points (the sums taken in order);
// ok is false with fewer than two points or no spread in x. residual: RMS of y about it.
struct Line {
  bool ok = false;
  double slope = 0, residual = 0;
};
Line fit_line(const std::vector<std::pair<double, double>>& pts) {
  Line l;
  const int n = int(pts.size());
  if (n < 2) return l;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (auto [x, y] : pts) sx += x, sy += y, sxx += x * x, sxy += x * y;
  const double den = n * sxx - sx * sx;
  if (!(den > 0)) return l;
  l.slope = (n * sxy - sx * sy) / den;
  const double icpt = (sy - l.slope * sx) / n;
  double r2 = 0;
  for (auto [x, y] : pts) r2 += (y - icpt - l.slope * x) * (y - icpt - l.slope * x);
  l.residual = std::sqrt(r2 / n);
  l.ok = true;
  return l;
}

}  // namespace


FlankFit fit_flank(const std::vector<SurfacePoint>& points, const FlankFitDef& def) {
  FlankFit out;
  if (points.empty() || !(def.bin > 0) || def.sectors < 1) return out;
  double smax = 0;
  for (const auto& p : points)
    if (std::isfinite(p.s)) smax = std::max(smax, p.s);
  if (smax / def.bin > 1e6) return out;  // a caller's stray point far away: refuse, do not allocate
  const int nbins = int(smax / def.bin) + 1;
  const int ns = def.sectors;
  std::vector<double> cell(std::size_t(nbins) * ns, -1e300);
  for (const auto& p : points) {
    if (!(p.s >= 0) || !std::isfinite(p.s) || p.sector < 0 || p.sector >= ns) continue;
    double& c = cell[std::size_t(int(p.s / def.bin)) * ns + p.sector];
    c = std::max(c, p.h);
  }
  std::vector<double> surf(nbins, -1e300);
  for (int b = 0; b < nbins; ++b) {
    double sum = 0;
    int n = 0;
    for (int k = 0; k < ns; ++k)
      if (cell[std::size_t(b) * ns + k] > -1e299) sum += cell[std::size_t(b) * ns + k], ++n;
    if (n > 0) surf[b] = sum / n;
  }
  const auto peak_it = std::max_element(surf.begin(), surf.end());
  out.peak = *peak_it;
  out.surface.resize(nbins);
  for (int b = 0; b < nbins; ++b) out.surface[b] = surf[b] > -1e299 ? surf[b] : -1.0;
  // the outer flank: from the peak bin outwards up to the first bin at or below the toe
  // level (or empty); bins above the top level are left out
  std::vector<std::pair<double, double>> used;
  for (int b = def.outer_run ? int(peak_it - surf.begin()) + 1 : 0; b < nbins; ++b) {
    if (!(surf[b] > def.lo_frac * out.peak)) {
      if (def.outer_run) break;
      continue;
    }
    if (surf[b] >= def.hi_frac * out.peak) continue;
    used.push_back({def.bin * (b + 0.5), surf[b]});
  }
  out.points = int(used.size());
  const Line line = fit_line(used);
  if (!line.ok) return out;
  out.slope = line.slope;
  out.residual = line.residual;
  out.angle_deg = std::atan(-out.slope) * 180.0 / std::numbers::pi;
  return out;
}

ConeFit fit_cone_area(const std::vector<Vec3>& points, double radius, const ConeFitDef& def) {
  ConeFit out;
  if (!(def.cell > 0) || !(def.reach >= 0) || def.levels < 2 || !(radius > 0)) return out;
  const double R = radius + def.reach;
  if (R / def.cell > 1e4) return out;  // refuse a map of more than 1e8 cells
  const int n = int(2 * R / def.cell) + 1;
  std::vector<double> surf(std::size_t(n) * n, -1e300);
  double H = -1e300;
  for (const Vec3& p : points) {
    const double x = p.x, z = p.z, y = p.y;
    if (!(x * x + z * z <= radius * radius) || !std::isfinite(y)) continue;
    H = std::max(H, y);
    const int i0 = std::max(0, int((x - def.reach + R) / def.cell));
    const int i1 = std::min(n - 1, int((x + def.reach + R) / def.cell));
    const int k0 = std::max(0, int((z - def.reach + R) / def.cell));
    const int k1 = std::min(n - 1, int((z + def.reach + R) / def.cell));
    for (int k = k0; k <= k1; ++k)
      for (int i = i0; i <= i1; ++i) {
        const double cx = -R + (i + 0.5) * def.cell - x, cz = -R + (k + 0.5) * def.cell - z;
        if (cx * cx + cz * cz > def.reach * def.reach) continue;
        double& c = surf[std::size_t(k) * n + i];
        c = std::max(c, y);
      }
  }
  if (!(H > 0)) return out;
  out.height = H;
  std::vector<double> hs;
  for (double c : surf)
    if (c > -1e299) hs.push_back(c);
  std::sort(hs.begin(), hs.end());
  std::vector<std::pair<double, double>> used;  // (r(z), z)
  for (int l = 0; l < def.levels; ++l) {
    const double z = H * (def.lo_frac + (def.hi_frac - def.lo_frac) * l / (def.levels - 1));
    const double cells = double(hs.end() - std::upper_bound(hs.begin(), hs.end(), z));
    used.push_back({std::sqrt(cells * def.cell * def.cell / std::numbers::pi), z});
  }
  const Line line = fit_line(used);
  if (!line.ok) return out;
  out.levels = int(used.size());
  out.slope = line.slope;
  out.residual = line.residual;
  out.angle_deg = std::atan(-out.slope) * 180.0 / std::numbers::pi;
  return out;
}

Status validate(const PileDef& pd) {
  auto bad = [](const char* f, double v, const char* allowed) {
    return Error{"", std::string("PileDef.") + f, format_number(v), allowed, ""};
  };
  if (pd.granules < 1) return bad("granules", pd.granules, "must be >= 1");
  if (pd.batch != 1 && pd.batch != 7 && pd.batch != 19 && pd.batch != 37)
    return bad("batch", pd.batch, "must be 1, 7, 19 or 37 (full hexagonal rings)");
  if (!(pd.batch_interval > 0)) return bad("batch_interval", pd.batch_interval, "must be > 0 (s)");
  if (!(pd.frame_dt > 0)) return bad("frame_dt", pd.frame_dt, "must be > 0 (s)");
  if (!(pd.max_relax >= 0)) return bad("max_relax", pd.max_relax, "must be >= 0 (s)");
  if (!(pd.floor_radius > 0)) return bad("floor_radius", pd.floor_radius, "must be > 0 (m)");
  if (!(pd.fit.bin > 0)) return bad("fit.bin", pd.fit.bin, "must be > 0 (m)");
  if (pd.fit.sectors < 1) return bad("fit.sectors", pd.fit.sectors, "must be >= 1");
  if (!(pd.cone.cell > 0)) return bad("cone.cell", pd.cone.cell, "must be > 0 (m)");
  if (!(pd.cone.reach >= 0)) return bad("cone.reach", pd.cone.reach, "must be >= 0 (m)");
  if (pd.cone.levels < 2) return bad("cone.levels", pd.cone.levels, "must be >= 2");
  if (!(pd.cone.lo_frac >= 0 && pd.cone.lo_frac < pd.cone.hi_frac && pd.cone.hi_frac <= 1))
    return bad("cone.lo_frac", pd.cone.lo_frac, "must satisfy 0 <= lo_frac < hi_frac <= 1");
  return Ok{};
}

ShellDef pile_floor(const PileDef& pd) {
  const float r = pd.particle_radius;
  const float R = pd.floor_radius;
  // rough floor: spheres of radius r, square lattice of spacing 2 r, centres at y = 0
  ShellDef floor;
  floor.motion = MotionType::Static;
  floor.radii = {r};
  const int nl = int(R / (2 * r));
  for (int i = -nl; i <= nl; ++i)
    for (int k = -nl; k <= nl; ++k) {
      const float x = 2 * r * i, z = 2 * r * k;
      if (x * x + z * z <= R * R) floor.offsets.push_back({x, 0, z});
    }
  return floor;
}

SimulationDef pile_simulation_def(const PileDef& pd) {
  const float r = pd.particle_radius;
  const float R = pd.floor_radius;
  SimulationDef d;
  d.material = pd.material;
  d.particle_radius = r;
  d.max_bodies = pd.granules + 1;
  d.max_particles = 4 * pd.granules + int(pile_floor(pd).offsets.size());
  d.bounds_min = {-R - 4 * r, -2 * r, -R - 4 * r};
  d.bounds_max = {R + 4 * r, 0.5f * R + 0.1f, R + 4 * r};
  d.floor_height = -r;  // bedrock under the rough layer (granules that roll off the disc)
  d.sleep_time = 0;
  d.threads = pd.threads;
  return d;
}

namespace pile_detail {
Quat random_orientation(std::uint64_t& s) {  // uniform (Shoemake)
  double u1 = uniform(s), u2 = uniform(s), u3 = uniform(s);
  double r1 = std::sqrt(1 - u1), r2 = std::sqrt(u1), t1 = 2 * std::numbers::pi * u2, t2 = 2 * std::numbers::pi * u3;
  return {float(r1 * std::sin(t1)), float(r1 * std::cos(t1)), float(r2 * std::sin(t2)), float(r2 * std::cos(t2))};
}
double uniform01(std::uint64_t& s) { return uniform(s); }

void fit_pile(const PileDef& pd, const std::vector<Vec3>& pos, int floor_spheres, ReposeResult& out) {
  const float R = pd.floor_radius;
  // surface: granule sphere tops above the top of the rough layer (y = r), s measured from
  // the pile's axis: the vertical through the centroid of the granules on the disc (the pour
  // is centred on x = z = 0, but a pile can lean by a few mm; spheres off the disc are left
  // out of the centroid and of the fit)
  std::vector<SurfacePoint> pts;
  double cx = 0, cz = 0;
  int nc = 0;
  for (int i = floor_spheres; i < int(pos.size()); ++i)
    if (double(pos[i].x) * pos[i].x + double(pos[i].z) * pos[i].z <= double(R) * R) cx += pos[i].x, cz += pos[i].z, ++nc;
  if (nc > 0) cx /= nc, cz /= nc;
  out.axis_x = cx, out.axis_z = cz;
  for (int i = floor_spheres; i < int(pos.size()); ++i) {
    const Vec3 x = pos[i];
    if (double(x.x) * x.x + double(x.z) * x.z > double(R) * R) continue;  // rolled off the disc
    const double dx = x.x - cx, dz = x.z - cz;
    SurfacePoint sp;
    sp.s = std::sqrt(dx * dx + dz * dz);
    sp.h = double(x.y);  // sphere top y + r, minus the top of the rough layer r
    double phi = std::atan2(dz, dx) + std::numbers::pi;  // [0, 2 pi]
    sp.sector = std::min(pd.fit.sectors - 1, int(phi / (2 * std::numbers::pi) * pd.fit.sectors));
    pts.push_back(sp);
  }
  const FlankFit fit = fit_flank(pts, pd.fit);
  out.flank_angle_deg = fit.angle_deg;
  out.flank_residual = fit.residual;
  out.flank_points = fit.points;
  out.peak = fit.peak;
  // the angle: the cone fit over the granules' sphere centres on the disc (axis-free)
  std::vector<Vec3> cen(pos.begin() + floor_spheres, pos.end());
  const ConeFit cone = fit_cone_area(cen, R, pd.cone);
  out.angle_deg = cone.angle_deg;
  out.residual = cone.residual;
  out.fit_points = cone.levels;
  out.profile = fit.surface;
  out.spheres.assign(pos.begin() + floor_spheres, pos.end());
}
}  // namespace pile_detail

Result<ReposeResult> measure_repose(const PileDef& pd) {
  if (auto v = validate(pd); !v) return v.errors();
  auto sim = Simulation::create(pile_simulation_def(pd));
  if (!sim) return sim.errors();
  return pour_pile(*sim, pd);
}

}  // namespace sandpatch
