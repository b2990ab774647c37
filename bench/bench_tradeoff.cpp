// bench tradeoff: what each knob users turn costs and what it gets wrong ("The trade,
// measured"; docs/tradeoff.md).
//
// Three reference cases, each run at every setting of the sweep:
//   pile    the angle of repose of a poured pile (particles/pile.hpp pour_pile, the pour and
//           cone fit of measure_repose on a simulation whose guard substeps at t_c / N): the
//           pile's world volume is fixed, so particle scale s pours 1/s^3 as many granules
//   crater  a sphere dropped into a settled granular bed (measure_crater below, straight on the
//           DEM): crater depth and rim volume from the particle surface before and after
//           (Uehara et al. 2003, PRL 90 194301, for the experiment and its depth law)
//   drop    a Bullet sphere dropped onto a small flat heightfield terrain driven by the real
//           TerrainManager in the frame of manager/run.cpp (bench/tradeoff_drop.hpp): crater
//           depth and volume read from the heightfield after demote_all, what a library user sees
// Error of a setting: relative to the reference (the finest setting of its case) — the pile's
// |angle − angle_ref| / angle_ref, the crater's max(|depth − ref| / ref, |rim − ref| / ref) (the
// rim term only when the reference's rim is at least a granule sphere radius high: lower, it is
// the roughness of the surface), the drop's the same with the crater volume as a third term.
// Cost: wall seconds of the measured phase and the real-time factor (simulated / wall seconds).
// A repeat of one setting with another seed gives each case's noise floor.
//
// Why the crater case runs straight on the DEM: a run pays the pre-settled tile at start-up and
// its patch is sized by the body, so the patch-size knob could not be turned; here one settled
// bed per scale is cut to every patch size, as the manager cuts its tiles. The knobs only the
// manager's path has are turned on the drop case:
//   substeps            the scene's Bullet steps per frame (run.cpp: BulletWorld::step_frame, dt /
//                       substeps each, the patch's force held over all of them)
//   granules_per_slot   slot capacity; a patch that needs more is refused by the manager (its
//                       error names simulation.pool.granules_per_slot): that setting's outcome
//                       is "refused", reported with the message, never an error of the bench
//   LOD on / off        on: the manager's contact prediction places the patch (apron swept,
//                       0.2 and 0.5 m; the default 1 m covers this small terrain whole); off: the
//                       whole terrain as particles from t = 0 (request_patch), kept to the end
// The drop's reference is LOD off (the whole terrain as particles, no patch edge near the
// sphere) at scale 1 and N = 50 with one Bullet substep, the scene default. The substeps rows
// found that the patch's force (BulletWorld::apply_force) reached only the first Bullet
// substep of a frame (Bullet clears applied forces after every stepSimulation): the sphere
// sank 3x as deep at 4 substeps. Fixed by BulletWorld::step_frame; docs/tradeoff.md.
//
// The entry is here; the other parts are listed in bench/tradeoff_internal.hpp.

#include "bench/bench_tradeoff.hpp"

#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

#include "bench/bench_util.hpp"
#include "bench/tradeoff_internal.hpp"
#include "gl/context.hpp"

namespace fs = std::filesystem;

namespace sandpatch {

using namespace tradeoff_internal;
using bench::load_average;

std::string check_bench_tradeoff_args(const BenchTradeoffArgs& a) {
  if (a.threads < 0) return "bench tradeoff: --threads = " + std::to_string(a.threads) + ": must be >= 0 (0 = all cores)";
  return "";
}

int run_bench_tradeoff(const BenchTradeoffArgs& a) {
  if (std::string e = check_bench_tradeoff_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  const fs::path out = a.out_dir.empty() ? fs::path("out") / (std::string("bench_tradeoff_") + to_string(a.sweep))
                                         : fs::path(a.out_dir);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    std::fprintf(stderr, "bench tradeoff: --out = %s: cannot create the directory%s\n", out.string().c_str(),
                 ec ? (": " + ec.message()).c_str() : "");
    return 2;
  }
  const int threads = a.threads > 0 ? a.threads : omp_get_num_procs();
  const double load_before = load_average();
  RunContext ctx;
  ctx.sweep = a.sweep;
  ctx.threads = threads;
  ctx.mat = reference_material();
  ctx.r = 0.005f;
  ctx.pile_n = tradeoff_pile_granules(a.sweep);
  const Material& mat = ctx.mat;
  const float r = ctx.r;
  const int pile_n = ctx.pile_n;
  CraterDef& cd = ctx.cd;
  cd.material = mat;
  cd.granule_radius = r;
  cd.threads = threads;
  if (a.sweep == TradeoffSweep::Quick) cd.impact_seconds = 0.2;
  std::vector<Row> rows;
  for (const auto& t : tradeoff_sweep(a.sweep)) rows.push_back(Row{t});
  // the settled bed of each (scale, seed) is the largest patch of the sweep at them
  for (const auto& row : rows)
    if (row.set.kind == TradeoffCase::Crater) {
      double& p = ctx.settle_size[{row.set.knobs.particle_scale, row.set.knobs.seed}];
      p = std::max(p, row.set.knobs.patch_radii);
    }
  // GL: one probe for a context (llvmpipe without a GPU)
  std::string& gl_skip = ctx.gl_skip;
  std::string gl_renderer;
  if (!a.gl) gl_skip = "--no-gl";
  else {
    auto gl_ctx = gl::Context::create();
    if (!gl_ctx) gl_skip = "no OpenGL 4.3 context: " + gl_ctx.message();
    else gl_renderer = (*gl_ctx)->info().gl_renderer;
  }
  std::vector<ojson> skipped;
  skipped.push_back({{"case", "pile"}, {"knob", "backend = gl"},
                     {"reason", "on llvmpipe a 400-granule pile takes tens of minutes (the GL pile is checked against "
                                "the CPU in tests/particles/gpu); the crater's gl setting measures the backend"}});
  skipped.push_back({{"case", "pile"}, {"knob", "patch size"},
                     {"reason", "the pile lies on its own fixed floor disc (0.2 m), not in a patch"}});
  skipped.push_back({{"case", "pile, crater"}, {"knob", "LOD on/off, simulation.substeps, slot capacity"},
                     {"reason", "these two run straight on the DEM, one patch and no Bullet; the drop case turns these "
                                "knobs through the TerrainManager"}});
  skipped.push_back({{"case", "drop"}, {"knob", "backend = gl, patch size"},
                     {"reason", "the crater case measures the backend on the same DEM; the drop's patch size is what "
                                "LOD on (the apron) or off (the whole terrain) makes it"}});

  std::printf("bench tradeoff (%s sweep): %zu settings, %d threads, load %.2f; pile of %d granules at scale 1, crater "
              "of a %.1f cm sphere (rho %.0f kg/m^3) dropped %.0f cm; material k_n %.0f N/m, e %.2f, mu %.2f, r %.1f mm\n",
              to_string(a.sweep), rows.size(), threads, load_before, pile_n, cd.sphere_radius * 100, cd.sphere_density,
              cd.drop_height * 100, mat.normal_stiffness, mat.restitution, mat.friction, r * 1000.0);
  std::fflush(stdout);
  for (auto& row : rows)
    if (const int rc = run_setting(row, ctx); rc != 0) return rc;

  const RimInError rim = score_rows(rows, ctx);
  return write_report(a, out, rows, ctx, rim, skipped, gl_renderer, load_before);
}

}  // namespace sandpatch
