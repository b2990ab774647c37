// Internals of `sandpatch bench tradeoff` shared by its files; not a public header.
//   bench/bench_tradeoff.cpp    the entry: arguments, the run's set-up, the loop over settings
//   bench/tradeoff_sweep.cpp    the settings of each sweep, the Pareto front
//   bench/tradeoff_cases.cpp    one setting of each case run into a Row; errors and noise floors
//   bench/tradeoff_crater.cpp   the crater case (measure_crater)
//   bench/tradeoff_report.cpp   tradeoff.csv, tradeoff.json, the plot, the table, the JSON line
// The drop case is bench/tradeoff_drop.cpp.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "bench/bench_tradeoff.hpp"
#include "bench/tradeoff_drop.hpp"

namespace sandpatch::tradeoff_internal {

using ojson = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

inline constexpr double kG = 9.81;             // m/s^2
inline constexpr double kFrame = 1.0 / 120.0;  // s per step() call; the DEM substeps within

inline double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// "%g" of v, for setting ids.
std::string num_id(double v);

// The contact material of the pile and crater cases: the LAMMPS peer's (docs/BENCHMARKS.md), mu = 0.5
// (docs/dem.md).
Material reference_material();

// One setting of the sweep and what it measured.
struct Row {
  TradeoffSetting set;
  bool ran = false;
  std::string skipped;     // why not run ("" when it ran)
  std::string refused;     // drop: the manager's refusal ("" when it ran)
  double wall_s = 0, sim_s = 0, setup_s = 0;
  double dt = 0, contact_time = 0;
  int granules = 0;
  // pile
  double angle = 0, residual = 0, peak = 0;
  bool at_rest = false;
  int fit_points = 0;
  // crater
  CraterResult crater;
  // drop (through the TerrainManager); drop.refused: the manager refused the setting
  DropResult drop;
  // against the reference
  double error = std::numeric_limits<double>::quiet_NaN();
  double error_a = std::numeric_limits<double>::quiet_NaN();  // pile: angle; crater: depth (relative)
  double error_b = std::numeric_limits<double>::quiet_NaN();  // crater, drop: rim volume (relative)
  double error_v = std::numeric_limits<double>::quiet_NaN();  // drop: crater volume (relative)
  // drop: |d - d_exp| / d_exp, d the ball's final penetration (its lowest point below the
  // surface + the shell spheres' radius) and d_exp Uehara et al.'s (2003) law for this ball and
  // bed (bench/impact.hpp, docs/validation.md)
  double error_experiment = std::numeric_limits<double>::quiet_NaN();
  bool pareto = false;
  double scatter = std::numeric_limits<double>::quiet_NaN();  // noise repeats: |x - x_twin| / ref
};

// What every setting of one run shares.
struct RunContext {
  TradeoffSweep sweep = TradeoffSweep::Default;
  int threads = 1;
  Material mat;                 // pile and crater
  float r = 0.005f;             // granule radius, m (pile and crater)
  int pile_n = 0;               // pile granules at particle scale 1
  CraterDef cd;                 // the crater case's definition; each setting sets its knobs
  // the settled bed of each (scale, seed) is the largest patch of the sweep at them
  std::map<std::pair<double, std::uint64_t>, double> settle_size;
  std::string gl_skip;          // why gl settings are skipped ("" = they run)
  CraterBeds beds;              // settled beds kept between crater settings
};

// Runs one setting into `row` and prints its line. 0 ok (also for a refused or skipped
// setting), 1 failure (the message is on stderr).
int run_setting(Row& row, RunContext& ctx);

// Whether each case's reference resolves a rim (the rim term is then in the error).
struct RimInError {
  bool crater = false, drop = false;
};
// Errors against each case's reference, the noise repeats' scatter, the Pareto front per case
// (noise repeats left out).
RimInError score_rows(std::vector<Row>& rows, const RunContext& ctx);

// Writes OUT/tradeoff.csv, OUT/tradeoff.json and (with a plot script) the plot, then prints the
// summary table and, with json, the JSON line. 0 ok, 1 a file could not be written.
int write_report(const BenchTradeoffArgs& a, const std::filesystem::path& out, const std::vector<Row>& rows,
                 const RunContext& ctx, const RimInError& rim, const std::vector<ojson>& skipped,
                 const std::string& gl_renderer, double load_before);

}  // namespace sandpatch::tradeoff_internal
