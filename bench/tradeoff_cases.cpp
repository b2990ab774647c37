// bench tradeoff: one setting of each case run into a Row (the pile, the crater, the drop; each
// prints its line), and the rows scored against their case's reference: errors, the noise
// repeats' scatter, the Pareto front (bench/tradeoff_internal.hpp).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "bench/impact.hpp"
#include "bench/tradeoff_internal.hpp"
#include "particles/dem.hpp"
#include "particles/pile.hpp"

namespace sandpatch::tradeoff_internal {

namespace {

// The pile of particles/pile.hpp on a simulation whose guard substeps at t_c / N.
int run_pile(Row& row, const RunContext& ctx) {
  const TradeoffKnobs& k = row.set.knobs;
  const Material& mat = ctx.mat;
  const float r = ctx.r;
  const int threads = ctx.threads, pile_n = ctx.pile_n;
  PileDef pd;
  pd.material = mat;
  pd.particle_radius = r;
  pd.granules = std::max(1, int(std::lround(pile_n / std::pow(k.particle_scale, 3))));
  pd.seed = k.seed;
  pd.threads = threads;
  SimulationDef sd = pile_simulation_def(pd);
  sd.accuracy_steps_per_contact = k.steps_per_contact;
  sd.max_substeps = 100000;
  auto sim = Simulation::create(sd);
  if (!sim) {
    std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), sim.message().c_str());
    return 1;
  }
  auto res = pour_pile(*sim, pd);
  if (!res) {
    std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
    return 1;
  }
  row.ran = true;
  row.wall_s = res->wall_seconds;
  row.sim_s = res->sim_seconds;
  row.granules = res->granules;
  row.dt = sim->last_step().substep_dt;
  row.contact_time = sim->contact_time();
  row.angle = res->angle_deg;
  row.residual = res->residual;
  row.peak = res->peak * k.particle_scale;
  row.at_rest = res->at_rest;
  row.fit_points = res->fit_points;
  std::printf("  %-28s %5d granules, dt t_c/%d: angle %6.2f deg (%d bins, %s), %.2f s simulated in %6.1f s wall "
              "(RTF %.4f)\n",
              row.set.id.c_str(), row.granules, k.steps_per_contact, row.angle, row.fit_points,
              row.at_rest ? "at rest" : "NOT at rest", row.sim_s, row.wall_s, row.sim_s / row.wall_s);
  return 0;
}

// The drop through the TerrainManager (bench/tradeoff_drop.hpp); a refusal is an outcome.
int run_drop(Row& row, const RunContext& ctx) {
  const TradeoffKnobs& k = row.set.knobs;
  const int threads = ctx.threads;
  DropDef dd = tradeoff_drop_def(ctx.sweep);
  dd.threads = threads;
  auto res = measure_drop(dd, k);
  if (!res) {
    std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
    return 1;
  }
  row.drop = *res;
  row.setup_s = res->setup_seconds;
  if (!res->refused) {
    // Against the experiment: Uehara et al.'s depth for this ball in a bed of the tiles' bulk
    // density (the spheres' solid fraction 0.527 of tiles settled at mu <= 0.2, manager/filling.cpp)
    // and the repose angle measured at friction 0.5 (35.9 deg, docs/dem.md); the ball as the soil
    // sees it (the shell spheres, r x scale, on its surface).
    const double rw = double(dd.granule_radius) * k.particle_scale;
    const double mu = repose_mu(0.5);  // (the tradeoff's sand, bench/tradeoff_sweep.cpp)
    const double d_exp = uehara_depth(mu, dd.sphere_density, 0.527 * dd.granule_density, 2 * (dd.sphere_radius + rw),
                                      dd.drop_height);
    if (d_exp > 0) row.error_experiment = std::abs(res->sphere_sink + rw - d_exp) / d_exp;
  }
  row.dt = res->dt;
  row.contact_time = res->contact_time;
  if (res->refused) {
    // the setting's outcome: the manager refused the patch (slot too small)
    row.refused = res->refusal;
    while (!row.refused.empty() && row.refused.back() == '\n') row.refused.pop_back();
    std::printf("  %-40s refused at t = %.3f s: %s\n", row.set.id.c_str(), res->refused_at, row.refused.c_str());
  } else {
    row.ran = true;
    row.wall_s = res->wall_seconds;
    row.sim_s = res->sim_seconds;
    row.granules = res->granules;
    std::printf("  %-40s %5d granules (%d patch%s), dt t_c/%d, %d Bullet substep%s: depth %5.2f cm, crater %6.0f "
                "cm^3 (r %.0f cm), rim %6.0f cm^3 (height %.2f cm), sphere sank %.2f cm (%.0f %% off Uehara et al.), "
                "rebound %.2f, far field %+.2f cm, ledger %+.2f %%, %s; "
                "%.2f s simulated in %6.1f s wall (RTF %.4f; DEM %.1f s; set-up %.1f s)\n",
                row.set.id.c_str(), row.granules, res->patches, res->patches == 1 ? "" : "es", k.steps_per_contact,
                k.substeps, k.substeps == 1 ? "" : "s", res->depth * 100, res->crater_volume * 1e6,
                res->crater_radius * 100, res->rim_volume * 1e6, res->rim_height * 100, res->sphere_sink * 100,
                row.error_experiment * 100, res->rebound_ratio, res->far_field_dh * 100, res->ledger_error_pct, res->asleep_at_end ? "asleep" : "awake", row.sim_s, row.wall_s,
                row.sim_s / row.wall_s, res->dem_seconds, row.setup_s);
  }
  return 0;
}

// The crater straight on the DEM (measure_crater), from the settled beds kept in ctx.
int run_crater(Row& row, RunContext& ctx) {
  const TradeoffKnobs& k = row.set.knobs;
  CraterDef d = ctx.cd;
  d.knobs = k;
  d.settle_patch_radii = ctx.settle_size[{k.particle_scale, k.seed}];
  auto res = measure_crater(d, &ctx.beds);
  if (!res) {
    std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
    return 1;
  }
  row.ran = true;
  row.crater = *res;
  {
    // Against the experiment, as the drop's (run_drop): Uehara et al.'s depth for this sphere
    // (as the soil sees it: its shell spheres, r x scale, on its surface) in a bed of the tiles'
    // bulk density (0.527 of the grain density: the bed is settled as the manager settles its
    // tiles) and the repose angle measured at friction 0.5 (35.9 deg, docs/dem.md), against the
    // sphere's final penetration.
    const double rw = double(d.granule_radius) * k.particle_scale;
    const double mu = repose_mu(0.5);  // (the tradeoff's sand, bench/tradeoff_sweep.cpp)
    const double d_exp = uehara_depth(mu, d.sphere_density, 0.527 * double(d.material.density),
                                      2 * (d.sphere_radius + rw), d.drop_height);
    if (d_exp > 0) row.error_experiment = std::abs(res->sphere_sink + rw - d_exp) / d_exp;
  }
  row.wall_s = res->wall_seconds;
  row.sim_s = res->sim_seconds;
  row.setup_s = res->setup_seconds;
  row.granules = res->granules;
  row.dt = res->dt;
  row.contact_time = res->contact_time;
  std::printf("  %-28s %5d granules, dt t_c/%d: depth %5.2f cm, rim %6.1f cm^3 (height %.2f cm), crater r %.1f cm, "
              "sphere sank %.2f cm (%.0f %% off Uehara et al.); %.2f s simulated in %6.1f s wall (RTF %.4f; set-up %.1f s)\n",
              row.set.id.c_str(), row.granules, k.steps_per_contact, res->depth * 100, res->rim_volume * 1e6,
              res->rim_height * 100, res->crater_radius * 100, res->sphere_sink * 100, row.error_experiment * 100, row.sim_s,
              row.wall_s, row.sim_s / row.wall_s, row.setup_s);
  return 0;
}

}  // namespace

int run_setting(Row& row, RunContext& ctx) {
  if (row.set.kind == TradeoffCase::Crater && row.set.knobs.backend == "gl" && !ctx.gl_skip.empty()) {
    row.skipped = ctx.gl_skip;
    std::printf("  %-28s skipped: %s\n", row.set.id.c_str(), ctx.gl_skip.c_str());
    return 0;
  }
  const int rc = row.set.kind == TradeoffCase::Pile   ? run_pile(row, ctx)
                 : row.set.kind == TradeoffCase::Drop ? run_drop(row, ctx)
                                                      : run_crater(row, ctx);
  if (rc != 0) return rc;
  std::fflush(stdout);
  return 0;
}

RimInError score_rows(std::vector<Row>& rows, const RunContext& ctx) {
  RimInError out;
  for (TradeoffCase c : {TradeoffCase::Pile, TradeoffCase::Crater, TradeoffCase::Drop}) {
    const Row* ref = nullptr;
    for (const auto& row : rows)
      if (row.set.kind == c && row.set.reference && row.ran) ref = &row;
    if (!ref) continue;
    // the rim counts only when the reference resolves one: at least a granule sphere radius
    // high (world) — lower, it is the roughness of a granular surface
    const bool rim_resolved =
        (c == TradeoffCase::Crater && ref->crater.rim_volume > 0 &&
         ref->crater.rim_height >= double(ctx.r) * ref->set.knobs.particle_scale) ||
        (c == TradeoffCase::Drop && ref->drop.rim_volume > 0 &&
         ref->drop.rim_height >= double(tradeoff_drop_def(ctx.sweep).granule_radius) * ref->set.knobs.particle_scale);
    if (c == TradeoffCase::Crater) out.crater = rim_resolved;
    if (c == TradeoffCase::Drop) out.drop = rim_resolved;
    auto rel = [](double x, double x_ref) { return x_ref > 0 ? std::abs(x - x_ref) / x_ref : NAN; };
    for (auto& row : rows) {
      if (row.set.kind != c || !row.ran) continue;
      if (c == TradeoffCase::Pile) {
        row.error_a = ref->angle != 0 ? std::abs(row.angle - ref->angle) / std::abs(ref->angle) : NAN;
        row.error = row.error_a;
      } else if (c == TradeoffCase::Crater) {
        row.error_a = rel(row.crater.depth, ref->crater.depth);
        row.error_b = rim_resolved ? rel(row.crater.rim_volume, ref->crater.rim_volume) : NAN;
        row.error = std::isfinite(row.error_b) ? std::max(row.error_a, row.error_b) : row.error_a;
      } else {
        // drop: the worst of depth, crater volume and (when resolved) rim volume
        row.error_a = rel(row.drop.depth, ref->drop.depth);
        row.error_v = rel(row.drop.crater_volume, ref->drop.crater_volume);
        row.error_b = rim_resolved ? rel(row.drop.rim_volume, ref->drop.rim_volume) : NAN;
        row.error = row.error_a;
        for (double e : {row.error_v, row.error_b})
          if (std::isfinite(e)) row.error = std::isfinite(row.error) ? std::max(row.error, e) : e;
      }
    }
    // noise floor: a repeat with another seed against its seed-1 twin (same knobs), relative to the reference
    for (auto& row : rows) {
      if (row.set.kind != c || !row.ran || !row.set.noise) continue;
      for (const auto& twin : rows) {
        const auto &ka = row.set.knobs, &kb = twin.set.knobs;
        if (twin.set.kind != c || !twin.ran || twin.set.noise || ka.particle_scale != kb.particle_scale ||
            ka.steps_per_contact != kb.steps_per_contact || ka.patch_radii != kb.patch_radii ||
            ka.backend != kb.backend || ka.substeps != kb.substeps || ka.lod != kb.lod ||
            ka.lod_apron != kb.lod_apron || ka.granules_per_slot != kb.granules_per_slot)
          continue;
        if (c == TradeoffCase::Pile) {
          row.scatter = std::abs(row.angle - twin.angle) / std::abs(ref->angle);
        } else if (c == TradeoffCase::Crater) {
          const double sd = std::abs(row.crater.depth - twin.crater.depth) / ref->crater.depth;
          const double sr = rim_resolved
                                ? std::abs(row.crater.rim_volume - twin.crater.rim_volume) / ref->crater.rim_volume
                                : NAN;
          row.scatter = std::isfinite(sr) ? std::max(sd, sr) : sd;
        } else {
          double sc = std::abs(row.drop.depth - twin.drop.depth) / ref->drop.depth;
          if (ref->drop.crater_volume > 0)
            sc = std::max(sc, std::abs(row.drop.crater_volume - twin.drop.crater_volume) / ref->drop.crater_volume);
          if (rim_resolved) sc = std::max(sc, std::abs(row.drop.rim_volume - twin.drop.rim_volume) / ref->drop.rim_volume);
          row.scatter = sc;
        }
      }
    }
    std::vector<double> cost, err;
    std::vector<Row*> in;
    for (auto& row : rows)
      if (row.set.kind == c && row.ran && !row.set.noise) {
        in.push_back(&row);
        cost.push_back(row.wall_s / row.sim_s);
        err.push_back(row.error);
      }
    const auto front = pareto_front(cost, err);
    for (std::size_t i = 0; i < in.size(); ++i) in[i]->pareto = front[i];
  }
  return out;
}

}  // namespace sandpatch::tradeoff_internal
