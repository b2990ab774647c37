// sandpatch_impact: one sphere dropped onto a flat granular terrain through the World and its
// TerrainManager (bench/tradeoff_drop.hpp, measure_drop), printed as one JSON object: the
// rebound, the sphere's final depth, the crater left in the heightfield after demotion and,
// with --trace, the sphere per frame. The experiments of docs/validation.md run it.
//   sandpatch_impact [--radius R] [--density RHO] [--height H] [--stiffness KN] [--granule-radius r]
//                    [--granule-density RHO_G] [--friction MU] [--restitution E] [--depth D]
//                    [--unloading LAMBDA] [--side L] [--spacing S] [--frame-dt DT] [--seconds T] [--scale s]
//                    [--steps-per-contact N] [--substeps K] [--seed N] [--threads N] [--trace]
//                    [--series [--repose-deg DEG]]
// Units: m, kg/m^3, N/m, s. Exit 0 ok, 1 runtime failure, 2 bad arguments.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "bench/bench_tradeoff.hpp"
#include "bench/impact.hpp"
#include "bench/tradeoff_drop.hpp"

using namespace sandpatch;

namespace {

// --dem: the same drop straight on the DEM (measure_crater: a walled patch of the terrain's
// side, the bed patch_depth deep, the sphere released just above the surface at sqrt(2 g H)),
// with the energy ledger per frame (--trace).
int run_dem(const DropDef& d, const TradeoffKnobs& k) {
  CraterDef c;
  c.sphere_radius = d.sphere_radius;
  c.sphere_density = d.sphere_density;
  c.drop_height = d.drop_height;
  c.bed_depth_radii = d.patch_depth / d.sphere_radius;
  c.impact_seconds = d.run_seconds;
  c.granule_radius = d.granule_radius;
  c.material.density = d.granule_density;
  c.material.friction = d.friction;
  c.material.restitution = d.restitution;
  c.material.normal_stiffness = d.stiffness;
  c.material.unloading_stiffness_ratio = d.unloading_ratio;
  c.knobs = k;
  c.knobs.patch_radii = d.terrain_side / d.sphere_radius;
  c.knobs.seed = d.settle_seed ? d.settle_seed : 1;
  c.threads = d.threads;
  c.trace = true;
  c.frame_dt = d.frame_dt;
  auto r = measure_crater(c);
  if (!r) {
    std::cerr << "sandpatch_impact: " << r.message() << "\n";
    return 1;
  }
  const double v_in = std::sqrt(2 * 9.81 * d.drop_height);
  double v_out = 0, deepest = 0, top_after = -1e9;
  bool turned = false;
  for (const CraterFrame& f : r->frames) {
    deepest = std::max(deepest, -f.bottom);
    if (f.t > 0.02 && f.vy >= 0) turned = true;
    if (turned) v_out = std::max(v_out, f.vy), top_after = std::max(top_after, f.bottom);
  }
  nlohmann::ordered_json j;
  j["radius"] = d.sphere_radius;
  j["density"] = d.sphere_density;
  j["height"] = d.drop_height;
  j["impact_speed"] = v_in;
  j["rebound_speed"] = v_out;
  j["rebound_ratio"] = v_out / v_in;
  j["rebound_bottom"] = top_after;
  j["deepest"] = deepest;
  j["sphere_sink"] = r->sphere_sink;
  j["crater_depth"] = r->depth;
  j["granules"] = r->granules;
  j["dt"] = r->dt;
  j["wall_s"] = r->wall_seconds;
  j["setup_s"] = r->setup_seconds;
  if (d.trace) {
    auto& fr = j["frames"];
    fr = nlohmann::json::array();
    for (const CraterFrame& f : r->frames)
      fr.push_back({f.t, f.bottom, f.vy, f.body_kinetic, f.body_potential, f.bed_kinetic, f.bed_potential, f.elastic,
                    f.normal_damping, f.friction, f.elastic_tangential});
  }
  std::cout << j.dump() << "\n";
  return 0;
}

// --series: docs/validation.md's series (drop heights 0.05 ... 0.8 m at the given density, and
// densities 800, 2500, 7800 kg/m^3 from 0.2 m), one JSON line per point, then the fits against
// Uehara et al. (2003), with mu = tan(repose_deg), the bed's angle of repose.
int run_series(const DropDef& d, const TradeoffKnobs& k, double repose_deg) {
  ImpactSeriesDef sd;
  sd.base = d;
  sd.knobs = k;
  sd.heights = {0.05, 0.1, 0.2, 0.4, 0.8};
  sd.densities = {800, 2500, 7800};
  sd.density_height = 0.2;
  auto r = run_impact_series(sd);
  if (!r) {
    std::cerr << "sandpatch_impact: " << r.message() << "\n";
    return 1;
  }
  const double mu = std::tan(repose_deg * 3.14159265358979 / 180.0);
  const double Db = 2 * (d.sphere_radius + double(d.granule_radius) * k.particle_scale);
  auto point = [&](const ImpactPoint& p) {
    nlohmann::ordered_json j;
    j["h"] = p.drop_height;
    j["rho_b"] = p.density;
    j["depth"] = p.depth;
    j["H"] = p.total_drop;
    j["uehara_depth"] = uehara_depth(mu, p.density, r->bulk_density, Db, p.drop_height);
    j["impact_speed"] = p.drop.impact_speed;
    j["rebound_ratio"] = p.drop.rebound_ratio;
    j["rebound_bottom"] = p.drop.rebound_bottom;
    j["crater_depth"] = p.drop.depth;
    j["stop_time_ratio"] = p.drop.stop_time_ratio;
    j["peak_force_at"] = p.drop.peak_force_at;
    j["wall_s"] = p.drop.wall_seconds;
    std::cout << j.dump() << "\n";
  };
  for (const ImpactPoint& p : r->by_height) point(p);
  for (const ImpactPoint& p : r->by_density) point(p);
  // The series' distinct points (the density series' point at the height series' density is
  // one of the height series').
  std::vector<const ImpactPoint*> distinct;
  for (const ImpactPoint& p : r->by_height) distinct.push_back(&p);
  for (const ImpactPoint& p : r->by_density)
    if (std::none_of(r->by_height.begin(), r->by_height.end(),
                     [&](const ImpactPoint& q) { return q.drop_height == p.drop_height && q.density == p.density; }))
      distinct.push_back(&p);
  // Uehara's prefactor (0.14 in the experiments) each distinct point gives with the law's
  // exponents held: mean and standard deviation over the points.
  std::vector<double> A;
  for (const ImpactPoint* p : distinct)
    A.push_back(uehara_prefactor(mu, p->density, r->bulk_density, Db, p->depth, p->total_drop));
  // mean, standard deviation and count of a set of points' values
  auto mean_sd = [](const std::vector<double>& x) {
    double m = 0, v = 0;
    for (double a : x) m += a / double(x.size());
    for (double a : x) v += (a - m) * (a - m) / double(x.size() > 1 ? x.size() - 1 : 1);
    return nlohmann::ordered_json{{"mean", m}, {"sd", std::sqrt(v)}, {"n", x.size()}};
  };
  nlohmann::ordered_json f;
  f["bulk_density"] = r->bulk_density;
  f["repose_deg"] = repose_deg;  // the angle of repose Uehara's mu is taken from
  f["ball_diameter_soil"] = Db;
  f["depth_vs_H"] = {{"exponent", r->depth_vs_total_drop.exponent}, {"se", r->depth_vs_total_drop.exponent_se},
                     {"prefactor", r->depth_vs_total_drop.prefactor}, {"n", r->depth_vs_total_drop.points}};
  f["depth_vs_rho"] = {{"exponent", r->depth_vs_density.exponent}, {"se", r->depth_vs_density.exponent_se},
                       {"prefactor", r->depth_vs_density.prefactor}, {"n", r->depth_vs_density.points}};
  f["uehara_prefactor"] = mean_sd(A);
  f["uehara_prefactor"]["experiments"] = 0.14;
  f["worst_rebound"] = r->worst_rebound;
  // the stop's dynamics over the distinct points (Ambroso et al. 2005: t_stop v0 / d about 3,
  // the force largest at impact)
  {
    std::vector<double> ratio, peak;
    for (const ImpactPoint* p : distinct)
      if (p->drop.stop_time_ratio > 0) ratio.push_back(p->drop.stop_time_ratio), peak.push_back(p->drop.peak_force_at);
    if (!ratio.empty()) {
      f["stop_time_ratio"] = mean_sd(ratio);
      f["stop_time_ratio"]["experiments"] = 3.0;
      f["peak_force_at"] = mean_sd(peak);
    }
  }
  std::cout << f.dump() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  DropDef d;
  TradeoffKnobs k;
  k.lod = false;  // the whole terrain as one patch from t = 0
  d.frame_dt = 1.0 / 240.0;
  d.stiffness = 1.5e5f;
  d.threads = 1;
  d.max_substeps = 100000;
  bool dem = false, series = false;
  double repose_deg = 0;  // 0: from the friction (bench/impact.hpp repose_deg)
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--trace") {
      d.trace = true;
      continue;
    }
    if (a == "--dem") {
      dem = true;
      continue;
    }
    if (a == "--series") {
      series = true;
      continue;
    }
    if (i + 1 >= argc) {
      std::cerr << "sandpatch_impact: " << a << " needs a value\n";
      return 2;
    }
    char* end = nullptr;
    const double v = std::strtod(argv[++i], &end);
    if (!end || *end || !(v == v)) {
      std::cerr << "sandpatch_impact: " << a << " = " << argv[i] << ": not a number\n";
      return 2;
    }
    if (a == "--radius") d.sphere_radius = v;
    else if (a == "--density") d.sphere_density = v;
    else if (a == "--height") d.drop_height = v;
    else if (a == "--stiffness") d.stiffness = float(v);
    else if (a == "--granule-radius") d.granule_radius = float(v);
    else if (a == "--granule-density") d.granule_density = float(v);
    else if (a == "--friction") d.friction = float(v);
    else if (a == "--restitution") d.restitution = float(v);
    else if (a == "--unloading") d.unloading_ratio = float(v);
    else if (a == "--depth") d.patch_depth = v;
    else if (a == "--side") d.terrain_side = v;
    else if (a == "--spacing") d.spacing = float(v);
    else if (a == "--frame-dt") d.frame_dt = v;
    else if (a == "--seconds") d.run_seconds = v;
    else if (a == "--scale") k.particle_scale = v;
    else if (a == "--steps-per-contact") k.steps_per_contact = int(v);
    else if (a == "--substeps") k.substeps = int(v);
    else if (a == "--seed") d.settle_seed = std::uint64_t(v);
    else if (a == "--threads") d.threads = int(v);
    else if (a == "--slot") k.granules_per_slot = int(v);
    else if (a == "--after") d.after_demotion = v;
    else if (a == "--repose-deg") {
      if (!(v > 0 && v < 90)) {
        std::cerr << "sandpatch_impact: --repose-deg = " << argv[i] << ": must be an angle in (0, 90) degrees\n";
        return 2;
      }
      repose_deg = v;
    }
    else {
      std::cerr << "sandpatch_impact: unknown option " << a << "\n";
      return 2;
    }
  }
  if (dem) return run_dem(d, k);
  if (series) {
    if (repose_deg == 0) repose_deg = sandpatch::repose_deg(d.friction);
    if (repose_deg == 0) {
      std::cerr << "sandpatch_impact: --friction = " << d.friction
                << ": no measured angle of repose (docs/calibration.md measures 0.2 to 1): give --repose-deg\n";
      return 2;
    }
    return run_series(d, k, repose_deg);
  }
  auto r = measure_drop(d, k);
  if (!r) {
    std::cerr << "sandpatch_impact: " << r.message() << "\n";
    return 1;
  }
  if (r->refused) {
    std::cerr << "sandpatch_impact: " << r->refusal << "\n";
    return 1;
  }
  nlohmann::ordered_json j;
  j["radius"] = d.sphere_radius;
  j["density"] = d.sphere_density;
  j["height"] = d.drop_height;
  j["stiffness"] = d.stiffness;
  j["granule_radius"] = d.granule_radius;
  j["depth_bed"] = d.patch_depth;
  j["impact_speed"] = r->impact_speed;
  j["rebound_speed"] = r->rebound_speed;
  j["rebound_ratio"] = r->rebound_ratio;
  j["rebound_bottom"] = r->rebound_bottom;
  j["settle_time"] = r->settle_time;
  j["deepest"] = r->deepest;
  j["stop_time"] = r->stop_time;
  j["stop_penetration"] = r->stop_penetration;
  j["stop_time_ratio"] = r->stop_time_ratio;
  j["peak_force_at"] = r->peak_force_at;
  j["sphere_sink"] = r->sphere_sink;
  j["crater_depth"] = r->depth;
  j["axis_depth_after"] = r->axis_depth_after;
  j["shift_after_demotion"] = r->shift_after_demotion;
  j["far_field_dh"] = r->far_field_dh;
  j["granules"] = r->granules;
  j["dt"] = r->dt;
  j["wall_s"] = r->wall_seconds;
  j["setup_s"] = r->setup_seconds;
  if (d.trace) {
    auto& f = j["frames"];
    f = nlohmann::json::array();
    for (const DropFrame& fr : r->frames) f.push_back({fr.t, fr.bottom, fr.vy, fr.fy});
  }
  std::cout << j.dump() << "\n";
  return 0;
}
