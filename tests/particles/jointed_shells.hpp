// Collision groups through a simulation backend (the CPU Simulation, tests/particles/
// dem_test.cpp; the GL backend, tests/particles/gpu/gl_simulation_test.cpp): the spheres of
// two shells of one group > 0 do not touch (physics_common.glsl spheres_interact), granules
// still touch both.
//
// Two single-sphere dynamic shells A and B, r = d.particle_radius, centres 1.5 r apart along
// x (overlap delta = 0.5 r), no gravity, at rest, one substep per step. In a contact's first
// substep at rest (v = 0) the law gives f_n = k_n delta and no tangential force, so A feels
// -k_n delta along x from B, or exactly nothing when they share a group.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>

#include "particles/dem.hpp"

namespace sandpatch::testutil {

inline ShellDef group_sphere(const SimulationDef& d, Vec3 pos, std::int32_t group) {
  const float r = d.particle_radius;
  const float m = d.material.density * 4.0f / 3.0f * 3.14159265f * r * r * r;
  ShellDef s;
  s.offsets = {{0, 0, 0}};
  s.radii = {r};
  s.motion = MotionType::Dynamic;
  s.mass = m;
  s.inertia = {0.4f * m * r * r, 0.4f * m * r * r, 0.4f * m * r * r};
  s.position = pos;
  s.group = group;
  return s;
}

// The test box: 12 cm x 20 cm x 12 cm, no gravity, no sleep, A at its middle.
inline SimulationDef group_box() {
  SimulationDef d;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {0.12f, 0.2f, 0.12f};
  d.gravity_world = {0, 0, 0};
  d.sleep_time = 0;
  d.max_overlap_fraction = 0;  // (the GL backend has no guard; the CPU runs the same scene)
  return d;
}
inline Vec3 group_a(const SimulationDef&) { return {0.06f, 0.1f, 0.06f}; }
inline Vec3 group_b(const SimulationDef& d) { return group_a(d) + Vec3{1.5f * d.particle_radius, 0, 0}; }
// A granule below A and B, its centre 2.2 r under their midpoint: a sphere of it reaches each.
inline Vec3 group_granule(const SimulationDef& d) {
  return group_a(d) + Vec3{0.75f * d.particle_radius, -2.2f * d.particle_radius, 0};
}

// Runs the checks on a backend made by make() (a fresh simulation of group_box() each time);
// step(sim) advances it by one substep.
template <class Make, class Step>
void check_collision_groups(Make&& make, Step&& step) {
  const SimulationDef d = group_box();
  const float r = d.particle_radius;
  const double expect = double(d.material.normal_stiffness) * 0.5 * double(r);  // N, k_n delta
  // A's force after one substep, A and B in groups ga, gb (and a granule under both)
  auto force_on_a = [&](std::int32_t ga, std::int32_t gb, bool with_b, bool granule, Vec3* on_granule = nullptr) {
    auto s = make(d);
    EXPECT_TRUE(s.add_shell(group_sphere(d, group_a(d), ga)).ok());
    if (with_b) {
      EXPECT_TRUE(s.add_shell(group_sphere(d, group_b(d), gb)).ok());
    }
    if (granule) {
      EXPECT_TRUE(s.add_granule(group_granule(d)).ok());
    }
    step(s);
    if (on_granule) *on_granule = s.body_force({with_b ? 2 : 1});
    return s.body_force({0});
  };
  // no group, different groups, one in a group: A is pushed away from B by k_n delta
  for (auto [ga, gb] : {std::pair{0, 0}, std::pair{7, 8}, std::pair{7, 0}, std::pair{0, 7}}) {
    const Vec3 f = force_on_a(ga, gb, true, false);
    EXPECT_NEAR(f.x, -expect, 1e-4 * expect) << "groups " << ga << ", " << gb;
    EXPECT_EQ(f.y, 0.0f);
    EXPECT_EQ(f.z, 0.0f);
  }
  // one group: nothing at all
  {
    const Vec3 f = force_on_a(7, 7, true, false);
    EXPECT_EQ(f.x, 0.0f);
    EXPECT_EQ(f.y, 0.0f);
    EXPECT_EQ(f.z, 0.0f);
  }
  // a granule touching both: A feels the granule alone, as if B were not there
  {
    Vec3 g_with{}, g_alone{};
    const Vec3 with = force_on_a(7, 7, true, true, &g_with);
    const Vec3 alone = force_on_a(7, 7, false, true, &g_alone);
    EXPECT_GT(std::abs(with.y), 0.0f) << "the granule must touch A";
    EXPECT_EQ(with.x, alone.x);
    EXPECT_EQ(with.y, alone.y);
    EXPECT_EQ(with.z, alone.z);
    // the granule touches B too: its force differs from the one with A alone
    EXPECT_GT(std::abs(g_with.y - g_alone.y), 1e-3f * std::abs(g_alone.y)) << "the granule must touch B";
  }
  // the group changed between steps: the next substep follows it
  {
    auto s = make(d);
    auto a = s.add_shell(group_sphere(d, group_a(d), 0));
    auto b = s.add_shell(group_sphere(d, group_b(d), 0));
    ASSERT_TRUE(a.ok() && b.ok());
    step(s);
    EXPECT_LT(s.body_force(*a).x, 0.0f);
    ASSERT_TRUE(s.set_body_group(*a, 3).ok() && s.set_body_group(*b, 3).ok());
    EXPECT_EQ(s.body_group(*b), 3);
    step(s);
    EXPECT_EQ(s.body_force(*a).x, 0.0f);
    ASSERT_TRUE(s.set_body_group(*b, 0).ok());
    step(s);
    EXPECT_LT(s.body_force(*a).x, 0.0f);
    // errors name the field
    const Status neg = s.set_body_group(*a, -1);
    ASSERT_FALSE(neg.ok());
    EXPECT_NE(neg.message().find("set_body_group.group"), std::string::npos) << neg.message();
    auto g = s.add_granule({0.02f, 0.1f, 0.02f});
    ASSERT_TRUE(g.ok());
    const Status gran = s.set_body_group(*g, 1);
    ASSERT_FALSE(gran.ok());
    EXPECT_NE(gran.message().find("granule"), std::string::npos) << gran.message();
    ShellDef bad = group_sphere(d, {0.02f, 0.05f, 0.02f}, -2);
    auto refused = s.add_shell(bad);
    ASSERT_FALSE(refused.ok());
    EXPECT_NE(refused.message().find("ShellDef.group"), std::string::npos) << refused.message();
  }
}

}  // namespace sandpatch::testutil
