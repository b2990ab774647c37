// bench terra: the plate-sinkage, shear and wheel tests of bench/terra.hpp in one run, the
// fits and the rigid-wheel model against the wheel rig (docs/validation.md "Terramechanics").
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "bench/bench_util.hpp"
#include "bench/terra.hpp"

namespace sandpatch::terra {

namespace {

std::string csv_series(const std::vector<std::string>& names, const std::vector<const std::vector<double>*>& cols) {
  std::ostringstream o;
  for (std::size_t i = 0; i < names.size(); ++i) o << (i ? "," : "") << names[i];
  o << "\n";
  const std::size_t n = cols.empty() ? 0 : cols[0]->size();
  for (std::size_t r = 0; r < n; ++r) {
    for (std::size_t i = 0; i < cols.size(); ++i) {
      char buf[32];
      std::snprintf(buf, sizeof buf, "%.6g", r < cols[i]->size() ? (*cols[i])[r] : NAN);
      o << (i ? "," : "") << buf;
    }
    o << "\n";
  }
  return o.str();
}

bool save(const BenchTerraArgs& a, const std::string& name, const std::string& text) {
  if (a.out.empty()) return true;
  std::error_code ec;
  std::filesystem::create_directories(a.out, ec);
  if (!bench::write_text(std::filesystem::path(a.out) / name, text)) {
    std::fprintf(stderr, "bench terra: cannot write %s/%s\n", a.out.c_str(), name.c_str());
    return false;
  }
  return true;
}

}  // namespace

std::string check_bench_terra_args(const BenchTerraArgs& a) {
  if (a.plates.size() < 2 || a.plates.size() > 6) return "--plates: give 2 to 6 plate widths (m)";
  for (double b : a.plates)
    if (!(b >= 0.1 && b <= 1.5)) return "--plates: " + std::to_string(b) + " m: each in [0.1, 1.5] m";
  if (a.sigmas.size() < 2 || a.sigmas.size() > 6) return "--sigmas: give 2 to 6 normal stresses (Pa)";
  for (double s : a.sigmas)
    if (!(s >= 100 && s <= 1e5)) return "--sigmas: " + std::to_string(s) + " Pa: each in [100, 1e5] Pa";
  if (a.slips.empty() || a.slips.size() > 12) return "--slips: give 1 to 12 slips";
  for (double s : a.slips)
    if (!(s >= 0 && s <= 0.9)) return "--slips: " + std::to_string(s) + ": each in [0, 0.9]";
  if (!(a.z_lo > 0 && a.z_hi > a.z_lo && a.z_hi <= 0.4)) return "--z-range: 0 < lo < hi <= 0.4 m";
  if (a.threads < 0) return "--threads: >= 0";
  if (!(a.bed_depth == 0 || (a.bed_depth >= 0.1 && a.bed_depth <= 2.0))) return "--bed-depth: 0 (the scene's) or in [0.1, 2] m";
  return "";
}

int run_bench_terra(const BenchTerraArgs& a) {
  if (std::string e = check_bench_terra_args(a); !e.empty()) {
    std::fprintf(stderr, "bench terra: %s\n", e.c_str());
    return 2;
  }
  std::setvbuf(stdout, nullptr, _IOLBF, 0);  // each table line as it comes (the runs take minutes)
  RigSetup setup;
  setup.scene = a.scene;
  setup.threads = a.threads;
  setup.bed_depth = a.bed_depth;
  nlohmann::ordered_json js;
  js["scene"] = a.scene;
  js["bed_depth"] = a.bed_depth;
  js["load_before"] = bench::load_average();
  const double cpu0 = bench::process_cpu_seconds();
  const auto wall0 = std::chrono::steady_clock::now();
  auto fail = [](const std::vector<Error>& es) {
    for (const Error& e : es) std::fprintf(stderr, "bench terra: %s\n", e.message().c_str());
    return 1;
  };

  // 1. plates
  std::vector<PlateCurve> plates;
  std::printf("plate sinkage (pressed at %.3f m/s)\n  b (m)  granules  sim s  wall s  p at 5 cm (kPa)  p at 10 cm (kPa)\n",
              PlateDef{}.speed);
  for (double b : a.plates) {
    PlateDef d;
    d.width = b;
    d.depth = std::max(d.depth, a.z_hi + 0.01);
    auto r = run_plate(setup, d);
    if (!r) return fail(r.errors());
    auto at = [&](double z) {
      double best = NAN, dz = 1e9;
      for (std::size_t i = 0; i < r->curve.z.size(); ++i)
        if (std::abs(r->curve.z[i] - z) < dz) {
          dz = std::abs(r->curve.z[i] - z);
          best = r->curve.p[i];
        }
      return best / 1000;
    };
    std::printf("  %.3f  %8d  %5.2f  %6.1f  %15.1f  %16.1f\n", b, r->granules, r->simulated_s, r->wall_s, at(0.05), at(0.10));
    js["plates"].push_back({{"width", b}, {"granules", r->granules}, {"simulated_s", r->simulated_s}, {"wall_s", r->wall_s}});
    char name[64];
    std::snprintf(name, sizeof name, "plate_%03d.csv", int(std::lround(b * 1000)));
    if (!save(a, name, csv_series({"t", "z", "p"}, {&r->t, &r->curve.z, &r->curve.p}))) return 1;
    plates.push_back(r->curve);
  }
  auto bf = fit_bekker(plates, a.z_lo, a.z_hi);
  if (!bf) return fail(bf.errors());
  const Bekker& bk = bf->soil;
  std::printf("Bekker fit over z in [%.3f, %.3f] m (%d points, rms of ln p %.3f):\n"
              "  n = %.3f +- %.3f   k_c = %.1f +- %.1f kN/m^(n+1)   k_phi = %.1f +- %.1f kN/m^(n+2)\n",
              a.z_lo, a.z_hi, bf->points, bf->rms_log, bk.n, bf->n_se, bk.k_c / 1000, bf->k_c_se / 1000, bk.k_phi / 1000,
              bf->k_phi_se / 1000);
  js["bekker"] = {{"n", bk.n},           {"n_se", bf->n_se},         {"k_c_kN", bk.k_c / 1000},
                  {"k_c_se_kN", bf->k_c_se / 1000}, {"k_phi_kN", bk.k_phi / 1000}, {"k_phi_se_kN", bf->k_phi_se / 1000},
                  {"k_per_width_kN", bf->k},        {"rms_log", bf->rms_log},    {"points", bf->points}};
  for (auto& v : js["bekker"]["k_per_width_kN"]) v = v.get<double>() / 1000;
  js["bekker"]["n_alone"] = bf->n_alone;
  js["bekker"]["n_alone_se"] = bf->n_alone_se;
  for (std::size_t i = 0; i < bf->widths.size(); ++i)
    std::printf("  b = %.3f m alone: n = %.3f +- %.3f; with the shared n: k = %.1f +- %.1f kN/m^(n+2)\n", bf->widths[i],
                bf->n_alone[i], bf->n_alone_se[i], bf->k[i] / 1000, bf->k_se[i] / 1000);

  if (a.plates_only) {
    if (!save(a, "terra.json", js.dump(1) + "\n")) return 1;
    if (a.json) std::printf("%s\n", js.dump().c_str());
    return 0;
  }

  // 2. shear
  std::vector<ShearCurve> shears;
  std::printf("shear plate (grousered, dragged at %.2f m/s)\n  sigma nominal (kPa)  measured (kPa)  blades in (m)  granules  wall s\n",
              ShearDef{}.speed);
  for (double sg : a.sigmas) {
    ShearDef d;
    d.sigma = sg;
    auto r = run_shear(setup, d);
    if (!r) return fail(r.errors());
    std::printf("  %19.2f  %14.2f  %13.3f  %8d  %6.1f\n", sg / 1000, r->curve.sigma / 1000, r->blade_sinkage, r->granules, r->wall_s);
    char name[64];
    std::snprintf(name, sizeof name, "shear_%05d.csv", int(std::lround(sg)));
    if (!save(a, name, csv_series({"t", "j", "tau", "blade_sinkage"}, {&r->t, &r->curve.j, &r->curve.tau, &r->sink}))) return 1;
    js["shear"].push_back({{"sigma_nominal", sg}, {"sigma", r->curve.sigma}, {"blade_sinkage", r->blade_sinkage},
                           {"granules", r->granules}, {"simulated_s", r->simulated_s}, {"wall_s", r->wall_s}});
    shears.push_back(r->curve);
  }
  const double plateau_from = 0.15;  // m of drag
  auto sf = fit_shear(shears, plateau_from);
  if (!sf) return fail(sf.errors());
  const ShearLaw& sh = sf->soil;
  for (std::size_t i = 0; i < shears.size(); ++i) {
    js["shear"][i]["tau_max"] = shears[i].tau_max;
    js["shear"][i]["tau_max_sd"] = shears[i].tau_max_sd;
    js["shear"][i]["K"] = shears[i].K;
    js["shear"][i]["tau_peak"] = shears[i].tau_peak;
    js["shear"][i]["j_peak"] = shears[i].j_peak;
    std::printf("  sigma %.2f kPa: tau_max %.2f +- %.2f kPa (plateau j >= %.2f m), K alone %.3f m; peak %.2f kPa at j = %.3f m\n",
                shears[i].sigma / 1000, shears[i].tau_max / 1000, shears[i].tau_max_sd / 1000, plateau_from, shears[i].K,
                shears[i].tau_peak / 1000, shears[i].j_peak);
  }
  std::printf("Janosi-Hanamoto fit: c = %.2f +- %.2f kPa   phi = %.1f +- %.1f deg   K = %.3f +- %.3f m\n", sh.c / 1000,
              sf->c_se / 1000, sh.phi * 180 / M_PI, sf->phi_se * 180 / M_PI, sh.K, sf->K_se);
  js["janosi_hanamoto"] = {{"c_kPa", sh.c / 1000},          {"c_se_kPa", sf->c_se / 1000},
                           {"phi_deg", sh.phi * 180 / M_PI}, {"phi_se_deg", sf->phi_se * 180 / M_PI},
                           {"K_m", sh.K},                    {"K_se_m", sf->K_se}};

  // 3. wheel
  WheelGeometry geo;
  std::printf("wheel rig\n  slip cmd  slip  DP (N)  sd (N)  sinkage (m)  torque (N m)  | model: DP (N)  sinkage (m)  torque (N m)"
              "  | model at the rig's sinkage: load (N)  DP (N)  | wall s\n");
  std::vector<double> sl, dpv, skv, mdp, msk;
  for (double s : a.slips) {
    WheelDef d;
    d.slip = s;
    auto r = run_wheel(setup, d);
    if (!r) return fail(r.errors());
    geo = r->soil_seen;
    const WheelModel m = wheel_under_load(bk, sh, geo, r->slip, r->load);
    // the model at the rig's own sinkage (the entry angle from it, not from the load)
    const double th = std::acos(std::clamp(1.0 - r->sinkage / geo.radius, 0.0, 1.0));
    const WheelModel ms = wheel_at_entry(bk, sh, geo, r->slip, th);
    std::printf("  %8.2f  %4.2f  %6.0f  %6.0f  %11.3f  %12.0f  | %13.0f  %11.3f  %12.0f  | %27.0f  %6.0f  | %6.1f\n", s, r->slip,
                r->drawbar_pull, r->drawbar_pull_sd, r->sinkage, r->torque, m.ok ? m.drawbar_pull : NAN, m.ok ? m.sinkage : NAN,
                m.ok ? m.torque : NAN, ms.load, ms.drawbar_pull, r->wall_s);
    js["wheel"].push_back({{"slip_cmd", s},
                           {"slip", r->slip},
                           {"load", r->load},
                           {"drawbar_pull", r->drawbar_pull},
                           {"drawbar_pull_sd", r->drawbar_pull_sd},
                           {"sinkage", r->sinkage},
                           {"sinkage_sd", r->sinkage_sd},
                           {"torque", r->torque},
                           {"vertical", r->vertical},
                           {"model_ok", m.ok},
                           {"model_drawbar_pull", m.drawbar_pull},
                           {"model_sinkage", m.sinkage},
                           {"model_torque", m.torque},
                           {"model_at_sinkage_load", ms.load},
                           {"model_at_sinkage_drawbar_pull", ms.drawbar_pull},
                           {"model_at_sinkage_torque", ms.torque},
                           {"granules", r->granules},
                           {"simulated_s", r->simulated_s},
                           {"wall_s", r->wall_s}});
    char name[64];
    std::snprintf(name, sizeof name, "wheel_%02d.csv", int(std::lround(s * 100)));
    if (!save(a, name, csv_series({"t", "x", "dp", "sinkage"}, {&r->t, &r->x, &r->dp, &r->sink}))) return 1;
  }
  js["wheel_geometry"] = {{"radius", geo.radius}, {"width", geo.width}};
  // the model over slip 0 .. 0.9 at the rig's load (for the plot)
  if (!js["wheel"].empty()) {
    const double load = js["wheel"][0]["load"].get<double>();
    for (int i = 0; i <= 18; ++i) {
      const double s = 0.05 * i;
      const WheelModel m = wheel_under_load(bk, sh, geo, s, load);
      if (m.ok) js["model_curve"].push_back({{"slip", s}, {"drawbar_pull", m.drawbar_pull}, {"sinkage", m.sinkage}, {"torque", m.torque}});
    }
  }
  js["wall_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  js["cpu_s"] = bench::process_cpu_seconds() - cpu0;
  js["load_after"] = bench::load_average();
  if (!save(a, "terra.json", js.dump(1) + "\n")) return 1;
  if (a.json) std::printf("%s\n", js.dump().c_str());
  return 0;
}

}  // namespace sandpatch::terra
