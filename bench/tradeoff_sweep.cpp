// bench tradeoff: the settings of each sweep (reference first within each case), their ids,
// the cases' fixed definitions and the Pareto front (bench/bench_tradeoff.hpp).
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "bench/tradeoff_internal.hpp"

namespace sandpatch {

namespace tradeoff_internal {

std::string num_id(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

// The contact material of both cases: the LAMMPS peer's (docs/BENCHMARKS.md), mu = 0.5 (docs/dem.md).
Material reference_material() {
  Material m;
  m.density = 2500;
  m.normal_stiffness = 3292;
  m.restitution = 0.3f;
  m.friction = 0.5f;
  return m;
}

}  // namespace tradeoff_internal

using tradeoff_internal::num_id;

const char* to_string(TradeoffCase c) {
  return c == TradeoffCase::Pile ? "pile" : c == TradeoffCase::Crater ? "crater" : "drop";
}
const char* to_string(TradeoffSweep s) {
  return s == TradeoffSweep::Quick ? "quick" : s == TradeoffSweep::Full ? "full" : "default";
}

DropDef tradeoff_drop_def(TradeoffSweep sweep) {
  DropDef d;
  if (sweep == TradeoffSweep::Quick) d.run_seconds = 1.0;
  return d;
}

int tradeoff_pile_granules(TradeoffSweep sweep) { return sweep == TradeoffSweep::Quick ? 100 : 400; }

std::vector<TradeoffSetting> tradeoff_sweep(TradeoffSweep sweep) {
  std::vector<TradeoffSetting> v;
  auto add = [&](TradeoffCase c, double s, int n, double p, const char* backend = "cpu", std::uint64_t seed = 1,
                 bool ref = false, bool noise = false) {
    TradeoffSetting t;
    t.kind = c;
    t.knobs.particle_scale = s;
    t.knobs.steps_per_contact = n;
    t.knobs.patch_radii = c == TradeoffCase::Crater ? p : 0;
    t.knobs.backend = backend;
    t.knobs.seed = seed;
    t.reference = ref;
    t.noise = noise;
    t.id = std::string(to_string(c)) + "_s" + num_id(s) + "_n" + std::to_string(n) +
           (c == TradeoffCase::Crater ? "_p" + num_id(p) + "_" + backend : "") +
           (seed != 1 ? "_seed" + std::to_string(seed) : "");
    v.push_back(t);
  };
  // the drop case (bench/tradeoff_drop.hpp): through the TerrainManager
  auto drop = [&](double s, int n, int sub, bool lod, double apron, int slot, std::uint64_t seed = 1, bool ref = false,
                  bool noise = false) {
    TradeoffSetting t;
    t.kind = TradeoffCase::Drop;
    t.knobs.particle_scale = s;
    t.knobs.steps_per_contact = n;
    t.knobs.patch_radii = 0;
    t.knobs.substeps = sub;
    t.knobs.granules_per_slot = slot;
    t.knobs.lod = lod;
    t.knobs.lod_apron = lod ? apron : 0;
    t.knobs.seed = seed;
    t.reference = ref;
    t.noise = noise;
    t.id = "drop_s" + num_id(s) + "_n" + std::to_string(n) + "_sub" + std::to_string(sub) +
           (lod ? "_lod" + num_id(apron) : std::string("_lodoff")) + "_slot" + std::to_string(slot) +
           (seed != 1 ? "_seed" + std::to_string(seed) : "");
    v.push_back(t);
  };
  // The drop's rows of the default and full sweeps after their reference: N, substeps with LOD
  // off and on, slot capacities (two refused), particle scale 2.
  auto drop_knob_rows = [&]() {
    drop(1, 20, 1, false, 0, 16384);
    drop(1, 10, 1, false, 0, 16384);
    drop(1, 20, 2, false, 0, 16384);
    drop(1, 20, 1, true, 0.2, 16384);
    drop(1, 20, 2, true, 0.2, 16384);
    drop(1, 20, 4, true, 0.2, 16384);
    drop(1, 20, 1, true, 0.2, 1700);   // fits the LOD patch (1590) ...
    drop(1, 20, 1, false, 0, 1700);    // ... not the whole terrain (1835): refused
    drop(1, 20, 1, true, 0.2, 1024);   // refused
    drop(2, 20, 1, true, 0.2, 16384);
    drop(2, 20, 1, false, 0, 16384);
  };
  using C = TradeoffCase;
  switch (sweep) {
    case TradeoffSweep::Quick:
      add(C::Pile, 1, 50, 0, "cpu", 1, true);
      add(C::Pile, 1, 20, 0);
      add(C::Pile, 1.26, 20, 0);
      add(C::Pile, 1, 10, 0);
      add(C::Crater, 1, 50, 4, "cpu", 1, true);
      add(C::Crater, 1, 20, 4);
      add(C::Crater, 1.5, 20, 4);
      add(C::Crater, 1, 20, 3);
      // the drop at particle scale 2 (212 granules for the whole terrain, 176 for the LOD patch)
      drop(2, 20, 1, false, 0, 16384, 1, true);
      drop(2, 20, 1, true, 0.5, 16384);
      drop(2, 20, 2, true, 0.5, 16384);
      drop(2, 20, 1, false, 0, 192);  // the whole terrain needs 212: refused
      drop(2, 20, 1, true, 0.5, 192);  // the LOD patch fits
      drop(2, 20, 1, false, 0, 16384, 2, false, true);
      drop(2, 20, 1, true, 0.5, 16384, 2, false, true);
      break;
    case TradeoffSweep::Default:
      add(C::Pile, 1, 50, 0, "cpu", 1, true);
      for (double s : {1.0, 1.26, 1.59})
        for (int n : {50, 20, 10})
          if (!(s == 1.0 && n == 50)) add(C::Pile, s, n, 0);
      add(C::Pile, 1, 20, 0, "cpu", 2, false, true);
      add(C::Crater, 1, 50, 6, "cpu", 1, true);
      add(C::Crater, 1, 20, 6);
      add(C::Crater, 1, 10, 6);
      add(C::Crater, 1, 20, 4.5);
      add(C::Crater, 1, 20, 3.5);
      add(C::Crater, 1.5, 20, 6);
      add(C::Crater, 1.5, 10, 6);
      add(C::Crater, 2, 20, 6);
      add(C::Crater, 2, 10, 6);
      add(C::Crater, 2, 10, 4.5);
      add(C::Crater, 2, 20, 6, "gl");
      add(C::Crater, 1, 20, 6, "cpu", 2, false, true);
      // the drop at particle scale 1: 1835 granules for the whole terrain, 1590 for the LOD
      // patch (the apron rounded out to whole tile periods: 0.2 and 0.5 m give the same patch)
      drop(1, 50, 1, false, 0, 16384, 1, true);
      drop_knob_rows();
      drop(1, 20, 1, false, 0, 16384, 2, false, true);
      drop(1, 20, 1, true, 0.2, 16384, 2, false, true);
      break;
    case TradeoffSweep::Full:
      add(C::Pile, 0.79, 100, 0, "cpu", 1, true);
      for (double s : {0.79, 1.0, 1.26, 1.59})
        for (int n : {10, 20, 50, 100})
          if (!(s == 0.79 && n == 100)) add(C::Pile, s, n, 0);
      add(C::Pile, 1, 20, 0, "cpu", 2, false, true);
      add(C::Pile, 1, 20, 0, "cpu", 3, false, true);
      add(C::Crater, 0.75, 100, 10, "cpu", 1, true);
      for (double s : {0.75, 1.0, 1.5, 2.0})
        for (int n : {10, 20, 50})
          add(C::Crater, s, n, 8);
      for (double p : {4.0, 6.0, 10.0}) add(C::Crater, 1, 20, p);
      add(C::Crater, 2, 20, 6, "gl");
      add(C::Crater, 1.5, 20, 6, "gl");
      add(C::Crater, 1, 20, 8, "cpu", 2, false, true);
      add(C::Crater, 1, 20, 8, "cpu", 3, false, true);
      // the drop at particle scale 1: 1835 granules for the whole terrain, 1590 for the LOD
      // patch (the apron rounded out to whole tile periods: 0.2 and 0.5 m give the same patch)
      drop(1, 100, 1, false, 0, 16384, 1, true);
      drop(1, 50, 1, false, 0, 16384);
      drop_knob_rows();
      drop(1, 20, 8, true, 0.2, 16384);
      drop(1.5, 20, 1, true, 0.2, 16384);
      drop(1, 20, 1, true, 0.5, 16384);
      drop(1, 20, 1, true, 1.0, 16384);  // the manager's default apron: the whole terrain here
      drop(1, 20, 1, false, 0, 16384, 2, false, true);
      drop(1, 20, 1, false, 0, 16384, 3, false, true);
      drop(1, 20, 1, true, 0.2, 16384, 2, false, true);
      break;
  }
  return v;
}

std::vector<bool> pareto_front(const std::vector<double>& cost, const std::vector<double>& error) {
  const std::size_t n = std::min(cost.size(), error.size());
  std::vector<bool> front(n, false);
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(cost[i]) || !std::isfinite(error[i])) continue;
    bool dominated = false;
    for (std::size_t j = 0; j < n && !dominated; ++j) {
      if (j == i || !std::isfinite(cost[j]) || !std::isfinite(error[j])) continue;
      dominated = cost[j] <= cost[i] && error[j] <= error[i] && (cost[j] < cost[i] || error[j] < error[i]);
    }
    front[i] = !dominated;
  }
  return front;
}

}  // namespace sandpatch
