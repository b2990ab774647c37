// Sleeping regions of the CPU backend (particles/dem_regions.cpp, SimulationDef::sleep_regions):
// a bed of 432 granules (1,728 spheres, d = 1 cm) 24 granules long; a ball dropped at one end
// and left to rest, then a kinematic blade dragged through the bed from the other end.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "particles/bed.hpp"
#include "particles/dem.hpp"

namespace sandpatch {
namespace {

struct BedRun {
  std::uint64_t hash = 0;
  int granules = 0;
  int asleep_far = 0;        // granules asleep in the half away from the ball, when the blade starts
  int far = 0;               // granules in that half
  int peak_sleeping = 0;     // StepStats::sleeping_granules, the largest over the run
  int touched_asleep = 0;    // frames in which an asleep granule's sphere overlapped a blade sphere
  int woken_by_blade = 0;    // granules asleep when the blade started and awake at the end
  Vec3 ball{};               // m, where the ball rests when the blade starts
  float push = 0;            // N, the bed's mean force on the blade along its motion (-x)
};

constexpr float kR = 0.005f;          // m, sphere radius
constexpr double kFrame = 2e-3;       // s
constexpr int kSettle = 250;          // frames (0.5 s)
constexpr int kBall = 300;            // frames with the ball (0.6 s)
constexpr int kBlade = 150;           // frames with the blade (0.3 s)

BedRun run(bool regions, int threads, std::uint64_t seed = 5) {
  BedRun o;
  SimulationDef d;
  d.threads = threads;
  d.side_walls = true;
  d.cell_skin = 0.5f * kR;
  d.max_substeps = 400;
  d.sleep_time = 0.2f;
  d.sleep_regions = regions;
  const GranuleShape g = make_granule_shape(kR, 1.0f, 2500.0f);
  const float a = 2.0f * (g.centre_distance + g.radius) * 1.02f;
  const int nx = 24, nz = 6, layers = 3;
  const float Lx = nx * a + 0.004f, Lz = nz * a + 0.004f;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {Lx, layers * a + 0.08f, Lz};
  d.max_bodies = nx * nz * layers + 2;
  d.max_particles = 4 * nx * nz * layers + 32;
  auto s = Simulation::create(d);
  EXPECT_TRUE(s.ok()) << s.message();
  if (!s.ok()) return o;
  LatticeBedDef bed;
  bed.nx = nx;
  bed.nz = nz;
  bed.layers = layers;
  bed.spacing = a;
  bed.min = {0.5f * a + 0.002f, g.centre_distance + g.radius + 1e-4f, 0.5f * a + 0.002f};
  bed.seed = seed;
  EXPECT_TRUE(add_lattice_bed(*s, bed).ok());
  o.granules = s->body_count();
  auto frame = [&]() {
    EXPECT_TRUE(s->step(kFrame).ok());
    o.peak_sleeping = std::max(o.peak_sleeping, s->last_step().sleeping_granules);
  };
  for (int k = 0; k < kSettle; ++k) frame();
  float top = 0;
  for (int i = 0; i < o.granules; ++i) top = std::max(top, s->body_position(BodyId{i}).y + g.centre_distance + kR);
  // a 3 cm steel ball dropped 2 cm onto the first sixth of the bed
  ShellDef ball;
  ball.offsets = {{0, 0, 0}};
  ball.radii = {0.015f};
  ball.motion = MotionType::Dynamic;
  ball.mass = float(7800.0 * 4.0 / 3.0 * 3.14159265 * 0.015 * 0.015 * 0.015);
  const float I = 0.4f * ball.mass * 0.015f * 0.015f;
  ball.inertia = {I, I, I};
  ball.position = {0.12f * Lx, top + 0.035f, 0.5f * Lz};
  auto bid = s->add_shell(ball);
  EXPECT_TRUE(bid.ok()) << bid.message();
  if (!bid.ok()) return o;
  for (int k = 0; k < kBall; ++k) frame();
  o.ball = s->body_position(*bid);
  std::vector<char> was_asleep(std::size_t(o.granules), 0);
  for (int i = 0; i < o.granules; ++i) {
    was_asleep[std::size_t(i)] = s->region_asleep(BodyId{i});
    if (s->body_position(BodyId{i}).x > 0.5f * Lx) {
      ++o.far;
      o.asleep_far += was_asleep[std::size_t(i)];
    }
  }
  // a kinematic blade across the bed, its lowest sphere 1.5 sphere diameters under the
  // surface, dragged from the far end towards the ball at 0.2 m/s
  ShellDef blade;
  for (int k = 0; k < 8; ++k) blade.offsets.push_back({0, 0, (k - 3.5f) * 0.008f});
  for (int k = 0; k < 8; ++k) blade.offsets.push_back({0, 0.008f, (k - 3.5f) * 0.008f});
  blade.radii = {kR};
  blade.motion = MotionType::Kinematic;
  blade.position = {Lx - 0.01f, top - 3.0f * kR, 0.5f * Lz};
  blade.velocity = {-0.2f, 0, 0};
  auto tid = s->add_shell(blade);
  EXPECT_TRUE(tid.ok()) << tid.message();
  if (!tid.ok()) return o;
  const int first_blade_sphere = s->particle_count() - int(blade.offsets.size());
  for (int k = 0; k < kBlade; ++k) {
    frame();
    o.push += s->body_force(*tid).x / float(kBlade);
    // no asleep granule's sphere overlaps the blade
    const std::vector<Vec3> p = s->particle_positions();
    bool touched = false;
    for (int i = 0; i < o.granules && !touched; ++i) {
      if (!s->region_asleep(BodyId{i})) continue;
      for (int q = 0; q < 4 && !touched; ++q)
        for (int b = first_blade_sphere; b < s->particle_count(); ++b)
          if (length(p[std::size_t(4 * i + q)] - p[std::size_t(b)]) < 2.0f * kR) touched = true;
    }
    o.touched_asleep += touched;
  }
  for (int i = 0; i < o.granules; ++i) o.woken_by_blade += was_asleep[std::size_t(i)] && !s->region_asleep(BodyId{i});
  o.hash = s->state_hash();
  return o;
}

// The still part of the bed sleeps while the ball is settling in the other end: all of the
// far half (nothing there moves), and never a granule the blade touches; the blade wakes the
// granules ahead of it. What the bodies see is what they see with every granule stepped, within
// what the bed's own chaos moves: the ball rests 0.22 sphere radii from where it rests then
// (moving its drop height by 1-3 um moves that spot 0.02-0.07 r); the blade's mean drag over
// five beds (lattice seeds 5-9) is 8 % lower (per bed -50 % ... +24 %: a bed frozen 0.2 s after
// it came to rest is another sample of a settled bed; the five beds' drags with every granule
// stepped spread 1.0-2.0 N). The same state on 1 and 2 threads.
TEST(SleepingRegions, TheStillPartOfABedSleepsAndWakesAheadOfABlade) {
  const BedRun on1 = run(true, 1), on2 = run(true, 2), off = run(false, 2);
  std::printf("regions: peak asleep %d of %d; far half asleep %d of %d; frames a blade sphere touched an asleep "
              "granule %d; woken by the blade %d\n",
              on2.peak_sleeping, on2.granules, on2.asleep_far, on2.far, on2.touched_asleep, on2.woken_by_blade);
  std::printf("ball at rest: y %.5f m (regions) vs %.5f m (every granule), %.4f r apart\n", on2.ball.y, off.ball.y,
              length(on2.ball - off.ball) / kR);
  EXPECT_EQ(on1.hash, on2.hash) << "the same state on 1 and 2 threads";
  EXPECT_EQ(off.peak_sleeping, 0);
  EXPECT_EQ(on2.asleep_far, on2.far) << "the far half, where nothing moves, sleeps";
  EXPECT_EQ(on2.touched_asleep, 0) << "frames in which the blade touched an asleep granule";
  EXPECT_GT(on2.woken_by_blade, 20) << "granules the blade woke";
  EXPECT_LT(length(on2.ball - off.ball), 0.3f * kR) << "m: where the ball rests";
  double drag_on = on2.push, drag_off = off.push;
  for (std::uint64_t seed : {6, 7, 8, 9}) {
    const BedRun p = run(false, 2, seed), q = run(true, 2, seed);
    std::printf("bed seed %d: blade drag %.3f N (regions) vs %.3f N (every granule); ball %.3f r apart\n", int(seed),
                q.push, p.push, length(p.ball - q.ball) / kR);
    EXPECT_EQ(q.touched_asleep, 0) << "seed " << seed;
    drag_on += q.push, drag_off += p.push;
  }
  std::printf("mean blade drag over 5 beds: %.3f N (regions) vs %.3f N (every granule)\n", drag_on / 5, drag_off / 5);
  EXPECT_GT(drag_off, 0.0);
  EXPECT_NEAR(drag_on, drag_off, 0.2 * drag_off) << "N: the blade's drag, summed over the five beds";
}

// A 20 cm box with side walls, room for 64 granules, regions sleeping after 0.05 s still, and
// one layer of n x n granules on its floor (the small beds of the tests below).
SimulationDef small_box() {
  SimulationDef d;
  d.side_walls = true;
  d.sleep_time = 0.05f;
  d.sleep_regions = true;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {0.2f, 0.1f, 0.2f};
  d.max_bodies = 64;
  d.max_particles = 256;
  return d;
}
LatticeBedDef floor_layer(int n, std::uint64_t seed = 1) {
  LatticeBedDef bed;
  bed.nx = bed.nz = n;
  bed.layers = 1;
  bed.min = {0.02f, 0.0075f, 0.02f};
  bed.seed = seed;
  return bed;
}
// Steps s until granules sleep (at most 200 frames); how many.
int step_until_asleep(Simulation& s) {
  int asleep = 0;
  for (int k = 0; k < 200 && asleep == 0; ++k) {
    EXPECT_TRUE(s.step(kFrame).ok());
    asleep = s.last_step().sleeping_granules;
  }
  return asleep;
}

// What a granule set from outside (Simulation::set_body_state) is: awake, and not still.
TEST(SleepingRegions, AGranuleSetFromOutsideWakes) {
  auto s = Simulation::create(small_box());
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_TRUE(add_lattice_bed(*s, floor_layer(4)).ok());
  ASSERT_GT(step_until_asleep(*s), 0) << "granules at rest on the floor sleep";
  int which = -1;
  for (int i = 0; i < s->body_count() && which < 0; ++i)
    if (s->region_asleep(BodyId{i})) which = i;
  ASSERT_GE(which, 0);
  const BodyId b{which};
  ASSERT_TRUE(s->set_body_state(b, s->body_position(b) + Vec3{0, 0.02f, 0}, s->body_orientation(b), {}, {}).ok());
  EXPECT_FALSE(s->region_asleep(b));
  ASSERT_TRUE(s->step(kFrame).ok());
  EXPECT_FALSE(s->region_asleep(b)) << "it falls: its column is active";
  EXPECT_LT(s->body_velocity(b).y, 0.0f) << "m/s: falling";
}

// A granule handed over from another simulation (the travelling patch, manager/filling.cpp
// take_over) keeps its still time: set after set_body_state, it sleeps at the next step
// instead of after another sleep_time. Bad values are refused naming the field.
TEST(SleepingRegions, AGranuleKeepsTheStillTimeItIsGiven) {
  const SimulationDef d = small_box();
  auto a = Simulation::create(d);
  ASSERT_TRUE(a.ok()) << a.message();
  ASSERT_TRUE(add_lattice_bed(*a, floor_layer(4)).ok());
  const int asleep = step_until_asleep(*a);
  ASSERT_GT(asleep, 0) << "granules at rest on the floor sleep";
  // the same granules, where they lie, in two other simulations: b is given their still
  // times, c is not
  auto b = Simulation::create(d), c = Simulation::create(d);
  ASSERT_TRUE(b.ok() && c.ok());
  const Vec3 shift{0, 0, 0};
  for (int i = 0; i < a->body_count(); ++i) {
    const BodyId g{i};
    for (Simulation* s : {&*b, &*c}) {
      auto id = s->add_granule(a->body_position(g) + shift, a->body_orientation(g));
      ASSERT_TRUE(id.ok());
      ASSERT_TRUE(s->set_body_state(*id, a->body_position(g) + shift, a->body_orientation(g), {}, {}).ok());
      EXPECT_EQ(s->still_time(*id).seconds, 0.0f) << "set from outside: not still";
    }
    Simulation::StillTime t = a->still_time(g);
    t.anchor = t.anchor + shift;
    ASSERT_TRUE(b->set_still_time(BodyId{i}, t).ok());
    EXPECT_EQ(b->still_time(BodyId{i}).seconds, t.seconds);
  }
  ASSERT_TRUE(b->step(kFrame).ok());
  ASSERT_TRUE(c->step(kFrame).ok());
  EXPECT_GE(b->last_step().sleeping_granules, asleep) << "those asleep in a sleep at b's first step";
  EXPECT_EQ(c->last_step().sleeping_granules, 0) << "not given their still times, none sleeps yet";
  // refused, naming the field
  auto field = [&](Status st) { return st.ok() ? std::string("ok") : st.errors().front().field; };
  EXPECT_EQ(field(b->set_still_time(BodyId{0}, {-1.0f, {}})), "set_still_time.seconds");
  EXPECT_EQ(field(b->set_still_time(BodyId{0}, {NAN, {}})), "set_still_time.seconds");
  EXPECT_EQ(field(b->set_still_time(BodyId{0}, {0.1f, {INFINITY, 0, 0}})), "set_still_time.anchor");
  EXPECT_EQ(field(b->set_still_time(BodyId{9999}, {0.1f, {}})), "set_still_time.body");
}

// A simulation reset for another patch (Simulation::reset, a pool slot reused) is the one
// create() makes for that definition: the same state after the same steps, after a larger and
// after a smaller life in the slot (reset sets back only the entries the last life wrote).
TEST(SleepingRegions, AResetSimulationStepsAsAFreshOne) {
  const SimulationDef d = small_box();
  auto fill = [](Simulation& s, int n, std::uint64_t seed) {
    ASSERT_TRUE(add_lattice_bed(s, floor_layer(n, seed)).ok());
    for (int k = 0; k < 60; ++k) ASSERT_TRUE(s.step(kFrame).ok());
  };
  auto fresh = Simulation::create(d);
  ASSERT_TRUE(fresh.ok()) << fresh.message();
  fill(*fresh, 3, 2);
  auto slot = Simulation::create(d);
  ASSERT_TRUE(slot.ok()) << slot.message();
  fill(*slot, 5, 7);  // a larger life first
  ASSERT_TRUE(slot->reset(d).ok());
  fill(*slot, 3, 2);
  EXPECT_EQ(slot->state_hash(), fresh->state_hash()) << "after a larger life";
  ASSERT_TRUE(slot->reset(d).ok());
  fill(*slot, 2, 9);  // a smaller one
  ASSERT_TRUE(slot->reset(d).ok());
  fill(*slot, 3, 2);
  EXPECT_EQ(slot->state_hash(), fresh->state_hash()) << "after a smaller life";
}

}  // namespace
}  // namespace sandpatch
