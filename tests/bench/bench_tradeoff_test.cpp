// tests bench/bench_tradeoff.cpp: the Pareto front is the non-dominated set, every sweep has one
// reference per case and it is the finest setting, and the quick sweep runs end to end: the
// reference has zero error, every error and cost is finite, the marked front is non-dominated,
// the CSV and the last-line JSON carry their columns and name the files written.
// (The timings themselves are a program, `sandpatch bench tradeoff`, never a test.)
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "bench/bench_tradeoff.hpp"

using namespace sandpatch;
namespace fs = std::filesystem;

namespace {

std::vector<std::string> split_csv_line(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  bool quoted = false;
  for (char ch : line) {
    if (ch == '"') quoted = !quoted;
    else if (ch == ',' && !quoted) out.push_back(cur), cur.clear();
    else cur += ch;
  }
  out.push_back(cur);
  return out;
}

// Some j dominates i.
bool dominated(std::size_t i, const std::vector<double>& c, const std::vector<double>& e) {
  for (std::size_t j = 0; j < c.size(); ++j)
    if (j != i && c[j] <= c[i] && e[j] <= e[i] && (c[j] < c[i] || e[j] < e[i])) return true;
  return false;
}

}  // namespace

TEST(Tradeoff, ParetoFrontOfHandMadePoints) {
  // (cost, error): (1, 5) cheapest; (2, 3) and its twin both on the front; (3, 4) dominated by
  // (2, 3); (4, 1); (5, 1) dominated by (4, 1) (same error, dearer); NaN never on it.
  const std::vector<double> cost = {1, 2, 2, 3, 4, 5, NAN};
  const std::vector<double> err = {5, 3, 3, 4, 1, 1, 0};
  const auto f = pareto_front(cost, err);
  const std::vector<bool> want = {true, true, true, false, true, false, false};
  EXPECT_EQ(f, want);
}

TEST(Tradeoff, ParetoFrontIsExactlyTheNonDominatedSet) {
  std::uint64_t s = 12345;
  auto next = [&] {  // small LCG: reproducible points
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    return double((s >> 33) % 1000) / 100.0;
  };
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<double> c(20), e(20);
    for (int i = 0; i < 20; ++i) c[i] = next(), e[i] = next();
    const auto f = pareto_front(c, e);
    int on = 0;
    for (std::size_t i = 0; i < c.size(); ++i) {
      EXPECT_EQ(f[i], !dominated(i, c, e)) << "trial " << trial << " point " << i;
      on += f[i];
    }
    EXPECT_GE(on, 1);  // the cheapest point of least error is always on it
  }
}

TEST(Tradeoff, EverySweepHasOneFinestReferencePerCase) {
  for (auto sweep : {TradeoffSweep::Quick, TradeoffSweep::Default, TradeoffSweep::Full}) {
    const auto v = tradeoff_sweep(sweep);
    std::set<std::string> ids;
    for (const auto& t : v) EXPECT_TRUE(ids.insert(t.id).second) << "duplicate id " << t.id;
    for (auto c : {TradeoffCase::Pile, TradeoffCase::Crater}) {
      const TradeoffSetting* ref = nullptr;
      int refs = 0;
      for (const auto& t : v)
        if (t.kind == c && t.reference) ref = &t, ++refs;
      ASSERT_EQ(refs, 1) << to_string(sweep) << " " << to_string(c);
      EXPECT_EQ(ref->knobs.backend, "cpu");
      EXPECT_FALSE(ref->noise);
      for (const auto& t : v) {
        if (t.kind != c) continue;
        EXPECT_GE(t.knobs.particle_scale, ref->knobs.particle_scale) << t.id;
        EXPECT_LE(t.knobs.steps_per_contact, ref->knobs.steps_per_contact) << t.id;
        if (c == TradeoffCase::Crater) {
          EXPECT_LE(t.knobs.patch_radii, ref->knobs.patch_radii) << t.id;
        }
        EXPECT_GE(t.knobs.steps_per_contact, 10) << t.id;
      }
    }
  }
}

TEST(Tradeoff, BadCraterDefinitionNamesTheField) {
  CraterDef d;
  d.knobs.patch_radii = 1;
  auto r = measure_crater(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "CraterDef.knobs.patch_radii");
  d = CraterDef{};
  d.knobs.backend = "cuda";
  r = measure_crater(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "CraterDef.knobs.backend");
  EXPECT_NE(r.error().allowed.find("gl"), std::string::npos);
}

TEST(Tradeoff, QuickSweepRunsAndReportsConsistently) {
  const fs::path out = fs::temp_directory_path() / "sandpatch_bench_tradeoff_test";
  fs::remove_all(out);
  BenchTradeoffArgs a;
  a.sweep = TradeoffSweep::Quick;
  a.threads = 2;
  a.gl = false;  // llvmpipe would take minutes; `sandpatch bench tradeoff` runs it
  a.json = true;
  a.out_dir = out.string();
  testing::internal::CaptureStdout();
  const int rc = run_bench_tradeoff(a);
  const std::string text = testing::internal::GetCapturedStdout();
  ASSERT_EQ(rc, 0) << text;

  // the last line is one JSON object naming both files (the plot null: none asked for) and listing the settings
  std::string last;
  {
    std::istringstream in(text);
    for (std::string line; std::getline(in, line);)
      if (!line.empty()) last = line;
  }
  const auto j = nlohmann::json::parse(last);
  ASSERT_EQ(j["bench"], "tradeoff");
  ASSERT_TRUE(j["csv"].is_string());
  EXPECT_TRUE(fs::exists(j["csv"].get<std::string>()));
  EXPECT_TRUE(fs::exists(j["json"].get<std::string>()));
  EXPECT_TRUE(j.contains("plot"));
  const auto& settings = j["settings"];
  ASSERT_EQ(settings.size(), tradeoff_sweep(TradeoffSweep::Quick).size());

  std::map<std::string, std::vector<std::size_t>> by_case;
  for (std::size_t i = 0; i < settings.size(); ++i) {
    const auto& s = settings[i];
    ASSERT_TRUE(s["ran"].get<bool>()) << s.dump();
    for (const char* key : {"wall_s", "wall_s_per_sim_s", "real_time_factor", "error"}) {
      ASSERT_TRUE(s[key].is_number()) << key << " in " << s.dump();
      EXPECT_TRUE(std::isfinite(s[key].get<double>())) << key << " in " << s.dump();
      EXPECT_GE(s[key].get<double>(), 0.0) << key;
    }
    EXPECT_GT(s["wall_s"].get<double>(), 0.0);
    // real-time factor and cost are reciprocal
    EXPECT_NEAR(s["real_time_factor"].get<double>() * s["wall_s_per_sim_s"].get<double>(), 1.0, 1e-9);
    if (s["reference"].get<bool>()) {
      EXPECT_EQ(s["error"].get<double>(), 0.0) << s.dump();
    }
    by_case[s["case"].get<std::string>()].push_back(i);
  }
  ASSERT_EQ(by_case.size(), 2u);
  // the marked front is the non-dominated set of each case (noise repeats left out)
  for (const auto& [c, idx] : by_case) {
    std::vector<double> cost, err;
    std::vector<bool> marked;
    for (std::size_t i : idx) {
      if (settings[i]["noise"].get<bool>()) continue;
      cost.push_back(settings[i]["wall_s_per_sim_s"].get<double>());
      err.push_back(settings[i]["error"].get<double>());
      marked.push_back(settings[i]["pareto"].get<bool>());
    }
    for (std::size_t i = 0; i < cost.size(); ++i) EXPECT_EQ(marked[i], !dominated(i, cost, err)) << c << " " << i;
  }

  // the full JSON file: the physical measurements behind the errors
  std::ifstream jf(j["json"].get<std::string>());
  const auto full = nlohmann::json::parse(jf);
  for (const auto& s : full["settings"]) {
    if (s["case"] == "pile") {
      EXPECT_TRUE(s["angle_deg"].is_number());
      EXPECT_GT(s["granules"].get<int>(), 0);
    } else {
      // the sphere made a crater (at the reference, the finest bed): the surface under it went
      // down, by less than the bed is deep
      if (s["reference"].get<bool>()) {
        EXPECT_GT(s["depth_m"].get<double>(), 0.0) << s.dump();
      }
      EXPECT_GE(s["depth_m"].get<double>(), 0.0) << s.dump();
      EXPECT_LT(s["depth_m"].get<double>(), full["cases"]["crater"]["bed_depth_m"].get<double>()) << s.dump();
      EXPECT_GE(s["rim_volume_m3"].get<double>(), 0.0);
    }
    EXPECT_GT(s["dt_over_tc"].get<double>(), 0.0);
    EXPECT_LE(s["dt_over_tc"].get<double>(), 1.0 / s["steps_per_contact"].get<double>() * (1 + 1e-6)) << s.dump();
  }
  EXPECT_FALSE(full["not_swept"].empty());  // each knob left out says why

  // CSV: the header's columns, one row a setting with as many fields
  std::ifstream cf(j["csv"].get<std::string>());
  std::string header;
  std::getline(cf, header);
  const auto cols = split_csv_line(header);
  for (const char* col : {"id", "case", "particle_scale", "steps_per_contact", "patch_radii", "backend", "wall_s",
                          "real_time_factor", "error", "pareto"})
    EXPECT_NE(std::find(cols.begin(), cols.end(), col), cols.end()) << col;
  int rows = 0;
  for (std::string line; std::getline(cf, line);) {
    if (line.empty()) continue;
    EXPECT_EQ(split_csv_line(line).size(), cols.size()) << line;
    ++rows;
  }
  EXPECT_EQ(rows, int(settings.size()));
}
