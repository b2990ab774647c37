// bench dem: throughput of the CPU granule DEM on a settled bed (docs/BENCHMARKS.md).
//
// 1. build   granules on a loose lattice with random orientations in a walled box of the
//            peer's footprint (particles/bed.hpp)
// 2. settle  real parameters, dt = 5e-5 s, until the fastest granule (|v| + |w| reach) is
//            below 0.01 m/s, at least 0.3 s and at most 0.8 s of simulated time (a few
//            granules at the floor of large beds keep spinning; docs/dem.md)
// 3. time    `steps` steps of the settled bed with the same parameters and count contacts,
//            `repeat` times; the median block's rate is the result
#include "bench/bench.hpp"
#include "bench/bench_util.hpp"

#include <omp.h>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/hash.hpp"
#include "particles/bed.hpp"
#include "particles/contact_simd.hpp"
#include "particles/dem.hpp"

// Under `valgrind --tool=callgrind` the timed loop is dumped on its own (instruction counts
// that do not depend on the machine's load); with --instr-atstart=no the settling runs
// uninstrumented (several times faster). A no-op otherwise, and absent without the header.
#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define SP_CALLGRIND_ZERO() \
  do {                            \
    CALLGRIND_START_INSTRUMENTATION; \
    CALLGRIND_ZERO_STATS;         \
  } while (0)
#define SP_CALLGRIND_DUMP(name) CALLGRIND_DUMP_STATS_AT(name)
#else
#define SP_CALLGRIND_ZERO() ((void)0)
#define SP_CALLGRIND_DUMP(name) ((void)0)
#endif

namespace sandpatch {

using bench::process_cpu_seconds;

int run_bench_dem(const BenchDemArgs& a) {
  if (a.granules < 1 || a.granules > 4000000) {
    std::fprintf(stderr, "bench dem: --granules = %d: must be in [1, 4000000]\n", a.granules);
    return 2;
  }
  if (a.steps < 1) {
    std::fprintf(stderr, "bench dem: --steps = %d: must be >= 1\n", a.steps);
    return 2;
  }
  if (a.repeat < 1) {
    std::fprintf(stderr, "bench dem: --repeat = %d: must be >= 1\n", a.repeat);
    return 2;
  }
  if (a.threads < 0) {
    std::fprintf(stderr, "bench dem: --threads = %d: must be >= 0 (0 = all cores)\n", a.threads);
    return 2;
  }
  if (a.alternate_threads < 0 || (a.alternate_threads > 0 && a.repeat < 2)) {
    std::fprintf(stderr, "bench dem: --alternate-threads = %d: must be >= 1 with --repeat >= 2 (0 = off)\n",
                 a.alternate_threads);
    return 2;
  }
  if (a.backend != "cpu") {
    std::fprintf(stderr, "bench dem: --backend = %s: only 'cpu' is available in this build\n", a.backend.c_str());
    return 2;
  }
  const float r = 0.005f;
  const double dt = 5e-5;
  SimulationDef def;
  def.max_bodies = a.granules;
  def.max_particles = 4 * a.granules;
  def.particle_radius = r;
  def.material.density = 2500;
  def.material.normal_stiffness = 3292;
  def.material.restitution = a.restitution >= 0 ? float(a.restitution) : (a.unloading > 1.0 ? 1.0f : 0.3f);
  def.material.unloading_stiffness_ratio = float(a.unloading);
  def.material.friction = 0.5f;
  def.threads = a.threads;
  def.sleep_time = 0;  // never sleep: we time the work
  const float L = float(peer_footprint(a.granules, r));
  def.bounds_min = {0, 0, 0};
  def.side_walls = true;
  LatticeBedDef bed;
  const GranuleShape shape = make_granule_shape(r, def.granule_edge_factor, def.material.density);
  const float spacing = 2.0f * (shape.centre_distance + shape.radius) * 1.02f;
  bed.nx = bed.nz = std::max(1, int(std::floor((L - spacing) / spacing)) + 1);
  bed.layers = (a.granules + bed.nx * bed.nz - 1) / (bed.nx * bed.nz);
  bed.count = a.granules;
  bed.spacing = spacing;
  bed.min = {0.5f * (L - (bed.nx - 1) * spacing), shape.centre_distance + r + 1e-4f,
             0.5f * (L - (bed.nz - 1) * spacing)};
  bed.seed = 12345;
  def.bounds_max = {L, bed.min.y + bed.layers * spacing + 4 * r, L};
  auto sim = Simulation::create(def);
  if (!sim) {
    std::fprintf(stderr, "bench dem: %s", sim.message().c_str());
    return 2;
  }
  if (auto st = add_lattice_bed(*sim, bed); !st) {
    std::fprintf(stderr, "bench dem: %s", st.message().c_str());
    return 1;
  }
  const int threads = a.threads > 0 ? a.threads : omp_get_max_threads();
  const int spheres = sim->particle_count();
  // the pair kernel Simulation::create chose (SANDPATCH_DEM_KERNEL=scalar forces the scalar one)
  const char* kernel = simd::use_avx2_pair_kernel() ? "avx2" : "scalar";
  if (!a.json)
    std::printf("bench dem: %d granules (%d spheres), box %.3f m x %.3f m, %d layers, dt %g s, %d threads, %s pair kernel, "
                "normal spring %s (unloading ratio %g, restitution %g)\n",
                a.granules, spheres, L, L, bed.layers, dt, threads, kernel, a.unloading > 1.0 ? "hysteretic" : "linear",
                a.unloading, double(def.material.restitution));

  // settle
  auto t0 = std::chrono::steady_clock::now();
  int settle = 0;
  const int max_settle = int(0.8 / dt);
  for (; settle < max_settle; ++settle) {
    if (auto st = sim->step(dt); !st) {
      std::fprintf(stderr, "bench dem: settling: %s", st.message().c_str());
      return 1;
    }
    if (settle % 200 == 199 && settle * dt > 0.3 && sim->max_granule_speed() < 0.01) break;
  }
  double settle_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  double vmax_settled = sim->max_granule_speed();
  if (!a.json)
    std::printf("settled: %d steps (%.3f s simulated) in %.1f s wall, max granule speed %.4f m/s\n", settle + 1,
                (settle + 1) * dt, settle_s, vmax_settled);

  // timed: `repeat` blocks of `steps` steps one after the other on the same bed; the rate
  // reported is the median block's (this machine's load moves single runs by up to 1.6x)
  std::int64_t contacts = 0, wall_contacts = 0, resorts = 0, entries = 0;
  double stage_s[4] = {};  // guard, pairs, bodies, sort (StepStats), wall s over the --threads blocks
  std::vector<double> block_rate, block_cpu_ns;
  double wall = 0, cpu = 0;
  SP_CALLGRIND_ZERO();
  std::vector<double> alt_rate;  // blocks run with --alternate-threads
  for (int blk = 0; blk < a.repeat; ++blk) {
    const bool alt = a.alternate_threads > 0 && blk % 2 == 1;
    (void)sim->set_threads(alt ? a.alternate_threads : threads);  // (both validated above)
    const double cpu0 = process_cpu_seconds();
    t0 = std::chrono::steady_clock::now();
    double blk_stage[4] = {};
    for (int k = 0; k < a.steps; ++k) {
      if (auto st = sim->step(dt); !st) {
        std::fprintf(stderr, "bench dem: timed step %d: %s", blk * a.steps + k, st.message().c_str());
        return 1;
      }
      contacts += sim->last_step().contacts;
      wall_contacts += sim->last_step().wall_contacts;
      resorts += sim->last_step().resorts;
      entries += sim->last_step().neighbour_entries;
      const StepStats& ls = sim->last_step();
      blk_stage[0] += ls.guard_seconds, blk_stage[1] += ls.pair_seconds, blk_stage[2] += ls.body_seconds;
      blk_stage[3] += ls.sort_seconds;
    }
    const double w = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double c = process_cpu_seconds() - cpu0;
    if (alt) {
      alt_rate.push_back(double(spheres) * a.steps / w);
      if (!a.json)
        std::printf("block %d: %d steps with %d threads in %.3f s: %.3g sphere-steps/s\n", blk + 1, a.steps,
                    a.alternate_threads, w, alt_rate.back());
      continue;
    }
    wall += w;
    cpu += c;
    for (int k = 0; k < 4; ++k) stage_s[k] += blk_stage[k];
    block_rate.push_back(double(spheres) * a.steps / w);
    // CPU nanoseconds per sphere-step: the cost of the work whatever the load (with 1 thread;
    // with more it also holds the time threads spin at barriers)
    block_cpu_ns.push_back(1e9 * c / (double(spheres) * a.steps));
    if (!a.json && a.repeat > 1)
      std::printf("block %d: %d steps in %.3f s: %.3g sphere-steps/s, %.1f CPU ns per sphere-step\n", blk + 1, a.steps,
                  w, block_rate.back(), block_cpu_ns.back());
  }
  SP_CALLGRIND_DUMP("bench dem timed loop");
  const int total_steps = a.steps * a.repeat;
  auto median = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    const std::size_t m = v.size() / 2;
    return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
  };
  const double ssps = median(block_rate), cpu_ns = median(block_cpu_ns);
  const double best = *std::max_element(block_rate.begin(), block_rate.end());
  const double alt_ssps = alt_rate.empty() ? 0.0 : median(alt_rate);
  double cps = 2.0 * double(contacts) / total_steps / spheres;  // sphere-sphere contacts per sphere
  // the stages' wall nanoseconds per sphere-step, over the blocks run with --threads
  const int timed_blocks = int(block_rate.size());
  double stage_ns[4];
  for (int k = 0; k < 4; ++k) stage_ns[k] = 1e9 * stage_s[k] / (double(spheres) * a.steps * timed_blocks);
  if (!a.json) {
    if (a.repeat > 1)
      std::printf("timed: %d blocks of %d steps: median %.3g sphere-steps/s (best %.3g), %.1f CPU ns per sphere-step\n",
                  timed_blocks, a.steps, ssps, best, cpu_ns);
    else
      std::printf("timed: %d steps in %.3f s: %.3g sphere-steps/s (%.2f ms/step)\n", a.steps, wall, ssps,
                  1e3 * wall / a.steps);
    if (!alt_rate.empty())
      std::printf("alternate blocks, %d threads: median %.3g sphere-steps/s; %d threads / %d threads = %.2f\n",
                  a.alternate_threads, alt_ssps, threads, a.alternate_threads, ssps / alt_ssps);
    std::printf("cpu: %.3f s of CPU for %.3f s of wall (%.2f cores busy of %d threads), %.1f CPU ns per sphere-step\n",
                cpu, wall, cpu / wall, threads, cpu_ns);
    std::printf("contacts per sphere %.2f (sphere-sphere, other bodies), wall contacts per sphere %.3f, "
                "grid rebuilds %lld, max granule speed %.4f m/s\n",
                cps, double(wall_contacts) / total_steps / spheres, (long long)resorts, sim->max_granule_speed());
    std::printf("neighbour-list entries per sphere %.2f (pairs examined per sphere per step)\n",
                double(entries) / total_steps / spheres);
    std::printf("stages, wall ns per sphere-step (blocks with --threads): overlap guard %.1f, pair pass %.1f, "
                "body stage %.1f, sort + list %.1f\n",
                stage_ns[0], stage_ns[1], stage_ns[2], stage_ns[3]);
    std::printf("state hash %016llx after %d timed steps (same for any thread count and either pair kernel)\n",
                (unsigned long long)sim->state_hash(), total_steps);
  }
  nlohmann::json j = {{"bench", "dem"},
                      {"backend", a.backend},
                      {"granules", a.granules},
                      {"spheres", spheres},
                      {"steps", a.steps},
                      {"repeat", a.repeat},
                      {"alternate_threads", a.alternate_threads},
                      {"alternate_block_sphere_steps_per_s", alt_rate},
                      {"alternate_sphere_steps_per_s", alt_ssps},
                      {"block_sphere_steps_per_s", block_rate},
                      {"best_sphere_steps_per_s", best},
                      {"dt", dt},
                      {"threads", threads},
                      {"pair_kernel", kernel},
                      {"unloading_stiffness_ratio", a.unloading},
                      {"restitution", def.material.restitution},
                      {"wall_seconds", wall},
                      {"cpu_seconds", cpu},
                      {"cpu_ns_per_sphere_step", cpu_ns},
                      {"sphere_steps_per_s", ssps},
                      {"contacts_per_sphere", cps},
                      {"list_entries_per_sphere", double(entries) / total_steps / spheres},
                      {"stage_ns_per_sphere_step",
                       {{"guard", stage_ns[0]}, {"pairs", stage_ns[1]}, {"bodies", stage_ns[2]}, {"sort", stage_ns[3]}}},
                      {"grid_rebuilds", resorts},
                      {"settle_steps", settle + 1},
                      {"settled_max_speed", vmax_settled},
                      {"state_hash", Hasher::to_hex(sim->state_hash())},
                      {"contact_model", "linear spring-dashpot + tangential spring with history"}};
  if (a.json) std::printf("%s\n", j.dump().c_str());
  return 0;
}

}  // namespace sandpatch
