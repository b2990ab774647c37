// bench dem --backend gl; see bench_gl.hpp.
#include "particles/gpu/bench_gl.hpp"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <vector>

#include <nlohmann/json.hpp>

#include "gl/context.hpp"
#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "particles/gpu/gl_simulation.hpp"

namespace sandpatch::gpu {

int run_bench_dem_gl(int granules, int steps, int substeps, int workgroup, bool json, int idle_sims, int capacity) {
  if (granules < 1 || granules > 4000000) {
    std::fprintf(stderr, "bench dem: --granules = %d: must be in [1, 4000000]\n", granules);
    return 2;
  }
  if (steps < 1) {
    std::fprintf(stderr, "bench dem: --steps = %d: must be >= 1\n", steps);
    return 2;
  }
  if (substeps < 1 || substeps > 10000) {
    std::fprintf(stderr, "bench dem: --substeps = %d: must be in [1, 10000]\n", substeps);
    return 2;
  }
  if (capacity != 0 && (capacity < granules || capacity > 4000000)) {
    std::fprintf(stderr, "bench dem: --capacity = %d: must be 0 (the bed's) or in [--granules = %d, 4000000]\n", capacity, granules);
    return 2;
  }
  // 1. the bed of bench/bench_dem.cpp, through the public API
  const float r = 0.005f;
  const double dt = 5e-5;
  SimulationDef def;
  def.max_bodies = granules;
  def.max_particles = 4 * granules;
  def.particle_radius = r;
  def.material.density = 2500;
  def.material.normal_stiffness = 3292;
  def.material.restitution = 0.3f;
  def.material.friction = 0.5f;
  def.sleep_time = 0;  // never sleep: we time the work
  const float L = float(peer_footprint(granules, r));
  def.bounds_min = {0, 0, 0};
  def.side_walls = true;
  LatticeBedDef bed;
  const GranuleShape shape = make_granule_shape(r, def.granule_edge_factor, def.material.density);
  const float spacing = 2.0f * (shape.centre_distance + shape.radius) * 1.02f;
  bed.nx = bed.nz = std::max(1, int(std::floor((L - spacing) / spacing)) + 1);
  bed.layers = (granules + bed.nx * bed.nz - 1) / (bed.nx * bed.nz);
  bed.count = granules;
  bed.spacing = spacing;
  bed.min = {0.5f * (L - (bed.nx - 1) * spacing), shape.centre_distance + r + 1e-4f, 0.5f * (L - (bed.nz - 1) * spacing)};
  bed.seed = 12345;
  def.bounds_max = {L, bed.min.y + bed.layers * spacing + 4 * r, L};
  auto cpu = Simulation::create(def);
  if (!cpu) {
    std::fprintf(stderr, "bench dem: %s", cpu.message().c_str());
    return 2;
  }
  if (auto st = add_lattice_bed(*cpu, bed); !st) {
    std::fprintf(stderr, "bench dem: %s", st.message().c_str());
    return 1;
  }
  // 2. settle on the CPU backend (the GL path would take minutes on llvmpipe)
  auto t0 = std::chrono::steady_clock::now();
  int settle = 0;
  for (const int max_settle = int(1.5 / dt); settle < max_settle; ++settle) {
    if (auto st = cpu->step(dt); !st) {
      std::fprintf(stderr, "bench dem: settling: %s", st.message().c_str());
      return 1;
    }
    if (settle % 200 == 199 && settle * dt > 0.3 && cpu->max_granule_speed() < 0.01) break;
  }
  const double settle_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();

  // 3. the same bodies on the GPU (poses and velocities; tangential springs restart at 0)
  auto ctx = gl::Context::create();
  if (!ctx) {
    std::fprintf(stderr, "bench dem: %s", ctx.message().c_str());
    return 1;
  }
  const std::string renderer = (*ctx)->info().gl_renderer;
  GlOptions opt;
  opt.profile = std::getenv("SANDPATCH_GL_PROFILE") != nullptr;  // per-kernel GPU times
  if (workgroup > 0) opt.workgroup_size = workgroup;  // else GlOptions' default
  SimulationDef gdef = def;  // (--capacity: room for more granules than the bed, as a pool slot has)
  if (capacity > granules) gdef.max_bodies = capacity, gdef.max_particles = 4 * capacity;
  auto gsim = GlSimulation::create(gdef, opt);
  if (!gsim) {
    std::fprintf(stderr, "bench dem: %s", gsim.message().c_str());
    return 1;
  }
  for (int i = 0; i < cpu->body_count(); ++i) {
    BodyId b{i};
    auto id = gsim->add_granule(cpu->body_position(b), cpu->body_orientation(b), cpu->body_velocity(b),
                                cpu->body_angular_velocity(b));
    if (!id) {
      std::fprintf(stderr, "bench dem: %s", id.message().c_str());
      return 1;
    }
  }
  // the settled bed's contact springs too (docs/dem.md "Carried springs"): from positions alone
  // the bed would slip until its springs grew back, and the GL would time a bed the CPU's
  // beside it is not
  if (Status st = gsim->set_contact_springs(cpu->contact_springs()); !st) {
    std::fprintf(stderr, "bench dem: %s", st.message().c_str());
    return 1;
  }
  // (--idle-sims: as many more simulations of the bed, uploaded and never stepped)
  std::vector<GlSimulation> idle;
  for (int k = 0; k < idle_sims; ++k) {
    auto s = GlSimulation::create(gdef, opt);
    if (!s) {
      std::fprintf(stderr, "bench dem: idle simulation %d: %s", k, s.message().c_str());
      return 1;
    }
    for (int i = 0; i < cpu->body_count(); ++i)
      if (auto id = s->add_granule(cpu->body_position(BodyId{i}), cpu->body_orientation(BodyId{i})); !id) {
        std::fprintf(stderr, "bench dem: %s", id.message().c_str());
        return 1;
      }
    s->upload(std::numeric_limits<std::size_t>::max());
    idle.push_back(std::move(*s));
  }
  const int spheres = gsim->particle_count();
  if (!json)
    std::printf("bench dem (gl): %d granules (%d spheres), box %.3f m, %d layers, dt %g s\nrenderer: %s\n"
                "settled on the CPU backend: %d steps (%.3f s simulated) in %.1f s wall\n",
                granules, spheres, L, bed.layers, dt, renderer.c_str(), settle + 1, (settle + 1) * dt, settle_s);
  for (int k = 0; k < 20; ++k)  // warm-up: shader caches, springs re-formed
    if (auto st = gsim->step(dt); !st) {
      std::fprintf(stderr, "bench dem: warm-up step %d: %s", k, st.message().c_str());
      return 1;
    }

  // 4. timed (each step ends with the 32-byte status read-back, so the GPU has finished). A
  // step of `substeps` substeps is one frame of substeps x dt: the backend splits it into
  // substeps of at most its max_substep_dt (counted, not assumed).
  const double frame_dt = substeps * dt;
  std::int64_t contacts = 0, resorts = 0, gpu_substeps = 0;
  const std::vector<std::pair<std::string, double>> gpu_before = gsim->kernel_seconds();
  t0 = std::chrono::steady_clock::now();
  for (int k = 0; k < steps; ++k) {
    if (auto st = gsim->step(frame_dt); !st) {
      std::fprintf(stderr, "bench dem: timed step %d: %s", k, st.message().c_str());
      return 1;
    }
    contacts += gsim->last_step().contacts;
    resorts += gsim->last_step().resorts;
    gpu_substeps += gsim->last_step().substeps;
  }
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const double ssps = double(spheres) * double(gpu_substeps) / wall;
  const double cps = 2.0 * double(contacts) / steps / spheres;
  const double vmax = gsim->max_granule_speed();

  // 5. the CPU backend on the same settled bed, as many steps of dt as the GL backend ran
  // substeps, beside it (all OpenMP threads)
  const auto c0 = std::chrono::steady_clock::now();
  for (std::int64_t k = 0; k < gpu_substeps; ++k)
    if (auto st = cpu->step(dt); !st) {
      std::fprintf(stderr, "bench dem: CPU timed step %lld: %s", (long long)k, st.message().c_str());
      return 1;
    }
  const double cpu_wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - c0).count();
  const double cpu_ssps = double(cpu->particle_count()) * double(gpu_substeps) / cpu_wall;
  if (!json)
    std::printf("timed: %d steps (%lld substeps) in %.3f s: %.3g sphere-steps/s (%.3f ms/substep), contacts per sphere %.2f, "
                "grid rebuilds %lld, max granule speed %.4f m/s\n",
                steps, (long long)gpu_substeps, wall, ssps, 1e3 * wall / double(gpu_substeps), cps, (long long)resorts, vmax);
  if (!json)
    std::printf("CPU backend, same bed, as many steps: %.3g sphere-steps/s (%.3f ms/step); GL / CPU = %.3g\n", cpu_ssps,
                1e3 * cpu_wall / double(gpu_substeps), ssps / cpu_ssps);
  nlohmann::json j = {{"bench", "dem"},
                      {"backend", "gl"},
                      {"renderer", renderer},
                      {"granules", granules},
                      {"spheres", spheres},
                      {"steps", steps},
                      {"dt", dt},
                      {"wall_seconds", wall},
                      {"sphere_steps_per_s", ssps},
                      {"contacts_per_sphere", cps},
                      {"grid_rebuilds", resorts},
                      {"settle_steps_cpu", settle + 1},
                      {"max_granule_speed", vmax},
                      {"gpu_bytes", gsim->gpu_bytes()},
                      {"substeps_per_step", double(gpu_substeps) / steps},
                      {"workgroup_size", opt.workgroup_size},
                      {"idle_sims", idle_sims},
                      {"capacity_granules", capacity > granules ? capacity : granules},
                      {"substep_dt", frame_dt * steps / double(gpu_substeps)},
                      {"cpu_sphere_steps_per_s", cpu_ssps},
                      {"contact_model", "linear spring-dashpot + tangential spring with history"}};
  if (opt.profile) {  // GPU seconds of each kernel over the timed steps, against the wall time
    const auto after = gsim->kernel_seconds();
    double busy = 0;
    nlohmann::json kj = nlohmann::json::object();
    for (std::size_t k = 0; k < after.size(); ++k) {
      const double sec = after[k].second - gpu_before[k].second;
      busy += sec;
      kj[after[k].first] = sec;
      if (!json) std::printf("  %-26s %8.4f s GPU (%.1f %% of the wall time)\n", after[k].first.c_str(), sec, 100.0 * sec / wall);
    }
    if (!json) std::printf("  GPU busy %.4f s of %.4f s wall (%.1f %%)\n", busy, wall, 100.0 * busy / wall);
    j["kernel_gpu_seconds"] = kj;
    j["gpu_busy_seconds"] = busy;
  }
  if (json) std::printf("%s\n", j.dump().c_str());
  return 0;
}

}  // namespace sandpatch::gpu
