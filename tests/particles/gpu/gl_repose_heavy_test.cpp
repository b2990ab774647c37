// Angle of repose of the GL DEM against the CPU backend (issue 4 statistics). HEAVY: three
// 1.2 s simulations of 96 granules, about 20 s on llvmpipe.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "particles/dem.hpp"
#include "particles/pile.hpp"
#include "particles/gpu/gl_simulation.hpp"
#include "tests/particles/gpu/gl_test_util.hpp"

namespace sandpatch::gpu {
namespace {

using namespace testutil;

// Angle of repose, GL vs CPU (issue 4 statistics): a column of 96 granules between walls
// 2 granules apart (quasi-2D) collapses against the wall x = 0 and comes to rest. The flank
// angle is the slope of a least-squares line through the surface heights (the highest sphere
// top in 1 cm columns) where the surface lies between 20 % and 80 % of its peak (fit_flank
// with outer_run = false, particles/pile.hpp). Asserted
// within 2 degrees of the CPU; a CPU run one ulp away is printed as the chaotic spread.
TEST(GlSimulation, AngleOfReposeMatchesCpu) {
  auto ctx = context();
  ASSERT_TRUE(ctx);
  SimulationDef d = box_def(ShearLaw::SpringHistory);
  d.bounds_max = {0.25f, 0.3f, 0.046f};
  auto cpu = Simulation::create(d);
  auto cpu2 = Simulation::create(d);
  auto gpu = GlSimulation::create(d);
  ASSERT_TRUE(cpu.ok() && cpu2.ok() && gpu.ok()) << gpu.message();
  auto column = [&](auto& sim, bool nudge) {
    std::uint64_t seed = 3;
    const float a = 0.0228f;
    for (int l = 0; l < 12; ++l)
      for (int k = 0; k < 2; ++k)
        for (int i = 0; i < 4; ++i) {
          Vec3 x{0.0118f + i * a, 0.0118f + l * a, 0.0116f + k * a};
          if (nudge) x.x = std::nextafter(x.x, 1.0f);
          ASSERT_TRUE(sim.add_granule(x, random_quat(seed)).ok());
        }
  };
  column(*cpu, false);
  column(*cpu2, true);
  column(*gpu, false);
  for (int f = 0; f < 1200; ++f) {
    ASSERT_TRUE(cpu->step(1e-3).ok());
    ASSERT_TRUE(cpu2->step(1e-3).ok());
    auto st = gpu->step(1e-3);
    ASSERT_TRUE(st.ok()) << st.message();
  }
  // the reusable flank fit (particles/pile.hpp): 1 cm columns along x, one sector, every
  // column between 20 % and 80 % of the peak
  auto angle = [&](const std::vector<Vec3>& p) {
    std::vector<SurfacePoint> pts;
    for (const Vec3& x : p) pts.push_back({std::clamp(double(x.x), 0.0, 0.2499), double(x.y + d.particle_radius), 0});
    return fit_flank(pts, FlankFitDef{0.01, 1, 0.2, 0.8, false}).angle_deg;
  };
  const double ac = angle(cpu->particle_positions()), a2 = angle(cpu2->particle_positions()),
               ag = angle(gpu->particle_positions());
  std::printf("angle of repose: cpu %.2f deg, gl %.2f deg (%+.2f), cpu one ulp away %.2f deg (%+.2f); max speed "
              "cpu %.4f gl %.4f m/s\n",
              ac, ag, ag - ac, a2, a2 - ac, cpu->max_granule_speed(), gpu->max_granule_speed());
  EXPECT_GT(ac, 10.0);
  EXPECT_LT(cpu->max_granule_speed(), 0.01);
  EXPECT_LT(gpu->max_granule_speed(), 0.01);
  EXPECT_NEAR(ag, ac, 2.0);
}

}  // namespace
}  // namespace sandpatch::gpu
