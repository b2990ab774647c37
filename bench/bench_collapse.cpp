// bench collapse: quasi-2D granular column collapse against the published scalings
// (bench/collapse.hpp for the geometry and the measures; docs/validation.md for the
// comparison).
#include "bench/collapse.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "bench/bench_util.hpp"
#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "particles/granule.hpp"

namespace sandpatch {

namespace {

constexpr double kG = 9.81;  // m/s^2
// Settled column height per lattice layer, in lattice spacings: the lattice is loose (centres
// 1.02 bounding diameters apart) and compacts as it settles. Only used to choose the number of
// layers for a target aspect ratio; the measured H0 gives the reported a.
constexpr double kSettledLayer = 0.45;

Error def_error(const char* field, double v, const std::string& allowed) {
  return Error{"", std::string("CollapseDef.") + field, format_number(v), allowed, ""};
}

struct Deposit {
  double l_inf = 0, h_inf = 0;
  int ejected = 0;
  std::vector<double> profile;
};

// The deposit of the granule spheres `p` (sphere radius r, bin width d): see collapse.hpp.
Deposit measure(const std::vector<Vec3>& p, const std::vector<Vec3>& centres, double r, double d) {
  Deposit out;
  double xmax = 0;
  for (const Vec3& q : p) xmax = std::max(xmax, double(q.x));
  const int nb = int(std::min(1e6, std::floor(std::max(0.0, xmax) / d))) + 1;
  std::vector<double> top(nb, -1.0), edge(nb, -1.0);
  for (const Vec3& q : p) {
    const int b = std::clamp(int(std::floor(std::max(0.0, double(q.x)) / d)), 0, nb - 1);
    top[b] = std::max(top[b], double(q.y) + r);
    edge[b] = std::max(edge[b], double(q.x) + r);
  }
  int last = -1;
  for (int b = 0; b < nb; ++b) {
    if (top[b] >= 0) {
      last = b;
    } else if (b + 1 < nb && top[b + 1] < 0) {
      break;  // two empty bins in a row: the deposit ended at `last`
    }
  }
  for (int b = 0; b <= last; ++b) {
    out.h_inf = std::max(out.h_inf, top[b]);
    out.l_inf = std::max(out.l_inf, edge[b]);
  }
  out.profile.assign(top.begin(), top.begin() + (last + 1));
  for (const Vec3& c : centres)
    if (c.x > out.l_inf) ++out.ejected;
  return out;
}

}  // namespace

Status check_collapse(const CollapseDef& c) {
  std::vector<Error> es;
  if (!(c.aspect >= 0.2 && c.aspect <= 16)) es.push_back(def_error("aspect", c.aspect, "must be in [0.2, 16]"));
  if (c.length_granules < 2 || c.length_granules > 64)
    es.push_back(def_error("length_granules", c.length_granules, "must be in [2, 64] lattice columns"));
  if (c.width_granules < 1 || c.width_granules > 32)
    es.push_back(def_error("width_granules", c.width_granules, "must be in [1, 32] lattice columns"));
  if (!(c.particle_radius > 1e-4f && c.particle_radius <= 1.0f))
    es.push_back(def_error("particle_radius", c.particle_radius, "must be in (1e-4, 1] m"));
  if (!(c.friction >= 0 && c.friction <= 2)) es.push_back(def_error("friction", c.friction, "must be in [0, 2]"));
  if (!(c.unloading >= 1 && c.unloading <= 100)) es.push_back(def_error("unloading", c.unloading, "must be in [1, 100]"));
  if (!(c.restitution <= 1)) es.push_back(def_error("restitution", c.restitution, "must be in [0, 1], or < 0 for the law's default"));
  if (!(c.frame_dt > 0 && c.frame_dt <= 0.02)) es.push_back(def_error("frame_dt", c.frame_dt, "must be in (0, 0.02] s"));
  if (!(c.max_settle >= 0.1 && c.max_settle <= 10))
    es.push_back(def_error("max_settle", c.max_settle, "must be in [0.1, 10] s"));
  if (!(c.max_flow >= 0.1 && c.max_flow <= 30)) es.push_back(def_error("max_flow", c.max_flow, "must be in [0.1, 30] s"));
  if (!(c.rest_speed > 0 && c.rest_speed <= 1)) es.push_back(def_error("rest_speed", c.rest_speed, "must be in (0, 1] m/s"));
  if (c.threads < 0) es.push_back(def_error("threads", c.threads, "must be >= 0 (0 = OpenMP's default)"));
  if (!es.empty()) return es;
  // the column's granules (capacity): refuse before allocating
  const double layers = std::ceil(c.aspect * c.length_granules / kSettledLayer);
  const double n = layers * c.length_granules * c.width_granules;
  if (n > 200000)
    return Error{"", "CollapseDef.aspect", format_number(c.aspect),
                 "with length_granules x width_granules = " + std::to_string(c.length_granules * c.width_granules) +
                     " needs " + format_number(n) + " granules: at most 200000",
                 ""};
  return Ok{};
}

Result<CollapseResult> run_collapse(const CollapseDef& c) {
  if (auto st = check_collapse(c); !st) return st.errors();
  const auto wall0 = std::chrono::steady_clock::now();
  const float r = c.particle_radius;
  SimulationDef def;
  def.particle_radius = r;
  def.material.friction = c.friction;  // the other material fields: the defaults (docs/dem.md)
  if (c.unloading > 1.0f) {  // the hysteretic spring, by default e = 1/sqrt(unloading) from it alone
    def.material.unloading_stiffness_ratio = c.unloading;
    def.material.restitution = 1.0f;
  }
  if (c.restitution >= 0) def.material.restitution = c.restitution;
  def.threads = c.threads;
  def.sleep_time = 1e9f;  // never asleep: the run ends on its own rest test
  const GranuleShape shape = make_granule_shape(r, def.granule_edge_factor, def.material.density);
  const double d = 2.0 * (shape.centre_distance + shape.radius);  // bounding diameter, m
  const float s = float(d * 1.02);                                // lattice spacing, m
  const int nx = c.length_granules, nz = c.width_granules;
  const int layers = std::max(1, int(std::lround(c.aspect * nx / kSettledLayer)));
  const int n = nx * nz * layers;
  const float L0 = nx * s, W = nz * s;
  LatticeBedDef bed;
  bed.nx = nx;
  bed.nz = nz;
  bed.layers = layers;
  bed.spacing = s;
  bed.seed = c.seed;
  bed.min = {0.5f * s, shape.centre_distance + r + 1e-4f, 0.5f * s};
  const float lattice_top = bed.min.y + (layers - 1) * s + 0.5f * s;

  // the gate: a static shell of spheres of radius r, centres on the plane x = L0 + r at
  // spacing 1.5 r (closer than a sphere diameter: no granule sphere passes between them)
  ShellDef gate;
  gate.motion = MotionType::Static;
  gate.radii = {r};
  const int gz = int(std::ceil(W / (1.5f * r))) + 1, gy = int(std::ceil((lattice_top + s) / (1.5f * r))) + 1;
  const Vec3 gate_centre{L0 + r, 0.5f * (lattice_top + s), 0.5f * W};
  for (int iy = 0; iy < gy; ++iy)
    for (int iz = 0; iz < gz; ++iz) {
      const float y = (lattice_top + s) * iy / float(gy - 1), z = W * iz / float(gz - 1);
      gate.offsets.push_back({0.0f, y - gate_centre.y, z - gate_centre.z});
    }
  gate.position = gate_centre;

  def.max_bodies = n + 1;
  def.max_particles = 4 * n + int(gate.offsets.size());
  def.bounds_min = {0, 0, 0};
  // room for the runout: l_inf / L0 stays well below 3 + 3 a in every run measured
  def.bounds_max = {float(L0 * (3.0 + 3.0 * c.aspect)), lattice_top + s, W};
  def.side_walls = true;
  auto sim = Simulation::create(def);
  if (!sim) return sim.errors();
  if (auto st = add_lattice_bed(*sim, bed); !st) return st.errors();
  auto gate_id = sim->add_shell(gate);
  if (!gate_id) return gate_id.errors();

  CollapseResult res;
  res.granules = n;
  res.L0 = L0;
  res.W = W;
  res.d = d;
  auto count_step = [&] { res.sphere_steps += std::int64_t(4) * n * sim->last_step().substeps; };
  auto granule_spheres = [&] {
    std::vector<Vec3> p = sim->particle_positions();
    p.resize(std::size_t(4) * n);  // granules first (added before the gate)
    return p;
  };
  auto granule_centres = [&] {
    std::vector<Vec3> v(n);
    for (int i = 0; i < n; ++i) v[i] = sim->body_position(BodyId{i});
    return v;
  };

  // settle inside the walls and the gate
  const int max_settle = int(std::ceil(c.max_settle / c.frame_dt));
  int f = 0;
  for (; f < max_settle; ++f) {
    if (auto st = sim->step(c.frame_dt); !st) return st.errors();
    count_step();
    if ((f + 1) * c.frame_dt >= 0.3 && sim->max_granule_speed() < 0.5 * c.rest_speed) break;
  }
  res.settle_time = std::min(f + 1, max_settle) * c.frame_dt;
  {
    const Deposit col = measure(granule_spheres(), granule_centres(), r, d);
    res.H0 = col.h_inf;
    res.aspect = res.H0 / L0;
  }

  // release: the gate is gone at t = 0
  if (auto st = sim->set_body_enabled(*gate_id, false); !st) return st.errors();
  sim->wake();
  const double t_free = std::sqrt(res.H0 / kG);  // s
  const int max_flow = int(std::ceil(c.max_flow / c.frame_dt));
  const int every = std::max(1, int(std::lround(0.01 / c.frame_dt)));  // front checked every 10 ms
  double front_moved = 0;  // l_inf when the front last moved by more than 1 % of L0
  double height_moved = res.H0, t_height = 0;  // h_inf, time when it last moved by 1 % of L0
  for (f = 0; f < max_flow; ++f) {
    if (auto st = sim->step(c.frame_dt); !st) return st.errors();
    count_step();
    const double t = (f + 1) * c.frame_dt;
    if ((f + 1) % every) continue;
    const Deposit dep = measure(granule_spheres(), {}, r, d);
    if (std::fabs(dep.l_inf - front_moved) > 0.01 * L0) {
      front_moved = dep.l_inf;
      res.t_stop = t;
    }
    if (std::fabs(dep.h_inf - height_moved) > 0.01 * L0) {
      height_moved = dep.h_inf;
      t_height = t;
    }
    res.at_rest = t > 0.1 && sim->max_granule_speed() < c.rest_speed;
    // at rest, or neither the front nor the height has moved for 0.3 s after 3 free-fall
    // times: done
    if (res.at_rest || (t > 3 * t_free && t - std::max(res.t_stop, t_height) > 0.3)) {
      ++f;
      break;
    }
  }
  res.t_flow = std::min(f, max_flow) * c.frame_dt;
  const Deposit dep = measure(granule_spheres(), granule_centres(), r, d);
  if (dep.l_inf > def.bounds_max.x - 2 * d)
    return Error{"", "CollapseDef.aspect", format_number(c.aspect),
                 "the deposit reached the far wall (x = " + format_number(def.bounds_max.x) + " m)", ""};
  res.l_inf = dep.l_inf;
  res.h_inf = dep.h_inf;
  res.ejected = dep.ejected;
  res.profile = dep.profile;
  res.runout = (res.l_inf - L0) / L0;
  res.height = res.h_inf / L0;
  res.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  return res;
}


nlohmann::json collapse_json(const CollapseResult& r) {
  return {{"granules", r.granules},     {"L0", r.L0},         {"W", r.W},           {"d", r.d},
          {"H0", r.H0},                 {"aspect", r.aspect}, {"l_inf", r.l_inf},   {"h_inf", r.h_inf},
          {"runout", r.runout},         {"height", r.height}, {"ejected", r.ejected}, {"settle_time", r.settle_time},
          {"t_stop", r.t_stop},         {"t_flow", r.t_flow}, {"at_rest", r.at_rest}, {"wall_seconds", r.wall_seconds},
          {"sphere_steps", r.sphere_steps}};
}

std::string check_bench_collapse_args(const BenchCollapseArgs& a) {
  if (a.aspects.empty()) return "bench collapse: --aspects is empty: give aspect ratios in [0.2, 16]";
  for (double v : a.aspects)
    if (!(v >= 0.2 && v <= 16))
      return "bench collapse: --aspects: " + format_number(v) + ": each must be in [0.2, 16]";
  if (a.frictions.empty()) return "bench collapse: --friction is empty: give friction coefficients in [0, 2]";
  for (float v : a.frictions)
    if (!(v >= 0 && v <= 2)) return "bench collapse: --friction = " + format_number(v) + ": must be in [0, 2]";
  if (a.length_granules < 2 || a.length_granules > 64)
    return "bench collapse: --length = " + std::to_string(a.length_granules) + ": must be in [2, 64]";
  if (a.width_granules < 1 || a.width_granules > 32)
    return "bench collapse: --width = " + std::to_string(a.width_granules) + ": must be in [1, 32]";
  if (!(a.split > 0)) return "bench collapse: --split = " + format_number(a.split) + ": must be > 0";
  if (a.threads < 0) return "bench collapse: --threads = " + std::to_string(a.threads) + ": must be >= 0";
  return "";
}

int run_bench_collapse(const BenchCollapseArgs& a) {
  if (const std::string m = check_bench_collapse_args(a); !m.empty()) {
    std::fprintf(stderr, "%s\n", m.c_str());
    return 2;
  }
  nlohmann::json out = {{"bench", "collapse"}, {"sweeps", nlohmann::json::array()}};
  const double load0 = bench::load_average();
  for (float mu : a.frictions) {
    if (!a.json)
      std::printf("bench collapse: mu = %.2f, L0 = %d lattice columns, slot %d wide, seed %llu, %d thread(s), unloading ratio %g, restitution %g\n",
                  mu, a.length_granules, a.width_granules, (unsigned long long)a.seed, a.threads, double(a.unloading),
                  a.restitution >= 0 ? double(a.restitution) : (a.unloading > 1.0f ? 1.0 : 0.3));
    if (!a.json)
      std::printf("%6s %6s %7s %6s %7s %8s %7s %7s %6s %9s %4s %4s %6s %7s %7s %6s\n", "a_tgt", "N", "H0[m]", "a", "l_inf",
                  "dL/L0", "h/L0", "h/H0", "t_stop", "t/sqrtH/g", "ej", "rest", "settle", "wall[s]", "Lube05", "ratio");
    std::vector<double> as, runs, hs;
    nlohmann::json rows = nlohmann::json::array();
    for (double asp : a.aspects) {
      CollapseDef c;
      c.aspect = asp;
      c.friction = mu;
      c.unloading = a.unloading;
      c.restitution = a.restitution;
      c.length_granules = a.length_granules;
      c.width_granules = a.width_granules;
      c.threads = a.threads;
      c.seed = a.seed;
      auto r = run_collapse(c);
      if (!r) {
        std::fprintf(stderr, "bench collapse: %s", r.message().c_str());
        return 1;
      }
      as.push_back(r->aspect);
      runs.push_back(r->runout);
      hs.push_back(r->height);
      // the planar law of Lube et al. (2005) in the run's regime: 1.2 a (low), 1.9 a^(2/3) (high)
      const double law = asp <= a.split ? 1.2 * r->aspect : 1.9 * std::pow(r->aspect, 2.0 / 3.0);
      nlohmann::json j = collapse_json(*r);
      j["lube2005_runout"] = law;
      j["aspect_target"] = asp;
      rows.push_back(j);
      if (!a.json && rows.size() == 1)
        std::printf("  L0 = %.4f m, slot W = %.4f m, granule bounding diameter d = %.4f m (L0 = %.1f d, W = %.1f d)\n",
                    r->L0, r->W, r->d, r->L0 / r->d, r->W / r->d);
      if (!a.json) {
        std::printf("%6.2f %6d %7.3f %6.2f %7.3f %8.3f %7.3f %7.3f %6.2f %9.2f %4d %4s %6.2f %7.1f %7.3f %6.2f\n", asp, r->granules,
                    r->H0, r->aspect, r->l_inf, r->runout, r->height, r->h_inf / r->H0, r->t_stop,
                    r->t_stop / std::sqrt(r->H0 / kG), r->ejected, r->at_rest ? "yes" : "no", r->settle_time, r->wall_seconds, law, r->runout / law);
        std::fflush(stdout);
      }
    }
    auto fj = [](const PowerFit& f) {
      return nlohmann::json{{"exponent", f.exponent},   {"exponent_se", f.exponent_se}, {"prefactor", f.prefactor},
                            {"log_prefactor_se", f.log_prefactor_se}, {"points", f.points}};
    };
    // the regimes are split on the target aspect ratios (a measured a near the split would
    // otherwise move a run from one fit to the other between frictions or seeds)
    std::vector<double> a_lo, a_hi, r_lo, r_hi, h_hi_v;
    for (std::size_t i = 0; i < as.size(); ++i) {
      const bool low = a.aspects[i] <= a.split;
      (low ? a_lo : a_hi).push_back(as[i]);
      (low ? r_lo : r_hi).push_back(runs[i]);
      if (!low) h_hi_v.push_back(hs[i]);
    }
    const PowerFit all = fit_power_law(as, runs), lo = fit_power_law(a_lo, r_lo), hi = fit_power_law(a_hi, r_hi),
                   h_hi = fit_power_law(a_hi, h_hi_v);
    if (!a.json) {
      auto pr = [](const char* what, const PowerFit& f) {
        std::printf("  %-34s exponent %.3f +- %.3f, prefactor %.3f (ln k +- %.3f), %d points\n", what, f.exponent,
                    f.exponent_se, f.prefactor, f.log_prefactor_se, f.points);
      };
      pr("(l_inf - L0)/L0 = k a^n, all a:", all);
      std::printf("  %-34s target a <= %.2f and > %.2f:\n", "", a.split, a.split);
      pr("  (l_inf - L0)/L0, low a:", lo);
      pr("  (l_inf - L0)/L0, high a:", hi);
      pr("h_inf/L0 = k a^n, high a:", h_hi);
      std::printf("  published: Lube et al. 2005 (planar): (l_inf - L0)/L0 = 1.2 a (small a), 1.9 a^(2/3) (large a); "
                  "Balmforth & Kerswell 2005: runout exponent 0.65 +- 0.05 (narrow slots), 0.9 +- 0.1 (wide "
                  "channels); H0/h_inf ~ a^0.5 (narrow), a^0.6 (wide), i.e. h_inf/L0 ~ a^0.5, a^0.4\n");
    }
    out["sweeps"].push_back({{"friction", mu},
                             {"length_granules", a.length_granules},
                             {"width_granules", a.width_granules},
                             {"threads", a.threads},
                             {"seed", a.seed},
                             {"runs", rows},
                             {"fit_runout_all", fj(all)},
                             {"fit_runout_low", fj(lo)},
                             {"fit_runout_high", fj(hi)},
                             {"fit_height_high", fj(h_hi)},
                             {"split", a.split}});
  }
  out["load_before"] = load0;
  out["load_after"] = bench::load_average();
  if (a.json) std::printf("%s\n", out.dump().c_str());
  return 0;
}

}  // namespace sandpatch
