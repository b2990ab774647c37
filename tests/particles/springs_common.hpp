// Contact springs carried between simulations: the beds and checks shared by the CPU's tests
// (dem_springs_test.cpp) and the GL backend's (gpu/gl_simulation_test.cpp).
#pragma once

#include <gtest/gtest.h>

#include <utility>
#include <vector>

#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "tests/particles/bed_common.hpp"

namespace sandpatch::springtest {

constexpr float kBedRadius = 0.005f;  // m: d = 1 cm spheres, the DEM's default material (bedtest::box_lattice)

// n x n x layers granules' walled box, whole-simulation sleep off.
inline SimulationDef bed_def(int n, int layers) {
  SimulationDef d;
  d.sleep_time = 0;
  d.side_walls = true;
  d.max_substeps = 1 << 16;  // frames of 1/120 s of stiff centimetre granules
  const float a = bedtest::box_spacing();
  const float L = n * a + 0.004f;
  d.particle_radius = kBedRadius;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {L, layers * a + 0.03f, L};
  d.max_bodies = n * n * layers;
  d.max_particles = 4 * n * n * layers;
  return d;
}

// The bed settled on the CPU backend for `settle` s in frames of 1/120 s.
inline Simulation settled_bed(int n, int layers, double settle) {
  auto s = Simulation::create(bed_def(n, layers));
  EXPECT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(add_lattice_bed(*s, bedtest::box_lattice(n, layers)).ok());
  for (double t = 0; t < settle; t += 1.0 / 120.0) EXPECT_TRUE(s->step(1.0 / 120.0).ok());
  return std::move(*s);
}

// The granules of `from` at the same places in `to` (a new simulation of the same definition;
// on the GL staged: set_contact_springs comes before the upload, as in a terrain patch's fill),
// with or without their springs.
template <class Sim>
void copy_bed(const Simulation& from, Sim& to, bool springs) {
  for (int b = 0; b < from.body_count(); ++b)
    ASSERT_TRUE(to.add_granule(from.body_position(BodyId{b}), from.body_orientation(BodyId{b})).ok());
  if (springs) {
    const Status st = to.set_contact_springs(from.contact_springs());
    ASSERT_TRUE(st.ok()) << st.message();
  }
}

// Mean displacement of the granules over `seconds` in frames of 1/120 s, in sphere diameters.
template <class Sim>
double mean_motion_d(Sim& s, double seconds) {
  std::vector<Vec3> start;
  for (int b = 0; b < s.body_count(); ++b) start.push_back(s.body_position(BodyId{b}));
  for (double t = 0; t < seconds; t += 1.0 / 120.0) {
    const Status st = s.step(1.0 / 120.0);
    EXPECT_TRUE(st.ok()) << st.message();
  }
  double sum = 0;
  for (int b = 0; b < s.body_count(); ++b) sum += length(s.body_position(BodyId{b}) - start[std::size_t(b)]);
  return sum / s.body_count() / (2.0 * kBedRadius);
}

// A granule slid along the floor of `s` (made from bed_def without side walls), parked,
// stepped, enabled again where it was: its floor springs before it was parked and after it is
// enabled again, before any step (a parked body's plane contacts end with it).
template <class Sim>
std::pair<int, int> floor_springs_across_parking(Sim& s) {
  const GranuleShape g = make_granule_shape(kBedRadius, 1.0f, 2500.0f);
  auto added = s.add_granule({0.05f, g.centre_distance + 0.5f * kBedRadius, 0.05f});
  EXPECT_TRUE(added.ok());
  const BodyId a = *added;
  for (int f = 0; f < 12; ++f) EXPECT_TRUE(s.step(1.0 / 120.0).ok());
  EXPECT_TRUE(s.set_body_state(a, s.body_position(a), s.body_orientation(a), {0.05f, 0, 0}, {}).ok());
  EXPECT_TRUE(s.step(1.0 / 240.0).ok());
  auto floor_springs = [&] {
    int n = 0;
    for (const ContactSpring& c : s.contact_springs()) n += c.a.index == a.index && c.plane == 0;
    return n;
  };
  const int before = floor_springs();
  const Vec3 x = s.body_position(a);
  const Quat q = s.body_orientation(a);
  EXPECT_TRUE(s.set_body_enabled(a, false).ok());
  EXPECT_TRUE(s.step(1.0 / 240.0).ok());
  EXPECT_TRUE(s.set_body_enabled(a, true).ok());
  EXPECT_TRUE(s.set_body_state(a, x, q, {}, {}).ok());
  return {before, floor_springs()};
}

}  // namespace sandpatch::springtest
