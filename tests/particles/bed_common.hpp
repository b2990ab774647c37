// Settled-bed scenario shared by bed_test.cpp (fast) and bed_heavy_test.cpp (10 s).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "particles/bed.hpp"
#include "particles/dem.hpp"

namespace sandpatch::bedtest {

// The lattice of n x n x layers granules of d = 0.01 m spheres (seed 3) in a walled box of
// side n a + 4 mm: run_bed's, the bed of the contact springs' tests (springs_common.hpp) and,
// moved 3 cm along x, the shell-list blade test's (dem_test.cpp).
inline float box_spacing() {
  const GranuleShape g = make_granule_shape(0.005f, 1.0f, 2500.0f);
  return 2.0f * (g.centre_distance + g.radius) * 1.02f;
}
inline LatticeBedDef box_lattice(int n, int layers) {
  const GranuleShape g = make_granule_shape(0.005f, 1.0f, 2500.0f);
  const float a = box_spacing();
  LatticeBedDef bed;
  bed.nx = bed.nz = n;
  bed.layers = layers;
  bed.spacing = a;
  bed.min = {0.5f * a + 0.002f, g.centre_distance + g.radius + 1e-4f, 0.5f * a + 0.002f};
  bed.seed = 3;
  return bed;
}

struct BedResult {
  double settled_speed = 0;   // max granule speed after settling, m/s
  double final_speed = 0;     // max granule speed at the end, m/s
  double drift_max = 0;       // max displacement of a surface granule over the window, m
  double drift_mean = 0;      // mean displacement of surface granules over the window, m
  int surface = 0;            // surface granules measured
};

// n x n x layers granules (d = 0.01 m spheres, peer material) in a walled box, settled for
// `settle` s, then observed for `window` s. Surface granules = centre within one granule
// size of the highest centre.
inline BedResult run_bed(ShearLaw law, int n, int layers, double settle, double window, int threads = 0) {
  SimulationDef d;
  d.material.shear = law;
  d.sleep_time = 0;
  d.threads = threads;
  d.side_walls = true;
  const float a = box_spacing();
  const float L = n * a + 0.004f;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {L, layers * a + 0.03f, L};
  d.max_bodies = n * n * layers;
  d.max_particles = 4 * n * n * layers;
  auto s = Simulation::create(d);
  EXPECT_TRUE(s.ok()) << s.message();
  EXPECT_TRUE(add_lattice_bed(*s, box_lattice(n, layers)).ok());
  const double dt = 5e-5;
  for (int k = 0; k < int(settle / dt); ++k) EXPECT_TRUE(s->step(dt).ok());
  BedResult r;
  r.settled_speed = s->max_granule_speed();
  const int nb = s->body_count();
  float top = -1e9f;
  for (int i = 0; i < nb; ++i) top = std::max(top, s->body_position(BodyId{i}).y);
  std::vector<int> surf;
  std::vector<Vec3> start;
  for (int i = 0; i < nb; ++i)
    if (s->body_position(BodyId{i}).y > top - a) {
      surf.push_back(i);
      start.push_back(s->body_position(BodyId{i}));
    }
  for (int k = 0; k < int(window / dt); ++k) EXPECT_TRUE(s->step(dt).ok());
  r.final_speed = s->max_granule_speed();
  for (std::size_t k = 0; k < surf.size(); ++k) {
    double dd = length(s->body_position(BodyId{surf[k]}) - start[k]);
    r.drift_max = std::max(r.drift_max, dd);
    r.drift_mean += dd / double(surf.size());
  }
  r.surface = int(surf.size());
  std::printf("bed %s %dx%dx%d settle %.2f s window %.2f s: speed after settling %.3g m/s, at end %.3g m/s; "
              "surface drift max %.3g d, mean %.3g d (%d granules)\n",
              "spring-history", n, n, layers, settle, window,
              r.settled_speed, r.final_speed, r.drift_max / 0.01, r.drift_mean / 0.01, r.surface);
  return r;
}

}  // namespace sandpatch::bedtest
