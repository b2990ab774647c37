// Simulation API (particles/dem.cpp): validation and capacities, the stability guard, the shell list,
// determinism across threads, energy, sleep and wake, terrain outside the patch.
#include "particles/dem.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <numbers>

#include "particles/bed.hpp"
#include "particles/contact_simd.hpp"
#include "tests/particles/bed_common.hpp"
#include "tests/particles/jointed_shells.hpp"

namespace sandpatch {
namespace {

SimulationDef small_box() {
  SimulationDef d;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {0.12f, 0.2f, 0.12f};
  d.side_walls = true;
  d.sleep_time = 0;
  return d;
}

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
float urand(std::uint64_t& s) { return float(double(splitmix(s) >> 11) / 9007199254740992.0); }

}  // namespace

TEST(Simulation, CreateNamesBadField) {
  SimulationDef d;
  d.particle_radius = -1;
  auto s = Simulation::create(d);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "SimulationDef.particle_radius");
  d = SimulationDef{};
  d.material.normal_stiffness = 0;
  s = Simulation::create(d);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "SimulationDef.material.normal_stiffness");
}

// Full pools return an Error naming the capacity to raise; nothing is half-added.
TEST(Simulation, CapacityExceededNamesCapacity) {
  SimulationDef d = small_box();
  d.max_bodies = 2;
  d.max_particles = 100;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE(s->add_granule({0.05f, 0.05f, 0.05f}).ok());
  ASSERT_TRUE(s->add_granule({0.08f, 0.05f, 0.05f}).ok());
  auto r = s->add_granule({0.05f, 0.1f, 0.05f});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "SimulationDef.max_bodies");
  EXPECT_EQ(s->body_count(), 2);
  d.max_bodies = 100;
  d.max_particles = 6;
  s = Simulation::create(d);
  ASSERT_TRUE(s->add_granule({0.05f, 0.05f, 0.05f}).ok());
  r = s->add_granule({0.08f, 0.05f, 0.05f});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "SimulationDef.max_particles");
  EXPECT_EQ(s->particle_count(), 4);
}

// The guard: a frame of 1/60 s with k_n = 1e9 needs ~1e4 substeps: refused, naming dt_frame
// and what to change; no state changes, no NaN. A frame 2x the stable limit is substepped
// (2 substeps) and stays finite; 0.5x runs in one.
TEST(Simulation, StabilityGuard) {
  SimulationDef d = small_box();
  d.material.normal_stiffness = 1e9f;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok());
  ASSERT_TRUE(s->add_granule({0.06f, 0.05f, 0.06f}).ok());
  auto st = s->step(1.0 / 60);
  ASSERT_FALSE(st.ok());
  EXPECT_EQ(st.error().field, "step.dt_frame");
  EXPECT_NE(st.error().detail.find("max_substeps"), std::string::npos);
  EXPECT_EQ(s->time(), 0.0);

  d.material.normal_stiffness = 3292;
  s = Simulation::create(d);
  ASSERT_TRUE(s->add_granule({0.06f, 0.0075f, 0.06f}).ok());
  const double lim = s->max_substep_dt();
  // the limit is the undamped contact time of two granules touching at a sphere (point
  // effective mass, particles/granule.hpp), divided by N = 20; it is below the damped t_c/20
  const GranuleShape& g = s->granule_shape();
  double mp = point_effective_mass(g.mass, g.inertia, g.centre_distance) / 2;
  EXPECT_NEAR(lim, std::numbers::pi * std::sqrt(mp / 3292.0) / 20, 1e-9);
  EXPECT_LE(lim, s->contact_time() / 20);
  EXPECT_EQ(*s->substeps_for(0.5 * lim), 1);
  EXPECT_EQ(*s->substeps_for(2.0 * lim), 2);
  for (int k = 0; k < 2000; ++k) ASSERT_TRUE(s->step(2.0 * lim).ok());
  Vec3 p = s->body_position(BodyId{0});
  EXPECT_TRUE(std::isfinite(p.x + p.y + p.z));
  EXPECT_GT(p.y, 0.0f);  // resting on the floor, not through it
  EXPECT_FALSE(s->step(-1).ok());
}

// The contact timing correction (velocity predictor + first-substep dashpot) follows the
// accuracy asked of the guard: off at the default t_c/20, on from t_c/50 (Auto); On and Off
// force it. When on, the predictor's gain is 1/2 for the default material (e = 0.3: damping
// per substep 2 zeta w0 dt well below 0.2).
TEST(Simulation, ContactTimingFollowsTheAccuracyAsked) {
  SimulationDef d = small_box();
  auto at = [&](int N, SimulationDef::ContactTiming t) {
    SimulationDef e = d;
    e.accuracy_steps_per_contact = N;
    e.contact_timing = t;
    auto s = Simulation::create(e);
    EXPECT_TRUE(s.ok());
    const double dt = s->max_substep_dt();
    return std::pair{s->contact_timing_on(dt), s->velocity_predictor_gain(dt)};
  };
  using T = SimulationDef::ContactTiming;
  EXPECT_EQ(at(20, T::Auto), std::pair(false, 0.0));
  EXPECT_EQ(at(49, T::Auto), std::pair(false, 0.0));
  EXPECT_EQ(at(50, T::Auto), std::pair(true, 0.5));
  EXPECT_EQ(at(20, T::On), std::pair(true, 0.5));
  EXPECT_EQ(at(100, T::Off), std::pair(false, 0.0));
}

namespace {
// A loose lattice of granules falling into a box (a few hundred contacts per step).
// unloading: Material::unloading_stiffness_ratio (1: the linear spring; with it restitution 1).
std::uint64_t run_pile(int threads, int steps, int steps_per_contact = 20, float unloading = 1.0f) {
  SimulationDef d = small_box();
  d.accuracy_steps_per_contact = steps_per_contact;
  d.material.unloading_stiffness_ratio = unloading;
  if (unloading > 1.0f) d.material.restitution = 1.0f;
  d.threads = threads;
  d.max_bodies = 200;
  d.max_particles = 800;
  auto s = Simulation::create(d);
  LatticeBedDef bed;
  bed.nx = bed.nz = 5;
  bed.layers = 6;
  bed.min = {0.012f, 0.012f, 0.012f};
  bed.seed = 7;
  EXPECT_TRUE(add_lattice_bed(*s, bed).ok());
  for (int k = 0; k < steps; ++k) EXPECT_TRUE(s->step(5e-5).ok());
  EXPECT_GT(s->last_step().contacts, 0);
  return s->state_hash();
}
}  // namespace

// Same scene: the same hash for 1 and 2 threads and for two runs (no FP atomics; every sum
// in a fixed order).
TEST(Simulation, DeterministicAcrossThreadsAndRuns) {
  std::uint64_t h1 = run_pile(1, 3000);
  std::uint64_t h2 = run_pile(2, 3000);
  std::uint64_t h2b = run_pile(2, 3000);
  EXPECT_EQ(h1, h2);
  EXPECT_EQ(h2, h2b);
  // with the contact timing correction on (first-substep flags carried across list rebuilds)
  EXPECT_EQ(run_pile(1, 3000, 50), run_pile(2, 3000, 50));
}

// Above 1,024 spheres the stages run on the threads (smaller beds run serially): 1,200 granules
// falling in a box give the same state whether they run on 1 thread, on 2, or switch between
// the two mid-run (Simulation::set_threads); a negative count is refused naming the field.
TEST(Simulation, SetThreadsMidRunKeepsTheState) {
  auto run = [](int threads_first, int threads_then) {
    SimulationDef d;
    d.bounds_min = {0, 0, 0};
    d.bounds_max = {0.3f, 0.4f, 0.3f};
    d.side_walls = true;
    d.sleep_time = 0;
    d.max_bodies = 1200;
    d.max_particles = 4800;
    d.threads = threads_first;
    auto s = Simulation::create(d);
    LatticeBedDef bed;
    bed.nx = bed.nz = 10;
    bed.layers = 12;
    bed.min = {0.02f, 0.012f, 0.02f};
    bed.seed = 11;
    EXPECT_TRUE(add_lattice_bed(*s, bed).ok());
    EXPECT_GT(s->particle_count(), 4096);
    for (int k = 0; k < 1200; ++k) {  // the bottom layer lands after ~300 steps, the next on it
      if (k == 600) {
        EXPECT_TRUE(s->set_threads(threads_then).ok());
      }
      EXPECT_TRUE(s->step(5e-5).ok());
    }
    EXPECT_GT(s->last_step().contacts, 0);
    return s->state_hash();
  };
  const std::uint64_t h11 = run(1, 1);
  EXPECT_EQ(run(2, 2), h11);
  EXPECT_EQ(run(2, 1), h11);
  EXPECT_EQ(run(1, 2), h11);
  SimulationDef d = small_box();
  auto s = Simulation::create(d);
  const Status st = s->set_threads(-1);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("set_threads.threads = -1"), std::string::npos) << st.message();
}

// Simulation::set_steps_per_contact: the next steps take the new substep bound (a frame of
// t_c-limited substeps takes about half as many at N = 10 as at N = 20), the state is kept,
// and N < 2 is refused naming the field.
TEST(Simulation, StepsPerContactChangesTheNextStepsSubsteps) {
  SimulationDef d = small_box();
  d.accuracy_steps_per_contact = 20;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_TRUE(s->add_granule({0.05f, 0.05f, 0.05f}).ok());
  const double frame = 20 * s->max_substep_dt();  // 20 substeps at N = 20
  auto n20 = s->substeps_for(frame);
  ASSERT_TRUE(n20.ok()) << n20.message();
  ASSERT_TRUE(s->step(frame).ok());
  const std::uint64_t h = s->state_hash();
  ASSERT_TRUE(s->set_steps_per_contact(10).ok());
  EXPECT_EQ(s->state_hash(), h) << "the state is kept";
  EXPECT_EQ(s->def().accuracy_steps_per_contact, 10);
  auto n10 = s->substeps_for(frame);
  ASSERT_TRUE(n10.ok());
  EXPECT_NEAR(double(*n10), 0.5 * double(*n20), 1.0) << *n20 << " substeps at N = 20";
  ASSERT_TRUE(s->step(frame).ok());
  EXPECT_EQ(s->last_step().substeps, *n10);
  const Status st = s->set_steps_per_contact(1);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("accuracy_steps_per_contact = 1"), std::string::npos) << st.message();
}

// The AVX2 pair kernel (particles/contact_avx2.cpp, used when the CPU has AVX2) gives the
// scalar contact law's results bit for bit: the same state hash with SANDPATCH_DEM_KERNEL=scalar,
// with the timing correction off and on, and with the hysteretic normal spring (lambda = 11.1,
// restitution 1: the kernel's dmax lane). (On a CPU without AVX2 both runs are scalar.)
TEST(Simulation, Avx2PairKernelMatchesScalarBitForBit) {
  const char* saved = std::getenv("SANDPATCH_DEM_KERNEL");
  const std::string keep = saved ? saved : "";
  for (float lambda : {1.0f, 11.111111f})
    for (int N : {20, 50}) {
      ::unsetenv("SANDPATCH_DEM_KERNEL");
      const std::uint64_t fast = run_pile(2, 3000, N, lambda);
      ::setenv("SANDPATCH_DEM_KERNEL", "scalar", 1);
      const std::uint64_t scalar = run_pile(2, 3000, N, lambda);
      EXPECT_EQ(fast, scalar) << "N = " << N << ", lambda " << lambda;
      if (lambda > 1.0f && N == 20) {
        EXPECT_NE(fast, run_pile(2, 3000, N)) << "the hysteretic law must change the bed";
      }
    }
  if (saved) ::setenv("SANDPATCH_DEM_KERNEL", keep.c_str(), 1); else ::unsetenv("SANDPATCH_DEM_KERNEL");
  std::printf("AVX2 pair kernel available: %s\n", simd::avx2_available() ? "yes" : "no");
}

namespace {
// A dilute gas of granules in a walled box without gravity (volume fraction ~2%).
Simulation make_gas(float e, float mu, int n,
                    SimulationDef::ContactTiming timing = SimulationDef::ContactTiming::Auto, float unloading = 1.0f) {
  SimulationDef d = small_box();
  d.contact_timing = timing;
  d.bounds_max = {0.15f, 0.15f, 0.15f};
  d.gravity_world = {0, 0, 0};
  d.floor_height = 0;
  d.material.restitution = e;
  d.material.friction = mu;
  d.material.unloading_stiffness_ratio = unloading;
  d.max_bodies = n + 8;  // room for a few added later (SpringEnergyAndHashAfterABodyIsAdded)
  d.max_particles = 4 * (n + 8);
  auto s = Simulation::create(d);
  EXPECT_TRUE(s.ok());
  std::uint64_t seed = 42;
  int side = int(std::ceil(std::cbrt(double(n))));
  float a = 0.15f / float(side);
  for (int i = 0; i < n; ++i) {
    int ix = i % side, iy = (i / side) % side, iz = i / (side * side);
    Vec3 x{(ix + 0.5f) * a, (iy + 0.5f) * a, (iz + 0.5f) * a};
    Vec3 v{urand(seed) - 0.5f, urand(seed) - 0.5f, urand(seed) - 0.5f};
    Vec3 w{20 * (urand(seed) - 0.5f), 20 * (urand(seed) - 0.5f), 20 * (urand(seed) - 0.5f)};
    Quat q = normalized(Quat{urand(seed) - 0.5f, urand(seed) - 0.5f, urand(seed) - 0.5f, urand(seed) - 0.5f});
    EXPECT_TRUE(s->add_granule(x, q, v, w).ok());
  }
  return std::move(*s);
}
}  // namespace

// e = 1, mu = 0: total energy (kinetic + elastic) conserved within 1% over 1e4 steps at
// dt = 5e-5 s (t_c/39). The gas is dilute but collides: we check collisions happened.
TEST(Energy, ConservedWithoutDampingOrFriction) {
  Simulation s = make_gas(1.0f, 0.0f, 125);
  double e0 = s.kinetic_energy() + s.potential_energy();
  std::int64_t contacts = 0;
  double worst = 0;
  for (int k = 0; k < 10000; ++k) {
    ASSERT_TRUE(s.step(5e-5).ok());
    contacts += s.last_step().contacts + s.last_step().wall_contacts;
    double e = s.kinetic_energy() + s.potential_energy();
    worst = std::max(worst, std::abs(e - e0) / e0);
  }
  EXPECT_GT(contacts, 100);
  EXPECT_LT(worst, 0.01);
  std::printf("energy: worst relative deviation %.3g over 1e4 steps, %lld contact-steps\n", worst,
              (long long)contacts);
}

// e = 0.5, mu = 0.5: energy never rises, checked every step. Tolerance: 1e-4 of the initial
// energy per step (the symplectic-Euler energy of a contact oscillates by O(w dt) of the
// contact's elastic energy; measured worst rise is printed).
// Checked with the contact timing correction off (the default at t_c/20) and on.
TEST(Energy, NeverRisesWithDamping) {
  for (auto timing : {SimulationDef::ContactTiming::Off, SimulationDef::ContactTiming::On}) {
    Simulation s = make_gas(0.5f, 0.5f, 125, timing);
    double e0 = s.kinetic_energy() + s.potential_energy();
    double prev = e0, worst_rise = 0;
    for (int k = 0; k < 10000; ++k) {
      ASSERT_TRUE(s.step(5e-5).ok());
      double e = s.kinetic_energy() + s.potential_energy();
      worst_rise = std::max(worst_rise, (e - prev) / e0);
      prev = e;
    }
    EXPECT_LT(worst_rise, 1e-4);
    EXPECT_LT(prev, e0);
    std::printf("damped, timing %s: worst per-step rise %.3g of E0, final/initial %.3f\n",
                timing == SimulationDef::ContactTiming::On ? "on" : "off", worst_rise, prev / e0);
  }
}

// The energy ledger (Simulation::set_energy_ledger): in the damped gas (e = 0.5, mu = 0.5, 125
// granules, 0.2 s) kinetic + spring energy + the work the ledger says the normal
// spring-dashpot and friction dissipated stays the initial energy up to a first-order error of
// the step (the ledger takes each contact's velocity at the substep's start, the bodies'
// kinetic energy changes with the mean of the old and new velocity): within 5 % of E0 at
// dt = 5e-5 s (measured 3.9 %, 3.6 %) and about half that at dt / 2 (asserted < 0.6 x; measured
// 1.9 %, 1.8 %), with the linear spring and with the hysteretic one (lambda = 4, whose springs'
// energy is normal_spring_energy, not potential_energy's 1/2 k_n delta^2). Both counters end
// positive. The ledger does not change the state: the same hash as a run without it.
TEST(Energy, LedgerBalancesTheLoss) {
  for (float lambda : {1.0f, 4.0f}) {
    double worst[2] = {0, 0};
    for (int half = 0; half < 2; ++half) {
      const double h = half ? 2.5e-5 : 5e-5;
      Simulation s = make_gas(0.5f, 0.5f, 125, SimulationDef::ContactTiming::Auto, lambda);
      Simulation ref = make_gas(0.5f, 0.5f, 125, SimulationDef::ContactTiming::Auto, lambda);
      const double e0 = s.kinetic_energy() + s.potential_energy();  // no contact at the start: springs 0
      s.set_energy_ledger(true);
      for (int k = 0; k < int(std::lround(0.2 / h)); ++k) {
        ASSERT_TRUE(s.step(h).ok());
        ASSERT_TRUE(ref.step(h).ok());
        const double e = s.kinetic_energy() + s.normal_spring_energy() + s.tangential_spring_energy() +
                         s.dissipated_normal() + s.dissipated_friction();
        worst[half] = std::max(worst[half], std::abs(e - e0) / e0);
      }
      EXPECT_GT(s.dissipated_normal(), 0.05 * e0);
      EXPECT_GT(s.dissipated_friction(), 0.0);
      EXPECT_EQ(s.state_hash(), ref.state_hash()) << "lambda " << lambda;
      std::printf("ledger, lambda %.0f, dt %.3g s: worst imbalance %.3g of E0; dissipated normal %.3f, friction %.3f of E0\n",
                  lambda, h, worst[half], s.dissipated_normal() / e0, s.dissipated_friction() / e0);
    }
    EXPECT_LT(worst[0], 0.05) << "lambda " << lambda;
    EXPECT_LT(worst[1], 0.6 * worst[0]) << "lambda " << lambda;
  }
}

// Bodies added after the neighbour list was built (a ball dropped into a settled bed) are not in
// that list until its next build: the tangential springs' energy and the state hash read the
// list as it was built, not past its end. Measured: the same energy as before the add, and a
// hash that is the same for two simulations that did the same.
TEST(Energy, SpringEnergyAndHashAfterABodyIsAdded) {
  Simulation s = make_gas(0.5f, 0.5f, 64);
  Simulation ref = make_gas(0.5f, 0.5f, 64);
  for (int k = 0; k < 400; ++k) {
    ASSERT_TRUE(s.step(5e-5).ok());
    ASSERT_TRUE(ref.step(5e-5).ok());
  }
  const double et = s.tangential_spring_energy();
  EXPECT_GT(et, 0.0);  // the gas has contacts with springs to count
  for (Simulation* x : {&s, &ref})
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(x->add_granule({0.02f + 0.05f * float(i), 0.14f, 0.14f}).ok());
  EXPECT_EQ(s.tangential_spring_energy(), et);
  EXPECT_EQ(s.state_hash(), ref.state_hash());
  ASSERT_TRUE(s.step(5e-5).ok());
  EXPECT_TRUE(std::isfinite(s.tangential_spring_energy()));
}

// A granule dropped on the floor comes to rest; the simulation falls asleep after
// sleep_time below sleep_speed and then does nothing; a kinematic shell that moves towards
// the granule wakes it when it comes within contact range, and not before.
TEST(Sleep, SleepsAndKinematicContactWakes) {
  SimulationDef d = small_box();
  d.sleep_time = 0.2f;
  d.sleep_speed = 0.005f;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok());
  auto g = s->add_granule({0.06f, 0.02f, 0.06f});
  ShellDef k;
  k.offsets = {{0, 0, 0}};
  k.radii = {0.005f};
  k.motion = MotionType::Kinematic;
  k.position = {0.1f, 0.008f, 0.06f};
  auto kid = s->add_shell(k);
  ASSERT_TRUE(g.ok() && kid.ok());
  int n = 0;
  while (!s->asleep() && n < 40000) {
    ASSERT_TRUE(s->step(1e-3).ok());
    ++n;
  }
  ASSERT_TRUE(s->asleep()) << "max speed " << s->max_granule_speed();
  std::uint64_t h = s->state_hash();
  ASSERT_TRUE(s->step(1e-3).ok());
  EXPECT_TRUE(s->last_step().slept);
  EXPECT_EQ(s->state_hash(), h);  // nothing moved
  // drive the kinematic sphere towards the granule at 0.05 m/s
  ASSERT_TRUE(s->set_kinematic_velocity(*kid, {-0.05f, 0, 0}, {}).ok());
  int woke_at = -1;
  for (int i = 0; i < 1000 && woke_at < 0; ++i) {
    ASSERT_TRUE(s->step(1e-3).ok());
    if (!s->asleep()) woke_at = i;
  }
  ASSERT_GE(woke_at, 0);
  // at wake-up the kinematic sphere is within contact range (+ skin) of a granule sphere
  float gap = 1e9f;
  auto ps = s->particle_positions();
  for (int i = 0; i < 4; ++i) gap = std::min(gap, length(ps[i] - ps[4]) - 0.01f);
  EXPECT_LT(gap, 0.002f);
}

// Terrain outside the filled region: a sphere dropped beyond the fill rests on the grid's
// height (0.05 m there), not on the floor (0).
TEST(Boundaries, RestsOnTerrainOutsideFill) {
  SimulationDef d;
  d.bounds_min = {-0.1f, 0, -0.1f};
  d.bounds_max = {0.1f, 0.2f, 0.1f};
  d.sleep_time = 0;
  d.terrain.nx = d.terrain.nz = 3;
  d.terrain.x0 = d.terrain.z0 = -0.1f;
  d.terrain.spacing = 0.1f;
  d.terrain.heights.assign(9, 0.05f);
  d.terrain.fill_min_x = d.terrain.fill_min_z = -0.05f;
  d.terrain.fill_max_x = d.terrain.fill_max_z = 0.05f;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok()) << s.message();
  auto out = s->add_granule({0.08f, 0.1f, 0.0f});
  auto in = s->add_granule({0.0f, 0.1f, 0.0f});
  for (int k = 0; k < 20000; ++k) ASSERT_TRUE(s->step(5e-5).ok());
  auto ps = s->particle_positions();
  float low_out = 1e9f, low_in = 1e9f;
  for (int i = 0; i < 4; ++i) low_out = std::min(low_out, ps[i].y);
  for (int i = 4; i < 8; ++i) low_in = std::min(low_in, ps[i].y);
  EXPECT_NEAR(low_out, 0.05f + 0.005f, 0.0005f);  // lowest sphere centre = terrain + r
  EXPECT_NEAR(low_in, 0.0f + 0.005f, 0.0005f);
}

// Collision groups (ShellDef::group, set_body_group): two overlapping shells of one group feel
// nothing from each other, granules still touch both; shells of no group or of two groups
// push each other with the law's k_n delta. With the AVX2 pair kernel and the scalar pass.
TEST(CollisionGroups, ShellsOfOneGroupDoNotTouch) {
  const char* saved = std::getenv("SANDPATCH_DEM_KERNEL");
  const std::string keep = saved ? saved : "";
  for (const char* kernel : {"", "scalar"}) {
    SCOPED_TRACE(std::string("kernel ") + (*kernel ? kernel : "default"));
    if (*kernel) ::setenv("SANDPATCH_DEM_KERNEL", kernel, 1); else ::unsetenv("SANDPATCH_DEM_KERNEL");
    testutil::check_collision_groups(
        [](const SimulationDef& d) {
          auto s = Simulation::create(d);
          EXPECT_TRUE(s.ok()) << s.message();
          return std::move(*s);
        },
        [](Simulation& s) {
          ASSERT_TRUE(s.step(1e-6).ok());
          ASSERT_EQ(s.last_step().substeps, 1);
        });
  }
  if (saved) ::setenv("SANDPATCH_DEM_KERNEL", keep.c_str(), 1); else ::unsetenv("SANDPATCH_DEM_KERNEL");
}

// The shell list (dem_impl.hpp): a kinematic blade of 14 spheres comes down at 0.3 m/s from
// 2 cm above a settled 10 x 10 x 3 granule bed and presses 1.3 cm into it (0.15 s; the terrain
// manager's skin, 0.5 r). Rebuilt when the blade has moved shell_trip (2.5 mm here), the list
// finds every pair in time: every sphere ends where it ends with the list rebuilt at every
// substep (SANDPATCH_DEM_SHELL_LIST=each), bit for bit (with a trip of twice the shell skin,
// 1,196 of the 1,214 spheres end elsewhere). The state is the same on 1 and 2 threads (the
// stages run on the threads above 1,024 spheres).
TEST(NeighbourLists, AShellPressingIntoABedFindsEveryPairInTime) {
  struct Out {
    std::uint64_t hash = 0;
    std::vector<Vec3> positions;
    int resorts = 0, shell_lists = 0;  // grid + both lists; the shell list alone
    float push = 0;                    // N, the bed's mean upward force on the blade
  };
  auto run = [](int threads, bool each_substep) {
    Out o;
    if (each_substep) ::setenv("SANDPATCH_DEM_SHELL_LIST", "each", 1);
    SimulationDef d;
    d.sleep_time = 0;
    d.threads = threads;
    d.side_walls = true;
    d.cell_skin = 0.0025f;
    const float a = bedtest::box_spacing();
    const int n = 10, layers = 3;
    const float L = n * a + 0.004f;
    d.bounds_min = {0, 0, 0};
    d.bounds_max = {L + 0.03f, layers * a + 0.05f, L};  // (the blade starts in the first 3 cm)
    d.max_bodies = n * n * layers + 1;
    d.max_particles = 4 * n * n * layers + 14;
    auto s = Simulation::create(d);
    ::unsetenv("SANDPATCH_DEM_SHELL_LIST");
    EXPECT_TRUE(s.ok()) << s.message();
    if (!s.ok()) return o;
    LatticeBedDef bed = bedtest::box_lattice(n, layers);
    bed.min.x += 0.03f;  // (the blade's first 3 cm)
    EXPECT_TRUE(add_lattice_bed(*s, bed).ok());
    const double dt = 5e-5;
    for (int k = 0; k < 16000; ++k) EXPECT_TRUE(s->step(dt).ok());  // 0.8 s: settled
    float top = 0;
    for (int i = 0; i < s->body_count(); ++i) top = std::max(top, s->body_position(BodyId{i}).y);
    ShellDef blade;
    for (int k = 0; k < 14; ++k) blade.offsets.push_back({0, 0, (k - 6.5f) * 0.01f});
    blade.radii = {0.005f};
    blade.motion = MotionType::Kinematic;
    blade.position = {0.5f * L + 0.03f, top + 0.02f, 0.5f * L};
    blade.velocity = {0, -0.3f, 0};
    auto bid = s->add_shell(blade);
    EXPECT_TRUE(bid.ok()) << bid.message();
    if (!bid.ok()) return o;
    for (int k = 0; k < 3000; ++k) {
      EXPECT_TRUE(s->step(dt).ok());
      o.resorts += s->last_step().resorts;
      o.shell_lists += s->last_step().shell_lists;
      o.push += s->body_force(*bid).y / 3000.0f;
    }
    o.positions = s->particle_positions();
    o.hash = s->state_hash();
    return o;
  };
  const Out one = run(1, false), two = run(2, false), each = run(2, true);
  EXPECT_EQ(one.hash, two.hash);
  ASSERT_EQ(two.positions.size(), each.positions.size());
  int differ = 0;
  for (std::size_t k = 0; k < two.positions.size(); ++k)
    differ += two.positions[k].x != each.positions[k].x || two.positions[k].y != each.positions[k].y ||
              two.positions[k].z != each.positions[k].z;
  EXPECT_EQ(differ, 0) << "spheres not where the every-substep list puts them";
  EXPECT_GT(two.push, 1.0f);        // it pressed into the bed
  EXPECT_GE(two.shell_lists, 1);    // the blade rebuilt its list between the granules' rebuilds
  std::printf("blade: push %.3g N, grid rebuilds %d, shell list alone %d (every substep: %d, %d)\n", two.push,
              two.resorts, two.shell_lists, each.resorts, each.shell_lists);
}

}  // namespace sandpatch
