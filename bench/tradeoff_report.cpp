// bench tradeoff: what a run writes — OUT/tradeoff.csv (one row a setting), OUT/tradeoff.json
// (everything), the plot (scripts/plot_tradeoff.py), the summary table and the JSON line
// (bench/bench_tradeoff.hpp, run_bench_tradeoff).
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "bench/bench_util.hpp"
#include "bench/tradeoff_internal.hpp"

namespace fs = std::filesystem;

namespace sandpatch::tradeoff_internal {

namespace {

using bench::load_average;
using bench::write_text;

ojson jnum(double v) { return std::isfinite(v) ? ojson(v) : ojson(); }
// A radial profile of Δh (m) per bin; a bin without samples (held as -1e300) becomes null.
ojson dh_json(const std::vector<double>& dh) {
  ojson out = ojson::array();
  for (double v : dh) out.push_back(v > -1e299 ? ojson(v) : ojson());
  return out;
}


// One setting: its CSV line onto csv, its JSON object onto settings.
void add_setting(const Row& row, std::string& csv, ojson& settings) {
  const auto& k = row.set.knobs;
  const bool crater = row.set.kind == TradeoffCase::Crater, drop = row.set.kind == TradeoffCase::Drop;
  const std::string outcome = row.ran ? "ok" : !row.refused.empty() ? "refused" : "skipped";
  const double cost = row.ran ? row.wall_s / row.sim_s : NAN, rtf = row.ran ? row.sim_s / row.wall_s : NAN;
  auto f = [](double v) {
    if (!std::isfinite(v)) return std::string();
    char b[40];
    std::snprintf(b, sizeof b, "%.6g", v);
    return std::string(b);
  };
  const bool pile = row.set.kind == TradeoffCase::Pile;
  const double depth = !row.ran ? NAN : crater ? row.crater.depth : drop ? row.drop.depth : NAN;
  const double cvol = !row.ran ? NAN : crater ? row.crater.crater_volume : drop ? row.drop.crater_volume : NAN;
  const double rvol = !row.ran ? NAN : crater ? row.crater.rim_volume : drop ? row.drop.rim_volume : NAN;
  const double rh = !row.ran ? NAN : crater ? row.crater.rim_height : drop ? row.drop.rim_height : NAN;
  const double crad = !row.ran ? NAN : crater ? row.crater.crater_radius : drop ? row.drop.crater_radius : NAN;
  const bool timed = row.ran && row.dt > 0 && row.contact_time > 0;
  std::string why = row.ran ? "" : !row.refused.empty() ? row.refused : row.skipped;
  std::replace(why.begin(), why.end(), '"', '\'');
  std::replace(why.begin(), why.end(), '\n', ' ');
  csv += row.set.id + "," + to_string(row.set.kind) + "," + f(k.particle_scale) + "," +
         std::to_string(k.steps_per_contact) + "," + (crater ? f(k.patch_radii) : "") + "," + k.backend + "," +
         (drop ? std::to_string(k.substeps) : "") + "," + (drop ? std::to_string(k.granules_per_slot) : "") + "," +
         (drop ? (k.lod ? "on" : "off") : "") + "," + (drop && k.lod ? f(k.lod_apron) : "") + "," +
         std::to_string(k.seed) + "," + (row.set.reference ? "1" : "0") + "," + (row.set.noise ? "1" : "0") + "," +
         (row.ran ? "1" : "0") + "," + outcome + "," + std::to_string(row.granules) + "," + f(timed ? row.dt : NAN) +
         "," + f(timed ? row.dt / row.contact_time : NAN) + "," + f(row.ran ? row.sim_s : NAN) + "," +
         f(row.ran ? row.wall_s : NAN) + "," + f(cost) + "," + f(rtf) + "," + f(pile && row.ran ? row.angle : NAN) +
         "," + f(depth) + "," + f(cvol) + "," + f(rvol) + "," + f(rh) + "," + f(crad) + "," + f(row.error) + "," +
         f(row.error_a) + "," + f(row.error_b) + "," + f(row.error_v) + "," + f(row.error_experiment) + "," +
         (row.pareto ? "1" : "0") + ",\"" +
         why + "\"\n";
  ojson j = {{"id", row.set.id},
             {"case", to_string(row.set.kind)},
             {"particle_scale", k.particle_scale},
             {"steps_per_contact", k.steps_per_contact},
             {"patch_radii", crater ? ojson(k.patch_radii) : ojson()},
             {"backend", k.backend},
             {"substeps", drop ? ojson(k.substeps) : ojson()},
             {"granules_per_slot", drop ? ojson(k.granules_per_slot) : ojson()},
             {"lod", drop ? ojson(k.lod ? "on" : "off") : ojson()},
             {"lod_apron_m", drop && k.lod ? ojson(k.lod_apron) : ojson()},
             {"seed", k.seed},
             {"reference", row.set.reference},
             {"noise", row.set.noise},
             {"ran", row.ran},
             {"outcome", outcome}};
  if (!row.refused.empty()) {
    // the manager refused the setting: its message names the capacity to raise
    j["refused"] = row.refused;
    j["refused_at_s"] = row.drop.refused_at;
    j["pool_bytes"] = row.drop.pool_bytes;
    j["setup_s"] = row.setup_s;
  } else if (!row.ran) {
    j["skipped"] = row.skipped;
  } else {
    j["granules"] = row.granules;
    j["dt_s"] = timed ? ojson(row.dt) : ojson();
    j["dt_over_tc"] = timed ? ojson(row.dt / row.contact_time) : ojson();
    j["sim_s"] = row.sim_s;
    j["wall_s"] = row.wall_s;
    j["wall_s_per_sim_s"] = cost;
    j["real_time_factor"] = rtf;
    if (crater) {
      j["depth_m"] = row.crater.depth;
      j["rim_volume_m3"] = row.crater.rim_volume;
      j["rim_height_m"] = row.crater.rim_height;
      j["crater_radius_m"] = row.crater.crater_radius;
      j["crater_volume_m3"] = row.crater.crater_volume;
      j["sphere_sink_m"] = row.crater.sphere_sink;
      j["final_speed_m_s"] = row.crater.final_speed;
      j["setup_s"] = row.setup_s;
      j["dh_m"] = dh_json(row.crater.dh);  // Δh per bin of bin_m from the axis
    } else if (drop) {
      j["depth_m"] = row.drop.depth;
      j["crater_volume_m3"] = row.drop.crater_volume;
      j["crater_radius_m"] = row.drop.crater_radius;
      j["rim_volume_m3"] = row.drop.rim_volume;
      j["rim_height_m"] = row.drop.rim_height;
      j["sphere_sink_m"] = row.drop.sphere_sink;
      j["far_field_dh_m"] = row.drop.far_field_dh;
      j["ledger_error_pct"] = row.drop.ledger_error_pct;
      j["patches"] = row.drop.patches;
      j["pool_bytes"] = row.drop.pool_bytes;
      j["dem_wall_s"] = row.drop.dem_seconds;
      j["asleep_at_end"] = row.drop.asleep_at_end;
      j["setup_s"] = row.setup_s;
      j["dh_m"] = dh_json(row.drop.dh);  // mean Δh per radial bin of one sample spacing from the axis
    } else {
      j["angle_deg"] = row.angle;
      j["fit_points"] = row.fit_points;
      j["fit_residual_m"] = row.residual;
      j["pile_height_m"] = row.peak;
      j["at_rest"] = row.at_rest;
    }
    j["error"] = jnum(row.error);
    j[crater || drop ? "error_depth" : "error_angle"] = jnum(row.error_a);
    if (crater || drop) j["error_rim"] = jnum(row.error_b);
    if (drop) j["error_crater_volume"] = jnum(row.error_v);
    if (crater || drop) j["error_vs_experiment"] = jnum(row.error_experiment);
    j["pareto"] = row.pareto;
    if (row.set.noise) j["seed_scatter"] = jnum(row.scatter);
  }
  settings.push_back(j);
}

// Runs the plot script on the JSON (stdout flushed first): result["plot"] on success, else
// result["plot_note"]; returns the note ("" on success). The JSON is written again either way.
std::string make_plot(const std::string& plot_script, const fs::path& json_path, const fs::path& png_path,
                      ojson& result) {
  std::string plot_note;
  std::fflush(stdout);
  const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
  const std::string cmd = python + " '" + plot_script + "' '" + json_path.string() + "' '" + png_path.string() +
                          "' 2>&1";
  const int status = std::system(cmd.c_str());
  const int rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (rc == 0) {
    result["plot"] = png_path.string();
  } else {
    plot_note = python + " " + plot_script + " exited with " + std::to_string(rc) +
                (rc == 3 ? ": matplotlib missing (apt-get install python3-matplotlib)"
                         : rc == 127 ? ": python3 missing" : "");
    result["plot_note"] = plot_note;
  }
  write_text(json_path, result.dump(2) + "\n");
  return plot_note;
}

// The summary table, one line a setting.
void print_table(const std::vector<Row>& rows) {
  std::printf("\n%-40s %8s %10s %8s %9s %s\n", "setting", "granules", "wall/sim", "RTF", "error", "pareto");
  for (const auto& row : rows) {
    if (!row.refused.empty()) {
      std::printf("%-40s refused: %s\n", row.set.id.c_str(), row.refused.c_str());
      continue;
    }
    if (!row.ran) {
      std::printf("%-40s skipped: %s\n", row.set.id.c_str(), row.skipped.c_str());
      continue;
    }
    std::printf("%-40s %8d %10.2f %8.4f %9.4f %s%s%s\n", row.set.id.c_str(), row.granules, row.wall_s / row.sim_s,
                row.sim_s / row.wall_s, row.error, row.pareto ? "*" : "", row.set.reference ? " (reference)" : "",
                row.set.noise ? " (other seed: noise floor)" : "");
  }
}

// The last stdout line with --json: the files and, per setting, its knobs, outcome, cost and error.
void print_json_line(const ojson& result, const ojson& settings, const std::string& plot_note) {
  ojson line = {{"bench", "tradeoff"}, {"csv", result["csv"]}, {"plot", result["plot"]}, {"json", result["json"]}};
  ojson list = ojson::array();
  for (const auto& s : settings) {
    ojson e = {{"id", s["id"]}, {"case", s["case"]}, {"ran", s["ran"]}};
    for (const char* key : {"particle_scale", "steps_per_contact", "patch_radii", "backend", "substeps",
                            "granules_per_slot", "lod", "lod_apron_m", "seed", "reference", "noise", "outcome", "wall_s",
                            "wall_s_per_sim_s", "real_time_factor", "error", "seed_scatter", "pareto", "skipped",
                            "refused"})
      if (s.contains(key)) e[key] = s[key];
    list.push_back(e);
  }
  line["settings"] = list;
  if (!plot_note.empty()) line["plot_note"] = plot_note;
  std::printf("%s\n", line.dump().c_str());
}

}  // namespace

int write_report(const BenchTradeoffArgs& a, const fs::path& out, const std::vector<Row>& rows, const RunContext& ctx,
                 const RimInError& rim, const std::vector<ojson>& skipped, const std::string& gl_renderer,
                 double load_before) {
  const Material& mat = ctx.mat;
  const CraterDef& cd = ctx.cd;
  // CSV (one row a setting) and JSON
  std::string csv =
      "id,case,particle_scale,steps_per_contact,patch_radii,backend,substeps,granules_per_slot,lod,lod_apron_m,seed,"
      "reference,noise,ran,outcome,granules,dt_s,dt_over_tc,sim_s,wall_s,wall_s_per_sim_s,real_time_factor,angle_deg,"
      "depth_m,crater_volume_m3,rim_volume_m3,rim_height_m,crater_radius_m,error,error_angle_or_depth,error_rim,"
      "error_crater_volume,error_vs_experiment,pareto,skipped\n";
  ojson settings = ojson::array();
  for (const auto& row : rows) add_setting(row, csv, settings);
  const double load_after = load_average();
  const DropDef dd0 = tradeoff_drop_def(a.sweep);
  const fs::path csv_path = out / "tradeoff.csv", json_path = out / "tradeoff.json", png_path = out / "tradeoff.png";
  ojson result = {{"bench", "tradeoff"},
                  {"sweep", to_string(a.sweep)},
                  {"csv", csv_path.string()},
                  {"json", json_path.string()},
                  {"plot", ojson()},
                  {"cost", "wall_s_per_sim_s: wall seconds of the measured phase per simulated second (1 / real_time_factor)"},
                  {"error", "pile: |angle - angle_ref| / angle_ref; crater: max(|depth - ref| / ref, |rim volume - ref| / "
                            "ref), the rim term only when the reference's rim is at least a granule sphere radius high "
                            "(cases.crater.rim_in_error); drop: max(|depth - ref| / ref, |crater volume - ref| / ref, "
                            "|rim volume - ref| / ref), the rim term as the crater's (cases.drop.rim_in_error); ref = "
                            "the case's reference setting; a refused setting has no error (outcome refused)"},
                  {"cases",
                   {{"pile", {{"granules_at_scale_1", ctx.pile_n}, {"granule_radius_m", ctx.r}, {"floor_radius_m", 0.2}}},
                    {"crater", {{"sphere_radius_m", cd.sphere_radius}, {"sphere_density", cd.sphere_density},
                                {"drop_height_m", cd.drop_height}, {"impact_speed_m_s", std::sqrt(2 * kG * cd.drop_height)},
                                {"bed_depth_m", cd.bed_depth_radii * cd.sphere_radius}, {"impact_seconds", cd.impact_seconds},
                                {"bin_m", cd.bin_radii * cd.sphere_radius}, {"granule_radius_m", ctx.r},
                                {"rim_in_error", rim.crater}}},
                    {"drop", {{"path", "Bullet sphere onto a flat heightfield through the TerrainManager (bench/tradeoff_drop.hpp); "
                                       "crater measured in the heightfield after demote_all"},
                              {"sphere_radius_m", dd0.sphere_radius}, {"sphere_density", dd0.sphere_density},
                              {"drop_height_m", dd0.drop_height}, {"impact_speed_m_s", std::sqrt(2 * kG * dd0.drop_height)},
                              {"terrain_side_m", dd0.terrain_side}, {"spacing_m", dd0.spacing},
                              {"patch_depth_m", dd0.patch_depth}, {"run_seconds", dd0.run_seconds},
                              {"frame_dt_s", dd0.frame_dt}, {"granule_radius_m", dd0.granule_radius},
                              {"material", {{"normal_stiffness", dd0.stiffness}, {"restitution", dd0.restitution},
                                            {"friction", dd0.friction}, {"density", dd0.granule_density}}},
                              {"rim_in_error", rim.drop}}},
                    {"material", {{"normal_stiffness", mat.normal_stiffness}, {"restitution", mat.restitution},
                                  {"friction", mat.friction}, {"density", mat.density}}}}},
                  {"settings", settings},
                  {"not_swept", skipped},
                  {"gl_renderer", gl_renderer},
                  {"threads", ctx.threads},
                  {"load_average", {load_before, load_after}}};
  std::string plot_note;
  if (!write_text(csv_path, csv) || !write_text(json_path, result.dump(2) + "\n")) {
    std::fprintf(stderr, "bench tradeoff: cannot write %s or %s\n", csv_path.string().c_str(), json_path.string().c_str());
    return 1;
  }
  if (!a.plot_script.empty()) {
    plot_note = make_plot(a.plot_script, json_path, png_path, result);
  } else {
    result["plot_note"] = "no plot asked for (--no-plot)";
  }

  // summary table
  print_table(rows);
  std::printf("load average %.2f -> %.2f\ndata: %s, %s\n", load_before, load_after, csv_path.string().c_str(),
              json_path.string().c_str());
  if (result["plot"].is_string()) std::printf("plot: %s\n", png_path.string().c_str());
  else std::printf("plot: not made (%s); the data above is written\n", result["plot_note"].get<std::string>().c_str());
  if (a.json) print_json_line(result, settings, plot_note);
  return 0;
}

}  // namespace sandpatch::tradeoff_internal
