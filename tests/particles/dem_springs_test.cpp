// Contact springs carried from one simulation into another (particles/dem_springs.cpp).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "particles/dem.hpp"
#include "tests/particles/springs_common.hpp"

namespace sandpatch {
namespace {

using namespace springtest;
constexpr float kRadius = kBedRadius;

// The same granules at the same places in a new simulation, with or without the springs.
Simulation copy_of(const Simulation& from, bool springs) {
  auto s = Simulation::create(from.def());
  EXPECT_TRUE(s.ok()) << s.message();
  copy_bed(from, *s, springs);
  return std::move(*s);
}

double mean_motion(Simulation& s, double seconds) { return mean_motion_d(s, seconds); }

}  // namespace

// A settled bed rebuilt from its positions alone compacts as a whole (its tangential springs
// start at zero, and the packing slips until they have grown back); rebuilt with its springs
// it stays as still as the bed itself. Measured: without 0.003-0.009 d in 0.1 s, with and the
// bed itself about 1e-5 d.
TEST(CarriedSprings, ABedRebuiltWithItsSpringsStaysAtRest) {
  Simulation bed = settled_bed(6, 6, 1.0);
  const std::vector<ContactSpring> springs = bed.contact_springs();
  int pairs = 0, planes = 0;
  for (const ContactSpring& c : springs) (c.plane < 0 ? pairs : planes)++;
  EXPECT_GT(pairs, bed.body_count());  // a packed bed: several contacts per granule
  EXPECT_GT(planes, 36);               // its bottom layer on the floor, its sides on the walls
  Simulation without = copy_of(bed, false), with = copy_of(bed, true);
  const double own = mean_motion(bed, 0.1), lost = mean_motion(without, 0.1), kept = mean_motion(with, 0.1);
  std::printf("mean motion in 0.1 s (d): the bed %.3g, rebuilt without springs %.3g, with %.3g (%d pairs, %d planes)\n",
              own, lost, kept, pairs, planes);
  EXPECT_GT(lost, 1e-3);
  EXPECT_LT(kept, 0.1 * lost);
  EXPECT_LT(kept, 5e-4);
  // The springs read back from the rebuilt bed are those set (after its steps, as the bed's own).
  EXPECT_EQ(with.contact_springs().size(), bed.contact_springs().size());
}

// Bad entries are refused whole, naming the entry and field.
TEST(CarriedSprings, RefusesBadEntriesNamingTheField) {
  auto s = Simulation::create(bed_def(4, 4));
  ASSERT_TRUE(s.ok());
  const BodyId a = *s->add_granule({0.02f, 0.02f, 0.02f}), b = *s->add_granule({0.04f, 0.02f, 0.02f});
  ShellDef shell;
  shell.offsets = {{0, 0, 0}};
  shell.radii = {kRadius};
  shell.position = {0.06f, 0.06f, 0.06f};
  const BodyId sh = *s->add_shell(shell);
  auto refused = [&](ContactSpring c, const std::string& field) {
    const ContactSpring good{a, 0, b, 1, -1, {1e-4f, 0, 0}, 0};
    const Status st = s->set_contact_springs({good, c});
    EXPECT_FALSE(st.ok());
    EXPECT_NE(st.message().find("set_contact_springs[1]." + field), std::string::npos) << st.message();
  };
  refused({a, 4, b, 0, -1, {}, 0}, "sphere_a");
  refused({a, 0, b, -1, -1, {}, 0}, "sphere_b");
  refused({a, 0, a, 1, -1, {}, 0}, "b");
  refused({a, 0, sh, 0, -1, {}, 0}, "b");
  refused({sh, 0, a, 0, -1, {}, 0}, "a");
  refused({BodyId{7}, 0, a, 0, -1, {}, 0}, "a");
  refused({a, 0, {}, 0, 6, {}, 0}, "plane");
  refused({a, 0, b, 0, -1, {NAN, 0, 0}, 0}, "xi");
  refused({a, 0, b, 0, -1, {}, -1e-3f}, "dmax");
  refused({a, 0, b, 0, -1, {}, INFINITY}, "dmax");
  EXPECT_TRUE(s->set_contact_springs({{a, 0, {}, 0, 0, {1e-5f, 0, 0}, 0}}).ok());  // a floor spring
}

}  // namespace sandpatch

namespace sandpatch {

// A parked body's boundary contacts end with it: a granule sliding on the floor holds a plane
// spring; parked, it holds none, so enabled again elsewhere its first contact with a plane is
// a new one (not the old spring, stretched where it slid).
TEST(CarriedSprings, AParkedGranuleLeavesItsPlaneSprings) {
  SimulationDef d = bed_def(4, 4);
  d.side_walls = false;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok()) << s.message();
  const auto [before, after] = floor_springs_across_parking(*s);
  EXPECT_GT(before, 0);
  EXPECT_EQ(after, 0);  // (before its next step: none carried over from before it was parked)
}

// A pair's spring set twice takes the later one (set_contact_springs keeps the springs in the
// order set; the list build looks each pair up in the rows of its lower id): a bed given its
// springs with every pair first zeroed, then as read, steps to the state of the bed given them
// once; given them only zeroed, it does not.
TEST(CarriedSprings, APairSetTwiceTakesTheLaterSpring) {
  Simulation bed = settled_bed(4, 3, 0.5);
  const std::vector<ContactSpring> springs = bed.contact_springs();
  std::vector<ContactSpring> zeroed = springs;
  for (ContactSpring& c : zeroed) c.xi = Vec3{0, 0, 0};
  auto rebuilt = [&](const std::vector<std::vector<ContactSpring>>& sets) {
    auto s = Simulation::create(bed.def());
    EXPECT_TRUE(s.ok()) << s.message();
    for (int b = 0; b < bed.body_count(); ++b)
      EXPECT_TRUE(s->add_granule(bed.body_position(BodyId{b}), bed.body_orientation(BodyId{b})).ok());
    for (const auto& set : sets) EXPECT_TRUE(s->set_contact_springs(set).ok());
    EXPECT_TRUE(s->step(1.0 / 120.0).ok());
    return s->state_hash();
  };
  const std::uint64_t once = rebuilt({springs}), twice = rebuilt({zeroed, springs}), zero = rebuilt({zeroed});
  EXPECT_EQ(twice, once);
  EXPECT_NE(zero, once);  // (the springs matter to the step: the test can fail)
}

// Lists built ahead of a step (Simulation::build_lists_now: the terrain manager does it on all
// threads before patches step side by side one thread each) give the step's own results: a
// bed rebuilt with its springs steps to the same state either way, and the step's stats count
// the sort built ahead; with nothing to build, build_lists_now does nothing.
TEST(CarriedSprings, ListsBuiltAheadOfTheStepGiveTheSameState) {
  Simulation bed = settled_bed(4, 3, 0.5);
  auto rebuilt = [&](bool ahead) {
    auto s = Simulation::create(bed.def());
    EXPECT_TRUE(s.ok()) << s.message();
    copy_bed(bed, *s, true);
    if (ahead) s->build_lists_now();
    EXPECT_TRUE(s->step(1.0 / 120.0).ok());
    EXPECT_GE(s->last_step().resorts, 1);  // (the first sort, ahead or in the step)
    return std::move(*s);
  };
  Simulation in_step = rebuilt(false), ahead = rebuilt(true);
  EXPECT_EQ(ahead.state_hash(), in_step.state_hash());
  const int before = ahead.last_step().resorts;
  ahead.build_lists_now();  // (lists fresh: nothing to build, the last step's stats kept)
  EXPECT_EQ(ahead.last_step().resorts, before);
  EXPECT_TRUE(ahead.step(1.0 / 120.0).ok());
  EXPECT_TRUE(in_step.step(1.0 / 120.0).ok());
  EXPECT_EQ(ahead.state_hash(), in_step.state_hash());
}

}  // namespace sandpatch
