// Sphere impacts against experiments (bench/impact.hpp, docs/validation.md).
#include "bench/impact.hpp"

#include <algorithm>
#include <cmath>

namespace sandpatch {

double repose_deg(double friction) {
  static constexpr double kMu[] = {0.2, 0.35, 0.5, 0.7, 1.0}, kDeg[] = {29.0, 33.8, 35.9, 38.0, 36.7};
  if (!(friction >= kMu[0] && friction <= kMu[4])) return 0;
  for (int j = 0; j < 5; ++j)
    if (friction == kMu[j]) return kDeg[j];  // (a measured friction: its angle exactly)
  int i = 0;
  while (i < 3 && friction > kMu[i + 1]) ++i;
  return kDeg[i] + (kDeg[i + 1] - kDeg[i]) * (friction - kMu[i]) / (kMu[i + 1] - kMu[i]);
}

double repose_mu(double friction) {
  const double deg = repose_deg(friction);
  return deg > 0 ? std::tan(deg * 3.14159265358979 / 180.0) : 0;
}

double uehara_depth(double mu, double rho_b, double rho_g, double diameter, double h) {
  if (!(mu > 0) || !(rho_b > 0) || !(rho_g > 0) || !(diameter > 0) || !(h >= 0)) return 0;
  const double c = 0.14 / mu * std::sqrt(rho_b / rho_g) * std::cbrt(diameter * diameter);
  double d = c * std::cbrt(h + 1e-12);
  for (int k = 0; k < 200; ++k) {
    const double next = c * std::cbrt(h + d);
    if (std::abs(next - d) < 1e-12) return next;
    d = next;
  }
  return d;
}

double uehara_prefactor(double mu, double rho_b, double rho_g, double diameter, double depth, double total_drop) {
  if (!(mu > 0) || !(rho_b > 0) || !(rho_g > 0) || !(diameter > 0) || !(depth >= 0) || !(total_drop > 0)) return 0;
  return depth * mu / (std::sqrt(rho_b / rho_g) * std::cbrt(diameter * diameter) * std::cbrt(total_drop));
}

Result<ImpactSeries> run_impact_series(const ImpactSeriesDef& def) {
  ImpactSeries out;
  const double shell = double(def.base.granule_radius) * def.knobs.particle_scale;
  auto one = [&](double h, double rho) -> Result<ImpactPoint> {
    DropDef d = def.base;
    d.drop_height = h;
    d.sphere_density = rho;
    d.run_seconds = std::sqrt(2 * h / 9.81) + def.settle_after;
    auto r = measure_drop(d, def.knobs);
    if (!r) return r.errors();
    if (r->refused) return Error{"", "ImpactSeriesDef.knobs.granules_per_slot", std::to_string(def.knobs.granules_per_slot),
                                 "large enough for the patch", r->refusal};
    ImpactPoint p;
    p.drop_height = h;
    p.density = rho;
    p.depth = r->sphere_sink + shell;
    p.total_drop = h + p.depth;
    p.drop = std::move(*r);
    p.drop.frames.clear();
    out.worst_rebound = std::max(out.worst_rebound, p.drop.rebound_ratio);
    return p;
  };
  std::vector<double> H, dH, rho, drho;
  for (double h : def.heights) {
    auto p = one(h, def.base.sphere_density);
    if (!p) return p.errors();
    H.push_back(p->total_drop), dH.push_back(p->depth);
    out.by_height.push_back(std::move(*p));
  }
  for (double r : def.densities) {
    auto p = one(def.density_height, r);
    if (!p) return p.errors();
    rho.push_back(r), drho.push_back(p->depth);
    out.by_density.push_back(std::move(*p));
  }
  const ImpactPoint* first = !out.by_height.empty() ? &out.by_height.front() : !out.by_density.empty() ? &out.by_density.front() : nullptr;
  if (first) {
    const double r = def.base.granule_radius * def.knobs.particle_scale;
    const double mg = 4.0 * def.base.granule_density * 4.0 / 3.0 * 3.14159265358979 * r * r * r;
    out.bulk_density = first->drop.granules * mg / (def.base.terrain_side * def.base.terrain_side * def.base.patch_depth);
  }
  out.depth_vs_total_drop = fit_power_law(H, dH);
  out.depth_vs_density = fit_power_law(rho, drho);
  return out;
}

}  // namespace sandpatch
