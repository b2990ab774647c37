// Angle of repose (particles/pile.hpp): the flank fit on synthetic surfaces, and one poured
// pile at mu = 0.5 (the fast CI variant; pile_heavy_test.cpp has the seeds and the mu sweep).
#include "particles/pile.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numbers>

namespace sandpatch {

// A cone of 30 degrees (height 0.1 m at the axis) sampled on a polar grid in 8 sectors, with
// a flat one-granule carpet (0.015 m) beyond its toe: the fit finds 30 degrees within 0.3
// (the bins average the surface over 1 cm) and leaves out the top and the carpet.
TEST(FlankFit, ConeOfKnownAngle) {
  const double tan30 = std::tan(30.0 * std::numbers::pi / 180), H = 0.1;
  std::vector<SurfacePoint> pts;
  for (int i = 0; i < 400; ++i)
    for (int k = 0; k < 64; ++k) {
      const double s = 0.0005 * i, phi = 2 * std::numbers::pi * (k + 0.5) / 64;
      const double h = std::max(H - s * tan30, 0.015);
      pts.push_back({s, h, int(phi / (2 * std::numbers::pi) * 8)});
    }
  FlankFit f = fit_flank(pts, FlankFitDef{0.01, 8, 0.3, 0.8});
  EXPECT_NEAR(f.angle_deg, 30.0, 0.3);
  EXPECT_NEAR(f.peak, H, 0.001);
  // flank bins: 0.03 < h < 0.08 -> s in (0.035, 0.121): 8 or 9 bins of 1 cm
  EXPECT_GE(f.points, 8);
  EXPECT_LE(f.points, 9);
  EXPECT_LT(f.residual, 1e-3);
  // with the carpet counted as flank (toe level below it) the slope is wrong: the toe
  // exclusion matters
  FlankFit g = fit_flank(pts, FlankFitDef{0.01, 8, 0.1, 0.8});
  EXPECT_LT(g.angle_deg, 25.0);
}

// Sphere centres on a 30 degree cone (height 0.1 m, apex off the disc centre at (13, -20) mm),
// on a jittered 5 mm grid, with spheres below the surface (the pile's inside) and a flat
// one-granule carpet (0.012 m) beyond the toe: the cone fit (area-equivalent radius, no axis)
// finds 30 degrees within 0.3 (30.05); with its lowest level in the carpet (10 % of H) the
// carpet's area counts as cone and the angle is off by more than 1 degree (28.2).
TEST(ConeFit, SphereConeOfKnownAngle) {
  const double tan30 = std::tan(30.0 * std::numbers::pi / 180), H = 0.1, x0 = 0.013, z0 = -0.02;
  std::vector<Vec3> pts;
  std::uint64_t seed = 7;
  auto jit = [&] {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return (double(seed >> 11) / 9007199254740992.0 - 0.5) * 0.002;
  };
  for (int i = -38; i <= 38; ++i)
    for (int k = -38; k <= 38; ++k) {
      const double x = 0.005 * i + jit(), z = 0.005 * k + jit();
      const double s = std::hypot(x - x0, z - z0);
      const double h = std::max(H - s * tan30, 0.012);
      pts.push_back({float(x), float(h), float(z)});
      pts.push_back({float(x), float(0.5 * h), float(z)});  // inside: below the surface
    }
  const ConeFit f = fit_cone_area(pts, 0.19, ConeFitDef{});
  std::printf("cone fit of a 30 deg sphere cone: %.3f deg, residual %.2g m, height %.4f m, %d levels\n", f.angle_deg,
              f.residual, f.height, f.levels);
  EXPECT_NEAR(f.angle_deg, 30.0, 0.3);
  EXPECT_NEAR(f.height, H, 0.002);
  EXPECT_EQ(f.levels, 31);
  EXPECT_LT(f.residual, 1e-3);
  ConeFitDef low;
  low.lo_frac = 0.1;
  EXPECT_LT(fit_cone_area(pts, 0.19, low).angle_deg, 29.0);
}

// A poured pile of 400 granules (peer material: k_n = 3292 N/m, e = 0.3, r = 5 mm) at
// mu = 0.5 on a rough floor: at rest, and its angle (the cone fit) lies in the band
// 25-40 degrees (seed 1: 31.7 degrees, the flank fit 22.3; no extra tolerance). Piles this
// small scatter from seed to seed by about 2.4 degrees (sd of the cone fit over seeds 1-6; the
// flank fit's 3.2), docs/dem.md "Angle of repose".
TEST(Pile, ReposeAngleAtMu05) {
  PileDef d;
  d.material.friction = 0.5f;
  d.seed = 1;
  d.threads = 1;
  auto r = measure_repose(d);
  ASSERT_TRUE(r.ok()) << r.message();
  std::printf("pile: %d granules, mu 0.5, seed 1: angle %.2f deg (cone fit residual %.2g m over %d levels; flank fit "
              "%.2f deg over %d bins), height %.3f m, %.2f s simulated in %.1f s wall, final max speed %.2g m/s\n",
              r->granules, r->angle_deg, r->residual, r->fit_points, r->flank_angle_deg, r->flank_points, r->peak,
              r->sim_seconds, r->wall_seconds, r->final_speed);
  EXPECT_TRUE(r->at_rest) << r->final_speed;
  EXPECT_EQ(r->fit_points, PileDef{}.cone.levels);
  EXPECT_LT(r->residual, 0.005);  // half a sphere diameter: the cone's r(z) is a line
  EXPECT_GE(r->angle_deg, 25.0);
  EXPECT_LE(r->angle_deg, 40.0);
}

// The same pile with the hysteretic normal spring and a weak dashpot (lambda = 11.1,
// restitution 0.9: the law docs/calibration.md recommends for impacts, e about 0.9/sqrt(lambda)):
// at rest, in the same 25-40 degree band, and within 2 seed standard deviations (2 x 2.4
// degrees) of the linear spring-dashpot's pile of the same seed. Measured, seeds 1-4: 32.7,
// 32.7, 32.3, 33.3 degrees against the linear law's 34.5, 34.4, 35.2, 36.5 (the hysteretic
// spring alone, restitution 1: 29.5, 29.5, 30.8, 28.7, its beds never quite at rest;
// docs/dem.md "Which normal law is the default").
TEST(Pile, HystereticSpringKeepsTheAngleAtMu05) {
  double angle[2] = {0, 0};
  for (int law = 0; law < 2; ++law) {
    PileDef d;
    d.material.friction = 0.5f;
    if (law == 1) {
      d.material.restitution = 0.9f;
      d.material.unloading_stiffness_ratio = 11.111111f;
    }
    d.seed = 1;
    d.threads = 1;
    auto r = measure_repose(d);
    ASSERT_TRUE(r.ok()) << r.message();
    std::printf("pile, %s: angle %.2f deg (cone fit residual %.2g m; flank fit %.2f deg), height %.3f m, %.2f s "
                "simulated in %.1f s wall, at rest %d\n",
                law ? "hysteretic lambda 11.1, restitution 0.9" : "linear e 0.3", r->angle_deg, r->residual,
                r->flank_angle_deg, r->peak, r->sim_seconds, r->wall_seconds, int(r->at_rest));
    EXPECT_TRUE(r->at_rest) << r->final_speed;
    EXPECT_GE(r->angle_deg, 25.0);
    EXPECT_LE(r->angle_deg, 40.0);
    angle[law] = r->angle_deg;
  }
  EXPECT_NEAR(angle[1], angle[0], 2 * 2.4);
}

// Bad definitions are refused naming the field.
TEST(Pile, BadDefinitionNamesField) {
  PileDef d;
  d.batch = 5;
  auto r = measure_repose(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "PileDef.batch");
  d = PileDef{};
  d.material.friction = -1;
  r = measure_repose(d);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.error().field, "SimulationDef.material.friction");
}

}  // namespace sandpatch
