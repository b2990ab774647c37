// tests particles/gpu/gl_simulation.cpp against the CPU backend (particles/dem.cpp): forces
// on a fixed random configuration, trajectories over 200 steps, determinism, errors and GL
// object clean-up. Small particle counts: this runs on llvmpipe in CI.
#include "particles/gpu/gl_simulation.hpp"

#include <GL/glcorearb.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <chrono>
#include <limits>
#include <map>
#include <memory>
#include <tuple>

#include "gl/context.hpp"
#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "particles/gpu/gl_impl.hpp"  // the kernels' order (Kernel)
#include "particles/gpu/layout.hpp"
#include "tests/particles/gpu/gl_test_util.hpp"
#include "tests/particles/head_on.hpp"
#include "tests/particles/jointed_shells.hpp"
#include "tests/particles/springs_common.hpp"

namespace sandpatch::gpu {
namespace {

using namespace testutil;

// Both backends get the same bodies from `add` (called once per backend).
template <class F>
void add_both(Simulation& cpu, GlSimulation& gpu, F&& add) {
  add([&](const ShellDef& sh) {
    ASSERT_TRUE(cpu.add_shell(sh).ok());
    ASSERT_TRUE(gpu.add_shell(sh).ok());
  }, [&](Vec3 x, Quat q, Vec3 v, Vec3 w) {
    ASSERT_TRUE(cpu.add_granule(x, q, v, w).ok());
    ASSERT_TRUE(gpu.add_granule(x, q, v, w).ok());
  });
}

// A fixed random configuration: single-sphere dynamic shells on a jittered lattice (spacing
// just under a diameter, so most neighbours overlap by up to ~3 % of r) touching the floor
// and the walls, with random velocities and spins; a cluster of 24 spheres above the top of
// the bounds (all binned into the top cells: a crowded cell, no cap); static floor spheres
// and a kinematic sphere; and a few granules. A single-sphere body's force is its sphere's.
void random_configuration(Simulation& cpu, GlSimulation& gpu, std::vector<int>* singles) {
  const SimulationDef& d = cpu.def();
  const float r = d.particle_radius;
  const float ms = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  std::uint64_t seed = 42;
  int body = 0;
  add_both(cpu, gpu, [&](auto shell, auto granule) {
    auto sphere = [&](Vec3 x, Vec3 v, Vec3 w, MotionType m) {
      ShellDef sh;
      sh.offsets = {Vec3{}};
      sh.radii = {r};
      sh.motion = m;
      if (m == MotionType::Dynamic) {
        sh.mass = ms;
        sh.inertia = {0.4f * ms * r * r, 0.4f * ms * r * r, 0.4f * ms * r * r};
      }
      sh.position = x;
      sh.velocity = v;
      sh.angular_velocity = w;
      shell(sh);
      if (singles && m == MotionType::Dynamic) singles->push_back(body);
      ++body;
    };
    const float a = 1.97f * r;
    for (int k = 0; k < 6; ++k)
      for (int j = 0; j < 6; ++j)
        for (int i = 0; i < 7; ++i) {
          Vec3 x{0.99f * r + i * a + 0.03f * r * srand1(seed), 0.985f * r + j * a + 0.03f * r * urand(seed),
                 0.99f * r + k * a + 0.03f * r * srand1(seed)};
          Vec3 v{0.2f * srand1(seed), 0.2f * srand1(seed), 0.2f * srand1(seed)};
          Vec3 w{30.0f * srand1(seed), 30.0f * srand1(seed), 30.0f * srand1(seed)};
          sphere(x, v, w, MotionType::Dynamic);
        }
    // crowded: above the bounds, binned into the top cells
    for (int k = 0; k < 24; ++k)
      sphere({0.04f + 0.5f * r * float(k % 3), 0.085f + 1.9f * r * float(k / 3), 0.04f + 0.3f * r * float(k % 2)},
             {0.1f * srand1(seed), 0, 0}, {}, MotionType::Dynamic);
    // static floor spheres under a second group, and a kinematic sphere
    for (int i = 0; i < 5; ++i) sphere({0.05f + i * 2.0f * r, 0.0f, 0.07f}, {}, {}, MotionType::Static);
    for (int i = 0; i < 5; ++i)
      sphere({0.05f + i * 2.0f * r + 0.2f * r, 1.97f * r, 0.07f}, {0.05f * srand1(seed), -0.1f, 0}, {}, MotionType::Dynamic);
    sphere({0.07f, 0.06f, 0.07f}, {0.1f, 0, 0}, {}, MotionType::Kinematic);
    for (int i = 0; i < 5; ++i)
      sphere({0.07f + (i - 2) * 0.8f * r, 0.06f + ((i & 1) ? 1.9f : -1.9f) * r, 0.07f}, {0, 0, 0.1f}, {},
             MotionType::Dynamic);
    // granules overlapping each other a little, in the free corner
    for (int i = 0; i < 6; ++i) {
      granule({0.062f + (i % 2) * 3.3f * r, 0.02f + (i / 2) * 3.3f * r, 0.062f}, random_quat(seed),
              {0.1f * srand1(seed), 0.1f * srand1(seed), 0}, {20.0f * srand1(seed), 0, 20.0f * srand1(seed)});
      body++;
    }
  });
}

struct Compare {
  double worst_rel = 0, worst_abs = 0;
  int failures = 0, checked = 0, nonzero = 0;
  // within 1e-4 relative or 1e-6 absolute
  void check(Vec3 g, Vec3 c, const char* what, int body) {
    const double diff = norm(g - c), mag = norm(c);
    ++checked;
    if (mag > 1e-6) ++nonzero;
    worst_abs = std::max(worst_abs, diff);
    if (mag > 1e-6) worst_rel = std::max(worst_rel, diff / mag);
    if (diff > 1e-4 * mag && diff > 1e-6) {
      if (++failures < 10)
        ADD_FAILURE() << what << " of body " << body << ": gpu (" << g.x << ", " << g.y << ", " << g.z << ") cpu ("
                      << c.x << ", " << c.y << ", " << c.z << ")";
    }
  }
};

void forces_match(ShearLaw law, float height = 0.08f) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(law);
  d.bounds_max.y = height;
  auto cpu = Simulation::create(d);
  ASSERT_TRUE(cpu.ok()) << cpu.message();
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(gpu.ok()) << gpu.message();
  std::vector<int> singles;
  random_configuration(*cpu, *gpu, &singles);
  // one substep: the forces of the last substep are those of the configuration above
  const double dt = 0.9 * cpu->max_substep_dt();
  ASSERT_EQ(*gpu->substeps_for(dt), 1);
  ASSERT_TRUE(cpu->step(dt).ok());
  auto st = gpu->step(dt);
  ASSERT_TRUE(st.ok()) << st.message();
  EXPECT_EQ(gpu->last_step().contacts, cpu->last_step().contacts);
  EXPECT_EQ(gpu->last_step().wall_contacts, cpu->last_step().wall_contacts);
  EXPECT_GT(cpu->last_step().contacts, 300);
  Compare cmp;
  for (int b = 0; b < cpu->body_count(); ++b) {
    cmp.check(gpu->body_force({b}), cpu->body_force({b}), "force", b);
    cmp.check(gpu->body_torque({b}), cpu->body_torque({b}), "torque", b);
  }
  std::printf("%d bodies (%zu single spheres), %lld contacts, %lld wall contacts: %d of %d vectors non-zero; "
              "worst relative difference %.3g, worst absolute %.3g N\n",
              cpu->body_count(), singles.size(), (long long)cpu->last_step().contacts,
              (long long)cpu->last_step().wall_contacts, cmp.nonzero, cmp.checked, cmp.worst_rel, cmp.worst_abs);
  EXPECT_EQ(cmp.failures, 0);
  // the sphere forces by id agree with the body forces of the single spheres
  auto pf = gpu->particle_forces();
  for (int b : singles) EXPECT_EQ(norm(pf[b] - gpu->body_force({b})), 0.0f);  // body b has particle id b
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

TEST(GlSimulation, ForcesMatchCpuOnRandomConfiguration) { forces_match(ShearLaw::SpringHistory); }
// The same in a taller box: 8 x 37 x 8 = 2368 cells of 2 r + skin = 0.011 m, three blocks of
// the grid's prefix sum (1024 cells each, scan_blocks.comp), whose offsets the scatter, the
// gather and the final cell starts add (common.glsl cell_begin, grid_copyback.comp).
TEST(GlSimulation, ForcesMatchCpuAcrossScanBlocks) { forces_match(ShearLaw::SpringHistory, 0.4f); }

// Head-on collision through the GL backend (tests/particles/head_on.hpp; the CPU's
// HeadOn.RestitutionAndContactTime): at dt = t_clamped/50, for e = 0.1, 0.5, 0.9, sphere pairs
// and a sphere onto the floor, 4 phases of the touch: e within 2 % of the requested e and the
// contact time within 2 % of the clamped law's, and the same numbers as the CPU
// backend's to 1e-3 of e (the shaders predict the velocities and flag a contact's first substep
// as dem.cpp does; docs/dem.md "Step size").
TEST(GlSimulation, HeadOnRestitutionAndContactTime) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  for (bool floor : {false, true})
    for (double e : {0.1, 0.5, 0.9}) {
      const auto g = ::sandpatch::testutil::head_on<GlSimulation>(
          [](const SimulationDef& d) { return GlSimulation::create(d); }, e, 50, 4, floor);
      const auto c = ::sandpatch::testutil::head_on<Simulation>(
          [](const SimulationDef& d) { return Simulation::create(d); }, e, 50, 4, floor);
      std::printf("%s e %.1f, dt = t_clamped/50: gl e %+.2f%%..%+.2f%%, contact %+.2f%%..%+.2f%%; "
                  "cpu e %+.2f%%..%+.2f%%\n",
                  floor ? "floor" : "pair ", e, 100 * (g.e_lo / e - 1), 100 * (g.e_hi / e - 1),
                  100 * (g.t_lo / g.t_clamped - 1), 100 * (g.t_hi / g.t_clamped - 1), 100 * (c.e_lo / e - 1),
                  100 * (c.e_hi / e - 1));
      for (double em : {g.e_lo, g.e_hi}) EXPECT_NEAR(em, e, 0.02 * e) << (floor ? "floor" : "pair") << " e " << e;
      for (double tm : {g.t_lo, g.t_hi})
        EXPECT_NEAR(tm, g.t_clamped, 0.02 * g.t_clamped) << (floor ? "floor" : "pair") << " e " << e;
      EXPECT_NEAR(g.e_lo, c.e_lo, 1e-3 * e);
      EXPECT_NEAR(g.e_hi, c.e_hi, 1e-3 * e);
    }
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// The hysteretic normal spring on the GL backend (dmax in the spring slots and the planes' w):
// with no dashpot (restitution 1) a binary collision rebounds at e = 1/sqrt(lambda) (Walton &
// Braun), lambda = 4 and 11.1, pairs and the floor, 4 phases at dt = t_clamped/50: within 1 % of
// 1/sqrt(lambda) (the CPU's HeadOnHysteretic.RestitutionIsOneOverRootLambda measures
// 0.4998 ... 0.5002 and 0.2998 ... 0.3001) and the CPU backend's numbers to 1e-3 of e.
TEST(GlSimulation, HystereticRestitutionIsOneOverRootLambda) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  for (float lambda : {4.0f, 11.111111f})
    for (bool floor : {false, true}) {
      const auto g = ::sandpatch::testutil::head_on<GlSimulation>(
          [](const SimulationDef& d) { return GlSimulation::create(d); }, 1.0, 50, 4, floor, lambda);
      const auto c = ::sandpatch::testutil::head_on<Simulation>(
          [](const SimulationDef& d) { return Simulation::create(d); }, 1.0, 50, 4, floor, lambda);
      const double e = 1.0 / std::sqrt(double(lambda));
      std::printf("hysteretic lambda %.3f %s: gl e %.4f ... %.4f, cpu %.4f ... %.4f (1/sqrt(lambda) = %.4f)\n", lambda,
                  floor ? "floor" : "pair ", g.e_lo, g.e_hi, c.e_lo, c.e_hi, e);
      for (double em : {g.e_lo, g.e_hi}) EXPECT_NEAR(em, e, 0.01 * e) << (floor ? "floor" : "pair") << " lambda " << lambda;
      EXPECT_NEAR(g.e_lo, c.e_lo, 1e-3 * e);
      EXPECT_NEAR(g.e_hi, c.e_hi, 1e-3 * e);
    }
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

template <class A, class B>
double max_dev(const A& a, const B& b) {
  auto pa = a.particle_positions(), pb = b.particle_positions();
  double m = 0;
  for (std::size_t i = 0; i < pa.size(); ++i) m = std::max(m, double(norm(pa[i] - pb[i])));
  return m;
}

// Terrain outside the filled rectangle (TerrainGrid): single spheres pressed into a bumpy
// height grid around the fill, plus granules resting on it; forces within the same
// tolerance, then 100 steps on the terrain stay within 1e-6 m of the CPU.
// A single sphere (a dynamic shell of the granules' radius) pressed 0.05-0.1 r into the terrain
// at (x, z); moving: with a random velocity and spin.
ShellDef sphere_on_terrain(const SimulationDef& d, float x, float z, bool moving, std::uint64_t& seed) {
  const float r = d.particle_radius;
  const float ms = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  ShellDef sh;
  sh.offsets = {Vec3{}};
  sh.radii = {r};
  sh.motion = MotionType::Dynamic;
  sh.mass = ms;
  sh.inertia = {0.4f * ms * r * r, 0.4f * ms * r * r, 0.4f * ms * r * r};
  sh.position = {x, d.terrain.height(x, z) + (0.9f + 0.05f * urand(seed)) * r, z};
  if (moving) {
    sh.velocity = {0.1f * srand1(seed), 0.0f, 0.1f * srand1(seed)};
    sh.angular_velocity = {10.0f * srand1(seed), 0, 10.0f * srand1(seed)};
  }
  return sh;
}

// One substep on both backends: the same plane-contact count (at least `spheres`), every body's
// force and torque within Compare's tolerance; then `more` substeps: positions within 1e-6 m.
void expect_terrain_contacts_agree(Simulation& cpu, GlSimulation& gpu, int spheres, int more) {
  const double dt = 0.9 * cpu.max_substep_dt();
  ASSERT_TRUE(cpu.step(dt).ok());
  ASSERT_TRUE(gpu.step(dt).ok());
  EXPECT_EQ(gpu.last_step().wall_contacts, cpu.last_step().wall_contacts);
  EXPECT_GE(cpu.last_step().wall_contacts, spheres);
  Compare cmp;
  for (int b = 0; b < cpu.body_count(); ++b) {
    cmp.check(gpu.body_force({b}), cpu.body_force({b}), "force", b);
    cmp.check(gpu.body_torque({b}), cpu.body_torque({b}), "torque", b);
  }
  std::printf("%d spheres on the terrain, %lld plane contacts: worst relative difference %.3g, absolute %.3g\n",
              spheres, (long long)cpu.last_step().wall_contacts, cmp.worst_rel, cmp.worst_abs);
  EXPECT_EQ(cmp.failures, 0);
  for (int s = 0; s < more; ++s) {
    ASSERT_TRUE(cpu.step(dt).ok());
    ASSERT_TRUE(gpu.step(dt).ok());
  }
  const double dev = max_dev(gpu, cpu);
  std::printf("after %d more substeps on the terrain: max position difference %.3g m\n", more, dev);
  EXPECT_LT(dev, 1e-6);
}

// The box without side walls over an n x n terrain grid at `spacing` (m) from the origin; the
// caller gives its heights and filled rectangle.
SimulationDef box_on_terrain(int n, float spacing) {
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.side_walls = false;
  d.terrain.nx = d.terrain.nz = n;
  d.terrain.x0 = d.terrain.z0 = 0.0f;
  d.terrain.spacing = spacing;
  return d;
}

TEST(GlSimulation, TerrainForcesMatchCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_on_terrain(6, 0.016f);
  TerrainGrid& t = d.terrain;
  std::uint64_t seed = 5;
  for (int k = 0; k < t.nx * t.nz; ++k) t.heights.push_back(0.004f + 0.006f * urand(seed));
  t.fill_min_x = t.fill_min_z = 0.03f;
  t.fill_max_x = t.fill_max_z = 0.05f;
  auto cpu = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && gpu.ok()) << gpu.message();
  int on_terrain = 0;
  for (int k = 0; k < 8; ++k)
    for (int i = 0; i < 8; ++i) {
      const float x = 0.005f + i * 0.01f, z = 0.005f + k * 0.01f;
      if (x > t.fill_min_x && x < t.fill_max_x && z > t.fill_min_z && z < t.fill_max_z) continue;
      const ShellDef sh = sphere_on_terrain(d, x, z, true, seed);
      ASSERT_TRUE(cpu->add_shell(sh).ok());
      ASSERT_TRUE(gpu->add_shell(sh).ok());
      ++on_terrain;
    }
  expect_terrain_contacts_agree(*cpu, *gpu, on_terrain, 100);
}

// A host write longer than one dispatch of copy_words.comp (65,535 workgroups): at workgroup
// size 1 a 300 x 300 terrain's 90,000 heights go in two dispatches. Spheres on its last rows,
// whose heights the second dispatch wrote, feel the same terrain as on the CPU.
TEST(GlSimulation, WriteLongerThanOneDispatchMatchesCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_on_terrain(300, 0.08f / 299.0f);
  TerrainGrid& t = d.terrain;
  for (int iz = 0; iz < t.nz; ++iz)
    for (int ix = 0; ix < t.nx; ++ix)
      t.heights.push_back(0.006f + 0.002f * std::sin(40.0f * ix * t.spacing) * std::cos(50.0f * iz * t.spacing));
  t.fill_min_x = t.fill_min_z = 0.002f;  // a small filled corner, away from the spheres
  t.fill_max_x = t.fill_max_z = 0.004f;
  GlOptions o;
  o.workgroup_size = 1;
  ASSERT_GT(t.heights.size(), std::size_t(65535) * std::size_t(o.workgroup_size));
  auto cpu = Simulation::create(d);
  auto gpu = GlSimulation::create(d, o);
  ASSERT_TRUE(cpu.ok() && gpu.ok()) << gpu.message();
  std::uint64_t seed = 9;
  int n = 0;
  for (int k = 0; k < 2; ++k)
    for (int i = 0; i < 6; ++i, ++n) {
      const float x = 0.006f + 0.0125f * i, z = 0.062f + 0.012f * k;  // rows 231-278 of 300
      const ShellDef sh = sphere_on_terrain(d, x, z, false, seed);
      ASSERT_TRUE(cpu->add_shell(sh).ok());
      ASSERT_TRUE(gpu->add_shell(sh).ok());
    }
  expect_terrain_contacts_agree(*cpu, *gpu, n, 20);
}

// A small granule bed dropped into the box: 150 granules (600 spheres) on a loose lattice
// with random orientations and velocities, so they fall, collide and pile up over the run.
template <class Sim>
void drop_bed(Sim& sim, float nudge) {
  std::uint64_t seed = 7;
  const float r = sim.def().particle_radius;
  const float a = 4.6f * r;
  int n = 0;
  for (int l = 0; l < 6; ++l)
    for (int k = 0; k < 5; ++k)
      for (int i = 0; i < 5; ++i, ++n) {
        Vec3 x{0.012f + i * a + 0.3f * r * srand1(seed), 0.008f + l * a, 0.012f + k * a + 0.3f * r * srand1(seed)};
        if (nudge != 0.0f) x.x = std::nextafter(x.x, 1.0f);  // one ulp
        Quat q = random_quat(seed);
        Vec3 v{0.2f * srand1(seed), -0.3f + 0.2f * srand1(seed), 0.2f * srand1(seed)};
        Vec3 w{10.0f * srand1(seed), 10.0f * srand1(seed), 10.0f * srand1(seed)};
        ASSERT_TRUE(sim.add_granule(x, q, v, w).ok());
      }
}

// 200 steps of dt = 5e-5 s from the same start. Reference for "round-off": the CPU run
// against a CPU run whose granules start one ulp apart in x (a perturbation of the size of
// one rounding). The GL run differs from the CPU by round-off in every operation, so its
// deviation starts larger than the one-ulp run's but must grow no faster: at every step
// after the first 10, dev_gl(t) <= 20 dev_ulp(t) * dev_gl(10)/dev_ulp(10) (same growth within
// a factor 20), and it stays below 0.01 particle diameters (a one-ulp CPU run reaches 2.4e-5 m
// = 0.0024 d by step 200, when a contact starts or slips one step apart).
// The same with the hysteretic normal spring (TrajectoriesAgreeOver200StepsHysteretic: lambda =
// 11.1, restitution 1), whose dmax the GL keeps in its spring slots.
void trajectories_agree(float lambda) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.material.unloading_stiffness_ratio = lambda;
  if (lambda > 1.0f) d.material.restitution = 1.0f;
  auto cpu = Simulation::create(d);
  auto cpu2 = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && cpu2.ok() && gpu.ok()) << gpu.message();
  drop_bed(*cpu, 0.0f);
  drop_bed(*cpu2, 1.0f);
  drop_bed(*gpu, 0.0f);
  const double dt = 5e-5;
  std::vector<double> dev_gl, dev_ulp;
  std::int64_t contacts = 0;
  for (int s = 1; s <= 200; ++s) {
    auto sc = cpu->step(dt);
    ASSERT_TRUE(sc.ok()) << sc.message();
    ASSERT_TRUE(cpu2->step(dt).ok());
    auto st = gpu->step(dt);
    ASSERT_TRUE(st.ok()) << st.message();
    contacts += cpu->last_step().contacts;
    dev_gl.push_back(max_dev(*gpu, *cpu));
    dev_ulp.push_back(max_dev(*cpu2, *cpu));
  }
  std::printf("step  dev_gl(m)  dev_1ulp(m)\n");
  for (int s : {1, 2, 5, 10, 20, 50, 100, 150, 200})
    std::printf("%4d  %.3e  %.3e\n", s, dev_gl[s - 1], dev_ulp[s - 1]);
  std::printf("sphere-sphere contacts per step (CPU): %.1f\n", double(contacts) / 200);
  EXPECT_GT(contacts, 200 * 20) << "the bed must collide during the run";
  const double d10 = std::max(dev_gl[9], 1e-9), u10 = std::max(dev_ulp[9], 1e-12);
  for (int s = 10; s < 200; ++s)
    EXPECT_LE(dev_gl[s], 20.0 * std::max(dev_ulp[s], 1e-12) * d10 / u10 + 1e-7) << "step " << s + 1;
  EXPECT_LT(dev_gl[199], 1e-2 * 2 * d.particle_radius);
}
TEST(GlSimulation, TrajectoriesAgreeOver200Steps) { trajectories_agree(1.0f); }
TEST(GlSimulation, TrajectoriesAgreeOver200StepsHysteretic) { trajectories_agree(11.111111f); }

// A square plate shell of n x n spheres of radius r, 1.6 r apart in x and z, moving down at
// 0.5 m/s (a body of more than kWideSpheres spheres for n >= 6).
ShellDef wide_plate(const SimulationDef& d, int n, Vec3 centre, MotionType m) {
  const float r = d.particle_radius;
  const float ms = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  ShellDef sh;
  const float a = 1.6f * r;
  for (int k = 0; k < n; ++k)
    for (int i = 0; i < n; ++i) sh.offsets.push_back({(i - 0.5f * (n - 1)) * a, 0.0f, (k - 0.5f * (n - 1)) * a});
  sh.radii = {r};
  sh.motion = m;
  if (m == MotionType::Dynamic) {
    sh.mass = float(n * n) * ms;
    const float side = float(n) * a, i0 = sh.mass * side * side / 12.0f;
    sh.inertia = {i0, 2.0f * i0, i0};
  }
  sh.position = centre;
  sh.velocity = {0.0f, -0.5f, 0.0f};
  return sh;
}

// Shells of more than kWideSpheres spheres are summed, integrated and rebuilt by a workgroup
// each (bodies.comp SP_WIDE_PASS), in another summation order than the CPU's sphere-id order.
// The falling bed of drop_bed with a dynamic plate of 9 x 9 spheres (81: 2 or 3 per
// invocation) dropped on it at 0.5 m/s and a kinematic plate of 6 x 6 (36) pushed down
// beside it: over 400 steps of 5e-5 s both plates press into the granules (peak force
// ~500 N). The plates' centres stay within 0.001 particle diameters of the CPU's (llvmpipe
// 5e-9 m, an H200 4e-7 m, against 5e-6 m). The granules the plates strike diverge as
// chaotically as any collision (trajectories_agree): until the impact (step 50) within the
// growth of a CPU run one ulp away, and by the end within 0.05 diameters (llvmpipe 2.2e-6 m
// or 0.0005 d, the same as the one-ulp run; an H200, whose compiler fuses multiply-adds,
// 7.9e-5 m or 0.016 d, against 2.5e-4 m).
TEST(GlSimulation, WideShellsMatchCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  const float r = d.particle_radius;
  const float ms = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  const ShellDef dyn = wide_plate(d, 9, {0.035f, 0.0745f, 0.035f}, MotionType::Dynamic);
  const ShellDef kin = wide_plate(d, 6, {0.063f, 0.0745f, 0.035f}, MotionType::Kinematic);
  ASSERT_GT(int(dyn.offsets.size()), kWideSpheres);
  ASSERT_GT(int(kin.offsets.size()), kWideSpheres);
  auto cpu = Simulation::create(d);
  auto cpu2 = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && cpu2.ok() && gpu.ok()) << gpu.message();
  BodyId plates[2];
  auto build = [&](auto& sim, float nudge) {
    drop_bed(sim, nudge);
    plates[0] = *sim.add_shell(dyn);
    plates[1] = *sim.add_shell(kin);
  };
  build(*cpu, 0.0f);
  build(*cpu2, 1.0f);
  build(*gpu, 0.0f);
  const double dt = 5e-5;
  std::vector<double> dev_gl, dev_ulp;
  double plate_force = 0, plate_dev = 0;
  for (int s = 1; s <= 400; ++s) {
    ASSERT_TRUE(cpu->step(dt).ok());
    ASSERT_TRUE(cpu2->step(dt).ok());
    auto st = gpu->step(dt);
    ASSERT_TRUE(st.ok()) << st.message();
    dev_gl.push_back(max_dev(*gpu, *cpu));
    dev_ulp.push_back(max_dev(*cpu2, *cpu));
    for (BodyId b : plates) {
      plate_force = std::max(plate_force, double(norm(cpu->body_force(b))));
      plate_dev = std::max(plate_dev, double(norm(gpu->body_position(b) - cpu->body_position(b))));
    }
  }
  std::printf("step  dev_gl(m)  dev_1ulp(m)\n");
  for (int s : {1, 10, 50, 100, 200, 300, 400}) std::printf("%4d  %.3e  %.3e\n", s, dev_gl[s - 1], dev_ulp[s - 1]);
  std::printf("largest contact force on a plate %.3g N; plate centres within %.3g m\n", plate_force, plate_dev);
  for (BodyId b : plates) {
    Vec3 a = cpu->body_position(b), g = gpu->body_position(b);
    std::printf("plate %d cpu %.5f %.5f %.5f gl %.5f %.5f %.5f\n", b.index, a.x, a.y, a.z, g.x, g.y, g.z);
  }
  EXPECT_GT(plate_force, 10.0 * ms * 9.81) << "the plates must press into the granules";
  const double d10 = std::max(dev_gl[9], 1e-9), u10 = std::max(dev_ulp[9], 1e-12);
  for (int s = 10; s < 50; ++s)
    EXPECT_LE(dev_gl[s], 20.0 * std::max(dev_ulp[s], 1e-12) * d10 / u10 + 1e-7) << "step " << s + 1;
  EXPECT_LT(dev_gl.back(), 5e-2 * 2 * r);
  EXPECT_LT(plate_dev, 1e-3 * 2 * r);
}

// Statistics after settling: the same loose bed of 96 granules poured into a
// walled box settles to a statistically equal bed on both backends. Bed height = twice the
// mean sphere-centre height (the height of a uniform layer with that centroid), within 2 %
// of the CPU's or within twice the deviation of a CPU run started one ulp away, whichever is
// larger: one small bed is one sample of a chaotic settling, and since e = 0.3 maps to the
// clamped-law damping (zeta 0.497, docs/dem.md) the one-ulp CPU run alone lands 2.45 % off
// (GL 3.64 %). The surface (95th percentile of sphere tops) is printed with the same spread.
// Settled: 0.7 s, longer while a granule still moves (see below); then every granule < 0.01 m/s.
TEST(GlSimulation, SettledBedMatchesCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.bounds_max = {0.1f, 0.2f, 0.1f};
  auto cpu = Simulation::create(d);
  auto cpu2 = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && cpu2.ok() && gpu.ok()) << gpu.message();
  auto pour = [&](auto& sim, bool nudge) {
    std::uint64_t seed = 11;
    const float r = d.particle_radius, a = 4.7f * r;
    for (int l = 0; l < 6; ++l)
      for (int k = 0; k < 4; ++k)
        for (int i = 0; i < 4; ++i) {
          Vec3 x{0.0125f + i * a + 0.2f * r * srand1(seed), 0.012f + l * a, 0.0125f + k * a + 0.2f * r * srand1(seed)};
          if (nudge) x.x = std::nextafter(x.x, 1.0f);
          ASSERT_TRUE(sim.add_granule(x, random_quat(seed)).ok());
        }
  };
  pour(*cpu, false);
  pour(*cpu2, true);
  pour(*gpu, false);
  const double frame = 1e-3;  // 11 substeps of 9.1e-5 s
  // 0.7 s, then on in 0.05 s pieces (at most to 2.1 s) while a granule of one of the three
  // beds is still moving at >= 0.01 m/s: in some summation orders one granule still rolls at
  // 0.7 s (a sample of the chaotic settling, like the heights)
  int frames = 0;
  auto moving = [&] {
    return cpu->max_granule_speed() >= 0.01 || cpu2->max_granule_speed() >= 0.01 || gpu->max_granule_speed() >= 0.01;
  };
  while (frames < 700 || (moving() && frames < 2100)) {
    for (int f = 0; f < (frames < 700 ? 700 : 50); ++f) {
      ASSERT_TRUE(cpu->step(frame).ok());
      ASSERT_TRUE(cpu2->step(frame).ok());
      auto st = gpu->step(frame);
      ASSERT_TRUE(st.ok()) << st.message();
    }
    frames += frames < 700 ? 700 : 50;
  }
  struct Bed {
    double height, surface;
  };
  auto stats = [&](const std::vector<Vec3>& p) {
    std::vector<double> y;
    double m = 0;
    for (const Vec3& x : p) {
      y.push_back(x.y + d.particle_radius);
      m += x.y;
    }
    std::sort(y.begin(), y.end());
    return Bed{2.0 * m / double(p.size()), y[std::size_t(0.95 * double(y.size()))]};
  };
  const Bed c = stats(cpu->particle_positions()), c2 = stats(cpu2->particle_positions()),
            g = stats(gpu->particle_positions());
  std::printf("after %.2f s: bed height cpu %.5f m, gl %.5f m (%+.2f %%), cpu one ulp away %.5f m (%+.2f %%)\n"
              "surface (95th pct of tops) cpu %.5f, gl %.5f (%+.2f %%), cpu one ulp away %.5f (%+.2f %%)\n"
              "max granule speed cpu %.5f gl %.5f m/s\n",
              frames * frame, c.height, g.height, 100 * (g.height - c.height) / c.height, c2.height,
              100 * (c2.height - c.height) / c.height, c.surface, g.surface, 100 * (g.surface - c.surface) / c.surface,
              c2.surface, 100 * (c2.surface - c.surface) / c.surface, cpu->max_granule_speed(), gpu->max_granule_speed());
  EXPECT_LT(cpu->max_granule_speed(), 0.01);
  EXPECT_LT(gpu->max_granule_speed(), 0.01);
  EXPECT_NEAR(g.height, c.height, std::max(0.02 * c.height, 2.0 * std::abs(c2.height - c.height)));
}

// The std430 offsets generated from fields.hpp (layout.hpp) are the ones the driver uses
// for the generated GLSL blocks: every particle and body field, asked of the driver.
// Sleeping regions are the CPU backend's: the GL backend refuses them, naming the field.
TEST(GlSimulation, RefusesSleepingRegions) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.sleep_regions = true;
  auto gpu = GlSimulation::create(d);
  ASSERT_FALSE(gpu.ok());
  EXPECT_NE(gpu.message().find("SimulationDef.sleep_regions"), std::string::npos) << gpu.message();
}

// The DEM kernels declare kStorageBlocks storage blocks (common.glsl), which create() checks
// against the driver's limit; the write kernel its own two alone.
TEST(GlSimulation, KernelsUseTheStorageBlocksCreateChecks) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  auto gpu = GlSimulation::create(box_def(ShearLaw::SpringHistory));
  ASSERT_TRUE(gpu.ok()) << gpu.message();
  const std::vector<unsigned> progs = gpu->gl_programs();  // in Kernel order
  ASSERT_EQ(progs.size(), std::size_t(kKernelCount));
  for (int k = 0; k < kKernelCount; ++k) {
    GLint blocks = -1;
    glGetProgramInterfaceiv(progs[std::size_t(k)], GL_SHADER_STORAGE_BLOCK, GL_ACTIVE_RESOURCES, &blocks);
    EXPECT_GE(blocks, 1) << kKernelFile[k];
    EXPECT_LE(blocks, k == kCopyWords ? 2 : kStorageBlocks) << kKernelFile[k];
    std::printf("%-26s %s: %d storage blocks\n", kKernelFile[k], kKernelDefine[k] ? kKernelDefine[k] : "", blocks);
  }
}

TEST(GlSimulation, GeneratedLayoutMatchesTheDriver) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(gpu.ok()) << gpu.message();
  const std::vector<unsigned> progs = gpu->gl_programs();  // in Kernel order
  ASSERT_EQ(progs.size(), std::size_t(kKernelCount));
  const unsigned gather = progs[kGridGather], bodies = progs[kBodies];
  auto offset = [](unsigned prog, const std::string& name) {
    GLuint idx = glGetProgramResourceIndex(prog, GL_BUFFER_VARIABLE, name.c_str());
    if (idx == GL_INVALID_INDEX) return -1;
    const GLenum props[2] = {GL_OFFSET, GL_ARRAY_STRIDE};
    GLint v[2] = {-1, -1};
    glGetProgramResourceiv(prog, GL_BUFFER_VARIABLE, idx, 2, props, 2, nullptr, v);
    return v[0];
  };
  int checked = 0;
  for (int f = 0; f < kParticleFieldCount; ++f) {
    const std::string n = "ParticlesA." + std::string(kParticleFields[f].name) + "[0]";
    int got = offset(gather, n);
    ASSERT_GE(got, 0) << n << " not reported by the driver";
    EXPECT_EQ(std::size_t(got), std430_offset(kParticleFields, f, std::size_t(d.max_particles))) << n;
    ++checked;
  }
  for (int f = 0; f < kBodyFieldCount; ++f) {
    const std::string n = "Bodies." + std::string(kBodyFields[f].name) + "[0]";
    int got = offset(bodies, n);
    ASSERT_GE(got, 0) << n << " not reported by the driver";
    EXPECT_EQ(std::size_t(got), std430_offset(kBodyFields, f, std::size_t(d.max_bodies))) << n;
    ++checked;
  }
  EXPECT_EQ(checked, int(kParticleFieldCount) + int(kBodyFieldCount));
}

// Same scene, same GPU: the same state bit for bit, run after run and for any workgroup
// size (which changes the scheduling of the atomics in the counting sort): fixed summation
// order, no float atomics. The falling bed with a plate of 81 spheres dropped on it (summed
// by a workgroup of kWideSpheres invocations whatever the workgroup size).

TEST(GlSimulation, DeterministicAcrossRunsAndWorkgroupSizes) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  std::vector<std::uint64_t> h;
  for (int wg : {64, 64, 32, 256}) {
    GlOptions o;
    o.workgroup_size = wg;
    auto gpu = GlSimulation::create(d, o);
    ASSERT_TRUE(gpu.ok()) << gpu.message();
    drop_bed(*gpu, 0.0f);
    const BodyId plate = *gpu->add_shell(wide_plate(d, 9, {0.035f, 0.0745f, 0.035f}, MotionType::Dynamic));
    std::int64_t resorts = 0;
    double plate_force = 0;
    for (int s = 0; s < 300; ++s) {
      ASSERT_TRUE(gpu->step(5e-5).ok());
      resorts += gpu->last_step().resorts;
      plate_force = std::max(plate_force, double(norm(gpu->body_force(plate))));
    }
    EXPECT_GT(plate_force, 1.0) << "the plate must land on the granules";
    EXPECT_GT(gpu->last_step().contacts, 10);
    EXPECT_GT(resorts, 1);
    h.push_back(gpu->state_hash());
  }
  for (std::size_t k = 1; k < h.size(); ++k) EXPECT_EQ(h[k], h[0]) << "run " << k;
}

// Creating, using and destroying a GlSimulation leaves no GL buffer or program behind.
TEST(GlSimulation, GlObjectsReturnToTheirStart) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  std::vector<unsigned> bufs, progs;
  {
    auto gpu = GlSimulation::create(box_def(ShearLaw::SpringHistory));
    ASSERT_TRUE(gpu.ok()) << gpu.message();
    drop_bed(*gpu, 0.0f);
    ASSERT_TRUE(gpu->step(1e-4).ok());
    bufs = gpu->gl_buffers();
    progs = gpu->gl_programs();
    ASSERT_EQ(bufs.size(), 10u);  // the 8 blocks, the grid arguments' and the writes' staging buffer
    ASSERT_EQ(progs.size(), std::size_t(kKernelCount));
    for (unsigned b : bufs) EXPECT_TRUE(glIsBuffer(b)) << b;
    for (unsigned p : progs) EXPECT_TRUE(glIsProgram(p)) << p;
    std::printf("GPU storage held: %zu bytes for %d particles\n", gpu->gpu_bytes(), gpu->def().max_particles);
  }
  for (unsigned b : bufs) EXPECT_FALSE(glIsBuffer(b)) << b;
  for (unsigned p : progs) EXPECT_FALSE(glIsProgram(p)) << p;
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Sleep as on the CPU (dem_test Sleep.SleepsAndKinematicContactWakes): a granule settles and
// the simulation sleeps; a slept frame changes nothing; a kinematic sphere driven towards the
// granule moves while the simulation sleeps and wakes it at contact range (+ skin).
TEST(GlSimulation, SleepsAndKinematicContactWakes) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {0.12f, 0.2f, 0.12f};
  d.side_walls = true;
  d.sleep_time = 0.2f;
  d.sleep_speed = 0.005f;
  auto s = GlSimulation::create(d);
  ASSERT_TRUE(s.ok()) << s.message();
  auto g = s->add_granule({0.06f, 0.02f, 0.06f});
  ShellDef k;
  k.offsets = {{0, 0, 0}};
  k.radii = {0.005f};
  k.motion = MotionType::Kinematic;
  k.position = {0.1f, 0.008f, 0.06f};
  auto kid = s->add_shell(k);
  ASSERT_TRUE(g.ok() && kid.ok());
  int n = 0;
  while (!s->asleep() && n < 3000) {
    ASSERT_TRUE(s->step(1e-3).ok());
    ++n;
  }
  ASSERT_TRUE(s->asleep()) << "max speed " << s->max_granule_speed();
  const std::uint64_t h = s->state_hash();
  ASSERT_TRUE(s->step(1e-3).ok());
  EXPECT_TRUE(s->last_step().slept);
  EXPECT_EQ(s->state_hash(), h);
  ASSERT_TRUE(s->set_kinematic_velocity(*kid, {-0.05f, 0, 0}, {}).ok());
  int woke_at = -1;
  for (int i = 0; i < 1000 && woke_at < 0; ++i) {
    ASSERT_TRUE(s->step(1e-3).ok());
    if (!s->asleep()) woke_at = i;
  }
  ASSERT_GE(woke_at, 1) << "the shell must move while asleep before it wakes the simulation";
  float gap = 1e9f;
  auto ps = s->particle_positions();
  for (int i = 0; i < 4; ++i) gap = std::min(gap, length(ps[i] - ps[4]) - 0.01f);
  std::printf("asleep after %d frames; woke after %d frames of the shell moving, gap %.5f m\n", n, woke_at, gap);
  EXPECT_LT(gap, 0.002f);
  EXPECT_GT(gap, -0.001f);
}

TEST(GlSimulation, ErrorsNameTheFieldOrCapacity) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.particle_radius = -1;
  auto bad = GlSimulation::create(d);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("SimulationDef.particle_radius"), std::string::npos) << bad.message();
  d = box_def(ShearLaw::SpringHistory);
  d.max_bodies = 2;
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(gpu.ok());
  EXPECT_TRUE(gpu->add_granule({0.02f, 0.02f, 0.02f}).ok());
  EXPECT_TRUE(gpu->add_granule({0.05f, 0.02f, 0.02f}).ok());
  auto full = gpu->add_granule({0.05f, 0.05f, 0.02f});
  ASSERT_FALSE(full.ok());
  EXPECT_NE(full.message().find("max_bodies"), std::string::npos) << full.message();
  auto refuse = gpu->step(1.0);  // the CPU guard's refusal
  ASSERT_FALSE(refuse.ok());
  EXPECT_NE(refuse.message().find("step.dt_frame"), std::string::npos) << refuse.message();
  GlOptions o;
  o.max_contacts_per_sphere = 0;
  auto badopt = GlSimulation::create(box_def(ShearLaw::SpringHistory), o);
  ASSERT_FALSE(badopt.ok());
  EXPECT_NE(badopt.message().find("GlOptions.max_contacts_per_sphere"), std::string::npos);
}

// More touching partners than spring slots is reported, naming the option to raise.
TEST(GlSimulation, SpringSlotOverflowIsReported) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  GlOptions o;
  o.max_contacts_per_sphere = 2;
  auto gpu = GlSimulation::create(box_def(ShearLaw::SpringHistory), o);
  ASSERT_TRUE(gpu.ok()) << gpu.message();
  drop_bed(*gpu, 0.0f);
  Status last = Ok{};
  for (int s = 0; s < 400 && last.ok(); ++s) last = gpu->step(5e-5);
  ASSERT_FALSE(last.ok());
  EXPECT_NE(last.message().find("GlOptions.max_contacts_per_sphere"), std::string::npos) << last.message();
}

// ---- control from the terrain manager: set_body_state / set_body_enabled ----

// A dynamic plus-shaped shell of 5 spheres of radius r (arms 2r along x and z).
ShellDef plus_shell(const SimulationDef& d, Vec3 position) {
  const float r = d.particle_radius;
  const float ms = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  ShellDef sh;
  sh.offsets = {Vec3{0, 0, 0}, Vec3{2 * r, 0, 0}, Vec3{-2 * r, 0, 0}, Vec3{0, 0, 2 * r}, Vec3{0, 0, -2 * r}};
  sh.radii = {r};
  sh.motion = MotionType::Dynamic;
  sh.mass = 5 * ms;
  const float i0 = 0.4f * ms * r * r, arm2 = ms * 4 * r * r;
  sh.inertia = {5 * i0 + 2 * arm2, 5 * i0 + 4 * arm2, 5 * i0 + 2 * arm2};
  sh.position = position;
  return sh;
}

Quat about_y(float angle) { return {0, std::sin(0.5f * angle), 0, std::cos(0.5f * angle)}; }

// The manager's sequence on both backends: set_body_state on a dynamic shell (still staged
// on the GPU: the queued copy changes), step; set_body_enabled(false), step; enable +
// set_body_state, step until the shell has landed on a granule. Bodies agree within the
// trajectory test's bound (0.01 particle diameters) after every phase; the parked shell sits
// at (centre x, bounds_max.y + 1000, centre z) with zero velocities on both. The shell is out
// of contact whenever its state is set or it is parked: dem.cpp does not rebuild a body's
// spheres in set_body_state / set_body_enabled (the first substep sees the old spheres, and
// a parked body's spheres never move), while the GL backend rebuilds them at once; with no
// contact at those moments both give the same trajectories.
TEST(GlSimulation, BodyStateAndParkingMatchCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  auto cpu = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && gpu.ok()) << gpu.message();
  std::uint64_t seed = 3;
  const Vec3 gx[4] = {{0.02f, 0.012f, 0.02f}, {0.06f, 0.012f, 0.02f}, {0.02f, 0.012f, 0.06f}, {0.06f, 0.012f, 0.06f}};
  for (const Vec3& x : gx) {
    const Quat q = random_quat(seed);
    ASSERT_TRUE(cpu->add_granule(x, q).ok());
    ASSERT_TRUE(gpu->add_granule(x, q).ok());
  }
  const ShellDef sh = plus_shell(d, {0.04f, 0.06f, 0.04f});
  auto bc = cpu->add_shell(sh);
  auto bg = gpu->add_shell(sh);
  ASSERT_TRUE(bc.ok() && bg.ok());
  ASSERT_EQ(bc->index, bg->index);
  const BodyId shell = *bg;
  const double frame = 1e-3;
  auto both = [&](auto&& f) {
    auto a = f(*cpu);
    auto b = f(*gpu);
    ASSERT_TRUE(a.ok()) << a.message();
    ASSERT_TRUE(b.ok()) << b.message();
  };
  // sphere positions by id; the parked shell's spheres are left out (the CPU leaves them
  // where the shell was parked, the GPU moves them with it)
  bool parked = false;
  auto sphere_dev = [&] {
    auto pg = gpu->particle_positions(), pc = cpu->particle_positions();
    double m = 0;
    for (std::size_t i = 0; i < pc.size(); ++i)
      if (!parked || i < 16) m = std::max(m, double(norm(pg[i] - pc[i])));
    return m;
  };
  double worst = 0;
  auto run = [&](int frames, const char* phase) {
    for (int f = 0; f < frames; ++f) {
      both([&](auto& s) { return s.step(frame); });
      worst = std::max(worst, sphere_dev());
    }
    double body_dev = 0;
    for (int b = 0; b < cpu->body_count(); ++b)
      body_dev = std::max(body_dev, double(norm(gpu->body_position({b}) - cpu->body_position({b}))));
    std::printf("%-28s max sphere difference %.3g m, body positions %.3g m\n", phase, sphere_dev(), body_dev);
    EXPECT_LT(body_dev, 1e-2 * 2 * d.particle_radius) << phase;
  };
  // 1. the shell is given a new pose and velocity (GPU: still staged)
  ASSERT_LT(gpu->uploaded_body_count(), gpu->body_count());
  const Vec3 x1{0.04f, 0.05f, 0.04f}, v1{0.05f, -0.2f, 0.0f}, w1{0.0f, 3.0f, 0.0f};
  both([&](auto& s) { return s.set_body_state(shell, x1, about_y(0.5f), v1, w1); });
  EXPECT_EQ(norm(gpu->body_position(shell) - x1), 0.0f);
  EXPECT_EQ(norm(gpu->body_velocity(shell) - v1), 0.0f);
  run(10, "set_body_state, 10 frames:");
  EXPECT_GT(norm(gpu->body_position(shell) - x1), 1e-3f);  // it moved from there
  // 2. parked
  both([&](auto& s) { return s.set_body_enabled(shell, false); });
  const Vec3 far{0.04f, d.bounds_max.y + 1000.0f, 0.04f};
  EXPECT_EQ(norm(gpu->body_position(shell) - far), 0.0f);
  EXPECT_FALSE(gpu->asleep());
  parked = true;
  run(20, "parked, 20 frames:");
  EXPECT_EQ(norm(gpu->body_position(shell) - far), 0.0f);
  EXPECT_EQ(norm(cpu->body_position(shell) - far), 0.0f);
  EXPECT_EQ(norm(gpu->body_velocity(shell)), 0.0f);
  EXPECT_EQ(norm(gpu->body_angular_velocity(shell)), 0.0f);
  EXPECT_EQ(norm(gpu->body_force(shell)), 0.0f);
  {
    auto ps = gpu->particle_positions();  // its spheres went with it
    const int first = 4 * 4;
    for (int k = 0; k < 5; ++k) EXPECT_GT(ps[first + k].y, d.bounds_max.y + 990.0f) << "sphere " << k;
  }
  // 3. enabled again and placed just above granule 0, falling onto it
  const Vec3 x3{0.02f, 0.03f, 0.02f}, v3{0.0f, -0.3f, 0.0f};
  both([&](auto& s) { return s.set_body_enabled(shell, true); });
  both([&](auto& s) { return s.set_body_state(shell, x3, Quat{}, v3, Vec3{}); });
  parked = false;  // (the CPU rebuilds the shell's spheres at the end of the next substep)
  double shell_force = 0;
  for (int f = 0; f < 6; ++f) {
    run(10, "enabled + set_body_state:");
    shell_force = std::max(shell_force, double(norm(cpu->body_force(shell))));
  }
  EXPECT_LT(gpu->body_position(shell).y, x3.y - 0.005f);  // it fell (dynamic again), onto granule 0
  EXPECT_GT(shell_force, 0.0) << "the shell must land on the granule";
  std::printf("worst particle difference over the run %.3g m\n", worst);
  EXPECT_LT(worst, 1e-2 * 2 * d.particle_radius);
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// A parked shell exerts no force. (a) Granules in the air, pressed by the shell: their
// contact forces are non-zero while it is enabled and, once it is parked, equal those of a
// run without the shell (zero: nothing else touches them). (b) A shell added inside a
// falling granule bed and parked before the first step (on the GPU while still staged): the
// bed's forces and positions over 60 substeps equal a run without the shell (same tolerance
// as the CPU-vs-GL force test). The CPU backend's values are printed for reference.
TEST(GlSimulation, ParkedShellExertsNoForce) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  const float r = d.particle_radius;
  const double dt1 = 0.9 * Simulation::create(d)->max_substep_dt();  // one substep per frame
  auto max_granule_force = [](auto& s, int n) {
    double m = 0;
    for (int b = 0; b < n; ++b) m = std::max(m, double(norm(s.body_force({b}))));
    return m;
  };
  {
    // (a) the shell's centre sphere and 4 granules around it, just touching its arms
    auto with = GlSimulation::create(d);
    auto without = GlSimulation::create(d);
    auto cpu = Simulation::create(d);
    ASSERT_TRUE(with.ok() && without.ok() && cpu.ok());
    const Vec3 c{0.04f, 0.04f, 0.04f};
    const Vec3 gpos[4] = {c + Vec3{4.2f * r, 0, 0}, c + Vec3{-4.2f * r, 0, 0}, c + Vec3{0, 0, 4.2f * r},
                          c + Vec3{0, 0, -4.2f * r}};
    for (const Vec3& x : gpos) {
      ASSERT_TRUE(with->add_granule(x).ok());
      ASSERT_TRUE(without->add_granule(x).ok());
      ASSERT_TRUE(cpu->add_granule(x).ok());
    }
    auto shell = with->add_shell(plus_shell(d, c));
    ASSERT_TRUE(shell.ok() && cpu->add_shell(plus_shell(d, c)).ok());
    ASSERT_TRUE(with->step(dt1).ok() && without->step(dt1).ok() && cpu->step(dt1).ok());
    ASSERT_EQ(*with->substeps_for(dt1), 1);
    const double active = max_granule_force(*with, 4);
    std::printf("(a) shell enabled: max granule contact force %.4g N (without the shell %.4g N)\n", active,
                max_granule_force(*without, 4));
    ASSERT_GT(active, 1e-3) << "the granules must touch the shell";
    EXPECT_EQ(max_granule_force(*without, 4), 0.0);
    ASSERT_TRUE(with->set_body_enabled(*shell, false).ok());
    ASSERT_TRUE(cpu->set_body_enabled(*shell, false).ok());
    for (int k = 0; k < 5; ++k) {
      ASSERT_TRUE(with->step(dt1).ok() && without->step(dt1).ok() && cpu->step(dt1).ok());
      Compare cmp;
      for (int b = 0; b < 4; ++b) cmp.check(with->body_force({b}), without->body_force({b}), "parked: granule force", b);
      EXPECT_EQ(cmp.failures, 0) << "substep " << k + 1 << " after parking";
      EXPECT_EQ(with->last_step().contacts, 0);
    }
    std::printf("(a) parked: max granule force gl %.4g N; cpu reference %.4g N\n", max_granule_force(*with, 4),
                max_granule_force(*cpu, 4));
  }
  {
    // (b) parked inside a falling bed before the first step
    auto with = GlSimulation::create(d);
    auto without = GlSimulation::create(d);
    auto cpu = Simulation::create(d);
    auto cpu_without = Simulation::create(d);
    ASSERT_TRUE(with.ok() && without.ok() && cpu.ok() && cpu_without.ok());
    drop_bed(*with, 0.0f);
    drop_bed(*without, 0.0f);
    drop_bed(*cpu, 0.0f);
    drop_bed(*cpu_without, 0.0f);
    const int n = without->body_count();
    auto shell = with->add_shell(plus_shell(d, {0.03f, 0.02f, 0.03f}));
    ASSERT_TRUE(shell.ok() && cpu->add_shell(plus_shell(d, {0.03f, 0.02f, 0.03f})).ok());
    ASSERT_LT(with->uploaded_body_count(), with->body_count());  // staged: the queued copy is parked
    ASSERT_TRUE(with->set_body_enabled(*shell, false).ok());
    ASSERT_TRUE(cpu->set_body_enabled(*shell, false).ok());
    Compare cmp;
    std::int64_t contacts = 0;
    for (int s = 0; s < 60; ++s) {
      ASSERT_TRUE(with->step(5e-5).ok() && without->step(5e-5).ok());
      ASSERT_TRUE(cpu->step(5e-5).ok() && cpu_without->step(5e-5).ok());
      contacts += without->last_step().contacts;
      for (int b = 0; b < n; ++b) cmp.check(with->body_force({b}), without->body_force({b}), "bed force", b);
    }
    EXPECT_GT(contacts, 0);
    EXPECT_GT(cmp.nonzero, 0);
    EXPECT_EQ(cmp.failures, 0);
    const auto pw = with->particle_positions(), po = without->particle_positions();
    double dev = 0;
    for (std::size_t i = 0; i < po.size(); ++i) dev = std::max(dev, double(norm(pw[i] - po[i])));
    double cpu_dev = 0, cpu_force = 0;
    for (int b = 0; b < n; ++b) {
      cpu_dev = std::max(cpu_dev, double(norm(cpu->body_position({b}) - cpu_without->body_position({b}))));
      cpu_force = std::max(cpu_force, double(norm(cpu->body_force({b}) - cpu_without->body_force({b}))));
    }
    std::printf("(b) bed of %d granules with a parked shell vs without, 60 substeps: gl worst force difference "
                "%.3g N (%d of %d non-zero), positions %.3g m; cpu reference: force %.3g N, positions %.3g m\n",
                n, cmp.worst_abs, cmp.nonzero, cmp.checked, dev, cpu_force, cpu_dev);
    EXPECT_LT(dev, 1e-6);
  }
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Collision groups as on the CPU (tests/particles/jointed_shells.hpp): shells of one group do
// not touch, granules touch both, a group set between steps holds from the next substep.
TEST(GlSimulation, ShellsOfOneGroupDoNotTouch) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  sandpatch::testutil::check_collision_groups(
      [](const SimulationDef& d) {
        auto s = GlSimulation::create(d);
        EXPECT_TRUE(s.ok()) << s.message();
        return std::move(*s);
      },
      [](GlSimulation& s) {
        ASSERT_TRUE(s.step(1e-6).ok());
        ASSERT_EQ(s.last_step().substeps, 1);
      });
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Errors as the CPU's (same field and text); a staged body's queued copy takes the state and
// the parking and is uploaded with it; an uploaded body's spheres follow set_body_state at
// once (before any step); enabling restores the motion bits (the shell falls again).
TEST(GlSimulation, BodyStateErrorsAndStagedBodies) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  GlOptions o;
  o.upload_in_step = false;
  auto gpu = GlSimulation::create(d, o);
  auto cpu = Simulation::create(d);
  ASSERT_TRUE(gpu.ok() && cpu.ok()) << gpu.message();
  const ShellDef sh = plus_shell(d, {0.04f, 0.04f, 0.04f});
  const BodyId b = *gpu->add_shell(sh);
  ASSERT_TRUE(cpu->add_shell(sh).ok());
  auto same_error = [](const Status& g, const Status& c) {
    ASSERT_FALSE(g.ok());
    ASSERT_FALSE(c.ok());
    EXPECT_EQ(g.message(), c.message());
  };
  same_error(gpu->set_body_state({5}, {}, {}, {}, {}), cpu->set_body_state({5}, {}, {}, {}, {}));
  same_error(gpu->set_body_state({-1}, {}, {}, {}, {}), cpu->set_body_state({-1}, {}, {}, {}, {}));
  same_error(gpu->set_body_enabled({5}, false), cpu->set_body_enabled({5}, false));
  EXPECT_NE(gpu->set_body_enabled({5}, false).message().find("set_body_enabled.body"), std::string::npos);
  // staged: park it, then setting its state is refused as on the CPU
  ASSERT_EQ(gpu->uploaded_body_count(), 0);
  ASSERT_TRUE(gpu->set_body_enabled(b, false).ok());
  ASSERT_TRUE(cpu->set_body_enabled(b, false).ok());
  ASSERT_TRUE(gpu->set_body_enabled(b, false).ok());  // already parked: nothing to do
  same_error(gpu->set_body_state(b, {}, {}, {}, {}), cpu->set_body_state(b, {}, {}, {}, {}));
  EXPECT_NE(gpu->set_body_state(b, {}, {}, {}, {}).message().find("enable it first"), std::string::npos);
  const Vec3 far{0.04f, d.bounds_max.y + 1000.0f, 0.04f};
  EXPECT_EQ(norm(gpu->body_position(b) - far), 0.0f);
  gpu->upload(std::numeric_limits<std::size_t>::max());
  ASSERT_EQ(gpu->uploaded_body_count(), 1);
  EXPECT_EQ(norm(gpu->body_position(b) - far), 0.0f);
  for (const Vec3& p : gpu->particle_positions()) EXPECT_GT(p.y, d.bounds_max.y + 990.0f);
  // uploaded: enable, set the state; the spheres follow at once
  ASSERT_TRUE(gpu->set_body_enabled(b, true).ok());
  const Vec3 x{0.03f, 0.05f, 0.035f};
  const Quat q = about_y(0.7f);
  ASSERT_TRUE(gpu->set_body_state(b, x, Quat{2 * q.x, 2 * q.y, 2 * q.z, 2 * q.w}, {0, 0, 0}, {0, 0, 0}).ok());
  const Quat qg = gpu->body_orientation(b);
  EXPECT_NEAR(qg.y, q.y, 1e-6f);  // normalised, as the CPU
  EXPECT_NEAR(qg.w, q.w, 1e-6f);
  const auto ps = gpu->particle_positions();
  for (std::size_t k = 0; k < sh.offsets.size(); ++k) {
    const Vec3 want = x + rotate(q, sh.offsets[k]);
    EXPECT_LT(norm(ps[k] - want), 1e-6f) << "sphere " << k;
  }
  // enabled: dynamic again, it falls
  ASSERT_TRUE(gpu->step(1e-3).ok());
  EXPECT_LT(gpu->body_velocity(b).y, -1e-3f);
  EXPECT_LT(gpu->body_position(b).y, x.y);
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// ---- contact springs carried from another simulation (gl_springs.cpp) ----

// The CPU test's beds and helpers (tests/particles/springs_common.hpp).
using springtest::kBedRadius;
using springtest::copy_bed;
using springtest::mean_motion_d;
inline SimulationDef spring_bed_def(int n, int layers) { return springtest::bed_def(n, layers); }
inline Simulation settled_cpu_bed(int n, int layers, double settle) { return springtest::settled_bed(n, layers, settle); }

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Contacts by (a, sphere a, b, sphere b, -1) with (a, sphere a) < (b, sphere b), or (a, sphere a,
// -1, 0, plane): (xi as the first named sphere's, m; dmax, m). Each contact once.
using SpringKey = std::tuple<int, int, int, int, int>;
std::map<SpringKey, std::pair<Vec3, float>> springs_by_key(const std::vector<ContactSpring>& v) {
  std::map<SpringKey, std::pair<Vec3, float>> m;
  for (const ContactSpring& c : v) {
    SpringKey k{c.a.index, c.sphere_a, c.b.index, c.sphere_b, -1};
    Vec3 xi = c.xi;
    if (c.plane >= 0) k = SpringKey{c.a.index, c.sphere_a, -1, 0, c.plane};
    else if (std::make_pair(c.b.index, c.sphere_b) < std::make_pair(c.a.index, c.sphere_a))
      k = SpringKey{c.b.index, c.sphere_b, c.a.index, c.sphere_a, -1}, xi = -1.0f * xi;
    EXPECT_TRUE(m.emplace(k, std::make_pair(xi, c.dmax)).second) << "a contact given twice";
  }
  return m;
}

// A bed settled on the CPU, rebuilt in a GlSimulation from its positions alone compacts (its
// springs start at zero); rebuilt with the CPU's springs (set while the granules are still
// staged) it stays nearly as still as the bed itself. The CPU test's bounds.
TEST(GlSimulation, BedRebuiltWithCpuSpringsStaysAtRest) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  const auto t0 = std::chrono::steady_clock::now();
  const int n = 6, layers = 6;
  Simulation bed = settled_cpu_bed(n, layers, 1.0);
  const double t_settle = seconds_since(t0);
  const std::vector<ContactSpring> springs = bed.contact_springs();
  int pairs = 0, planes = 0;
  for (const ContactSpring& c : springs) (c.plane < 0 ? pairs : planes)++;
  auto without = GlSimulation::create(bed.def());
  auto with = GlSimulation::create(bed.def());
  ASSERT_TRUE(without.ok() && with.ok()) << with.message();
  copy_bed(bed, *without, false);
  copy_bed(bed, *with, true);
  ASSERT_EQ(with->uploaded_body_count(), 0);  // staged when the springs were set
  const auto t1 = std::chrono::steady_clock::now();
  const double lost = mean_motion_d(*without, 0.1), kept = mean_motion_d(*with, 0.1);
  const double t_gl = seconds_since(t1);
  const std::vector<ContactSpring> back = with->contact_springs();
  std::printf("GL mean motion in 0.1 s (d): rebuilt without springs %.3g, with the CPU's %.3g (%d pairs, %d planes set; "
              "%zu springs read back); CPU settling %.1f s, GL 2 x 0.1 s %.1f s (%d substeps a frame)\n",
              lost, kept, pairs, planes, back.size(), t_settle, t_gl, with->last_step().substeps);
  EXPECT_GT(pairs, bed.body_count());
  EXPECT_GT(planes, n * n);
  EXPECT_GT(lost, 1e-3);
  EXPECT_LT(kept, 0.1 * lost);
  EXPECT_LT(kept, 5e-4);
  // the rebuilt bed holds as many contacts as the bed it came from, to a few
  EXPECT_NEAR(double(back.size()), double(springs.size()), 0.02 * double(springs.size()));
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// The springs set on both backends (the same bed, the same springs), after one identical
// substep, read back the same: every contact of one is a contact of the other, pair for pair
// (whichever side each reports it from), xi within 1e-3 of its size + 1e-8 m, dmax likewise;
// and every granule's contact force within 1e-2 of the largest (about its weight), its torque
// within that times d, of the CPU's (the GL holds each pair on both its spheres: a side left
// without its spring shows here: measured 3x the largest force, against 1.4e-3 of it).
// Measured xi: 2.7e-11 m off at worst on llvmpipe, 1.6e-9 m on an H200 (one contact).
TEST(GlSimulation, ContactSpringsRoundTripMatchesCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  const int n = 6, layers = 6;
  Simulation bed = settled_cpu_bed(n, layers, 1.0);
  auto cpu = Simulation::create(bed.def());
  auto gpu = GlSimulation::create(bed.def());
  ASSERT_TRUE(cpu.ok() && gpu.ok()) << gpu.message();
  copy_bed(bed, *cpu, true);
  copy_bed(bed, *gpu, true);
  const double dt = 0.9 * cpu->max_substep_dt();
  ASSERT_EQ(*gpu->substeps_for(dt), 1);
  ASSERT_TRUE(cpu->step(dt).ok());
  const Status st = gpu->step(dt);
  ASSERT_TRUE(st.ok()) << st.message();
  const auto set = springs_by_key(bed.contact_springs()), c = springs_by_key(cpu->contact_springs()),
             g = springs_by_key(gpu->contact_springs());
  int only_cpu = 0, only_gl = 0, bad = 0, planes = 0;
  double worst_rel = 0, worst_abs = 0, xi_max = 0;
  for (const auto& [k, v] : c) {
    const auto it = g.find(k);
    if (it == g.end()) {
      ++only_cpu;
      continue;
    }
    planes += std::get<4>(k) >= 0;
    const double diff = norm(it->second.first - v.first), mag = norm(v.first);
    xi_max = std::max(xi_max, mag);
    worst_abs = std::max(worst_abs, diff);
    if (mag > 1e-9) worst_rel = std::max(worst_rel, diff / mag);
    if (diff > 1e-3 * mag + 1e-8 || std::abs(it->second.second - v.second) > 1e-3 * v.second + 1e-8) {
      if (++bad < 10)
        ADD_FAILURE() << "contact (" << std::get<0>(k) << "," << std::get<1>(k) << "," << std::get<2>(k) << ","
                      << std::get<3>(k) << "," << std::get<4>(k) << "): gl xi (" << it->second.first.x << ", "
                      << it->second.first.y << ", " << it->second.first.z << ") cpu (" << v.first.x << ", " << v.first.y
                      << ", " << v.first.z << ")";
    }
  }
  for (const auto& [k, v] : g) only_gl += c.count(k) == 0;
  std::printf("round trip: %zu springs set, cpu %zu gl %zu after one substep (%d planes matched); only on the cpu %d, "
              "only on the gl %d; xi up to %.3g m, worst difference %.3g m (%.3g relative)\n",
              set.size(), c.size(), g.size(), planes, only_cpu, only_gl, xi_max, worst_abs, worst_rel);
  EXPECT_GT(c.size(), std::size_t(2 * n * n * layers));
  EXPECT_GT(planes, n * n);
  EXPECT_EQ(only_cpu, 0);
  EXPECT_EQ(only_gl, 0);
  EXPECT_GT(xi_max, 1e-8);  // the springs are not all zero
  // and the forces they gave (each pair's spring on both its spheres)
  double fmax = 0, tmax = 0, df = 0, dtq = 0;
  for (int b = 0; b < cpu->body_count(); ++b) {
    fmax = std::max(fmax, double(norm(cpu->body_force({b}))));
    tmax = std::max(tmax, double(norm(cpu->body_torque({b}))));
    df = std::max(df, double(norm(gpu->body_force({b}) - cpu->body_force({b}))));
    dtq = std::max(dtq, double(norm(gpu->body_torque({b}) - cpu->body_torque({b}))));
  }
  std::printf("granules' contact forces up to %.3g N, GL - CPU up to %.3g N; torques up to %.3g N m, GL - CPU up to %.3g N m\n",
              fmax, df, tmax, dtq);
  EXPECT_LT(df, 1e-2 * fmax);
  EXPECT_LT(dtq, 1e-2 * fmax * 2 * kBedRadius);
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Springs set while the bodies are staged wait for both their spheres: with half the bed
// uploaded, one substep takes the springs among the uploaded granules only (a pair with a
// staged granule is neither read back nor dropped); after the rest is uploaded the next
// substep takes the others. Substeps of 1e-7 s, so the upper half's absence for one of them
// barely shows: every contact is then read back as a CPU copy given the same springs has it
// after its two substeps, within 1e-2 of its size + 1e-8 m (a spring restarted from zero
// would be off by its whole size, up to 1e-4 m). Measured on llvmpipe: 1.6e-9 m at worst (1.0e-3
// relative, one pair), the same with the whole bed uploaded before the first substep: the
// backends' round-off in that contact, not the wait; the others within 1e-5 relative. An H200:
// the same 1.6e-9 m (1.2e-2 relative).
TEST(GlSimulation, SpringsSetOnStagedBodiesWaitForTheirUpload) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  Simulation bed = settled_cpu_bed(4, 4, 1.0);
  GlOptions o;
  o.upload_in_step = false;
  auto gpu = GlSimulation::create(bed.def(), o);
  auto cpu = Simulation::create(bed.def());
  ASSERT_TRUE(gpu.ok() && cpu.ok()) << gpu.message();
  copy_bed(bed, *gpu, true);
  copy_bed(bed, *cpu, true);
  gpu->upload(gpu->pending_upload_bytes() / 2);
  const int half = gpu->uploaded_body_count();
  ASSERT_GT(half, 0);
  ASSERT_LT(half, bed.body_count());
  const double dt = 1e-7;  // s, one substep
  ASSERT_EQ(*gpu->substeps_for(dt), 1);
  ASSERT_TRUE(gpu->step(dt).ok());
  const auto set = springs_by_key(bed.contact_springs());
  int among = 0, across = 0;
  for (const auto& [k, v] : springs_by_key(gpu->contact_springs())) {
    EXPECT_LT(std::get<0>(k), half);
    EXPECT_LT(std::get<2>(k), half);
    among += std::get<4>(k) < 0;
  }
  for (const auto& [k, v] : set) across += std::get<4>(k) < 0 && std::get<2>(k) >= half && std::get<0>(k) < half;
  gpu->upload(std::numeric_limits<std::size_t>::max());
  ASSERT_TRUE(gpu->step(dt).ok());
  ASSERT_TRUE(cpu->step(dt).ok());
  ASSERT_TRUE(cpu->step(dt).ok());
  const auto back = springs_by_key(gpu->contact_springs()), want = springs_by_key(cpu->contact_springs());
  int missing = 0, off = 0;
  double worst_rel = 0, worst_abs = 0, xi_max = 0;
  for (const auto& [k, v] : want) {
    const auto it = back.find(k);
    if (it == back.end()) {
      ++missing;
      continue;
    }
    const double diff = norm(it->second.first - v.first), mag = norm(v.first);
    xi_max = std::max(xi_max, mag);
    if (mag > 1e-9) worst_rel = std::max(worst_rel, diff / mag);
    worst_abs = std::max(worst_abs, diff);
    off += diff > 1e-2 * mag + 1e-8;
  }
  std::printf("staged: %d of %d granules uploaded first; %d pairs among them taken at the first substep, %d across "
              "waited; after the rest: gl %zu, cpu %zu, set %zu contacts (%d missing, %d off); xi up to %.3g m, worst "
              "difference %.3g m (%.3g relative)\n",
              half, bed.body_count(), among, across, back.size(), want.size(), set.size(), missing, off, xi_max, worst_abs,
              worst_rel);
  EXPECT_GT(among, 0);
  EXPECT_GT(across, 0);
  EXPECT_EQ(back.size(), want.size());
  EXPECT_EQ(missing, 0);
  EXPECT_EQ(off, 0);
  EXPECT_GT(xi_max, 1e-6);
}

// Bad entries are refused whole with the CPU's messages (set nothing); more pairs on one
// sphere than spring slots are refused naming GlOptions.max_contacts_per_sphere.
TEST(GlSimulation, ContactSpringsRefuseBadEntries) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  const SimulationDef d = spring_bed_def(4, 4);
  GlOptions o;
  o.max_contacts_per_sphere = 2;
  auto gpu = GlSimulation::create(d, o);
  auto cpu = Simulation::create(d);
  ASSERT_TRUE(gpu.ok() && cpu.ok()) << gpu.message();
  ShellDef shell;
  shell.offsets = {{0, 0, 0}};
  shell.radii = {kBedRadius};
  shell.position = {0.06f, 0.06f, 0.06f};
  std::vector<BodyId> g;
  for (int i = 0; i < 4; ++i) {
    g.push_back(*gpu->add_granule({0.02f + 0.02f * float(i), 0.02f, 0.02f}));
    ASSERT_TRUE(cpu->add_granule({0.02f + 0.02f * float(i), 0.02f, 0.02f}).ok());
  }
  const BodyId sh = *gpu->add_shell(shell);
  ASSERT_TRUE(cpu->add_shell(shell).ok());
  auto refused = [&](ContactSpring c, const std::string& field) {
    const ContactSpring good{g[0], 0, g[1], 1, -1, {1e-4f, 0, 0}, 0};
    const Status st = gpu->set_contact_springs({good, c}), sc = cpu->set_contact_springs({good, c});
    ASSERT_FALSE(st.ok());
    EXPECT_NE(st.message().find("set_contact_springs[1]." + field), std::string::npos) << st.message();
    EXPECT_EQ(st.message(), sc.message());
  };
  refused({g[0], 0, sh, 0, -1, {}, 0}, "b");
  refused({g[0], 0, {}, 0, 6, {}, 0}, "plane");
  refused({g[0], 4, g[1], 0, -1, {}, 0}, "sphere_a");
  refused({g[0], 0, g[1], 0, -1, {NAN, 0, 0}, 0}, "xi");
  refused({g[0], 0, g[1], 0, -1, {}, -1e-3f}, "dmax");
  const Status full = gpu->set_contact_springs(
      {{g[0], 0, g[1], 0, -1, {}, 0}, {g[0], 0, g[2], 0, -1, {}, 0}, {g[3], 0, g[0], 0, -1, {}, 0}});
  ASSERT_FALSE(full.ok());
  EXPECT_NE(full.message().find("GlOptions.max_contacts_per_sphere"), std::string::npos) << full.message();
  EXPECT_TRUE(gpu->set_contact_springs({{g[0], 0, {}, 0, 0, {1e-5f, 0, 0}, 0}}).ok());  // a floor spring
  ASSERT_TRUE(gpu->step(1e-4).ok());
}

// As CarriedSprings.AParkedGranuleLeavesItsPlaneSprings on the CPU: a granule that slid on the
// floor and was parked holds no plane spring when it is enabled again.
TEST(GlSimulation, AParkedGranuleLeavesItsPlaneSprings) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = spring_bed_def(4, 4);
  d.side_walls = false;
  auto s = GlSimulation::create(d);
  ASSERT_TRUE(s.ok()) << s.message();
  const auto [before, after] = springtest::floor_springs_across_parking(*s);
  EXPECT_GT(before, 0);
  EXPECT_EQ(after, 0);
}

}  // namespace
}  // namespace sandpatch::gpu
