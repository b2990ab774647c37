// HEAVY: the impact series of docs/validation.md through the World and its TerrainManager
// (bench/impact.hpp): drop heights 0.05 ... 0.8 m and ball densities 800, 2500, 7800 kg/m^3, with
// the hysteretic normal spring (e = 0.3 from the spring, no dashpot) and, for comparison, the
// linear spring-dashpot (e = 0.3 from the dashpot), about 4 minutes on one core; and three drops
// at 8 granule diameters across the ball, about 6 minutes.
//   ctest --test-dir build -R bench_impact_heavy --output-on-failure
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "bench/impact.hpp"

namespace sandpatch {

namespace {

ImpactSeriesDef series(float unloading, float restitution) {
  ImpactSeriesDef sd;
  DropDef& d = sd.base;
  d.sphere_radius = 0.25;
  d.sphere_density = 2500;
  d.terrain_side = 2.0;
  d.patch_depth = 0.5;
  d.frame_dt = 1.0 / 240.0;
  d.stiffness = 1.5e5f;
  d.restitution = restitution;
  d.unloading_ratio = unloading;
  d.threads = 1;
  d.max_substeps = 100000;
  sd.knobs.lod = false;
  sd.knobs.granules_per_slot = 60000;
  sd.heights = {0.05, 0.1, 0.2, 0.4, 0.8};
  sd.densities = {800, 2500, 7800};
  sd.density_height = 0.2;
  return sd;
}

void print(const char* name, const ImpactSeries& r, const ImpactSeriesDef& sd) {
  const double mu = repose_mu(0.5);
  const double Db = 2 * (sd.base.sphere_radius + sd.base.granule_radius);
  std::printf("%s: bulk density %.0f kg/m^3\n", name, r.bulk_density);
  for (const auto* v : {&r.by_height, &r.by_density})
    for (const ImpactPoint& p : *v)
      std::printf("  h %.2f m rho_b %5.0f: d %.4f m (Uehara %.4f), H %.4f m, rebound %.3f, bottom after %.4f m, "
                  "t_stop v0 / d %.2f, force largest at %.2f of t_stop\n",
                  p.drop_height, p.density, p.depth, uehara_depth(mu, p.density, r.bulk_density, Db, p.drop_height),
                  p.total_drop, p.drop.rebound_ratio, p.drop.rebound_bottom, p.drop.stop_time_ratio, p.drop.peak_force_at);
  std::printf("  d ~ H^%.3f +- %.3f (prefactor %.4f), d ~ rho_b^%.3f +- %.3f, worst rebound %.3f\n",
              r.depth_vs_total_drop.exponent, r.depth_vs_total_drop.exponent_se, r.depth_vs_total_drop.prefactor,
              r.depth_vs_density.exponent, r.depth_vs_density.exponent_se, r.worst_rebound);
}

}  // namespace

// Hysteretic spring: no rebound above 5 % of the impact speed (measured at most 3.3 %);
// d ~ rho_b^c with c within 0.2 of the experiments' 1/2 (measured 0.63-0.66 over two seeds);
// d ~ H^b with b within 0.35 of 1/3 (measured 0.54-0.64: the model's depth grows faster with
// the drop than the experiments', docs/validation.md; this guards the present state, it is not
// agreement); the depths within a factor 4 of Uehara et al.'s law with this bed's bulk density
// and repose angle (measured 0.29-0.77 of it: a sanity bound).
// Linear spring-dashpot at the same restitution: the bed throws the ball back (worst rebound
// above 10 % of the impact speed), which is the defect the hysteresis removes.
TEST(ImpactHeavy, SeriesAgainstUehara) {
  const ImpactSeriesDef wb = series(1.0f / (0.3f * 0.3f), 1.0f);
  auto r = run_impact_series(wb);
  ASSERT_TRUE(r.ok()) << r.message();
  print("hysteretic (lambda 11.1, no dashpot)", *r, wb);
  EXPECT_LE(r->worst_rebound, 0.05);
  EXPECT_NEAR(r->depth_vs_total_drop.exponent, 1.0 / 3.0, 0.35);
  EXPECT_NEAR(r->depth_vs_density.exponent, 0.5, 0.2);
  const double mu = repose_mu(0.5);
  const double Db = 2 * (wb.base.sphere_radius + wb.base.granule_radius);
  for (const ImpactPoint& p : r->by_height) {
    const double u = uehara_depth(mu, p.density, r->bulk_density, Db, p.drop_height);
    EXPECT_GT(p.depth, u / 4) << p.drop_height;
    EXPECT_LT(p.depth, 4 * u) << p.drop_height;
  }

  const ImpactSeriesDef lin = series(1.0f, 0.3f);
  auto l = run_impact_series(lin);
  ASSERT_TRUE(l.ok()) << l.message();
  print("linear (dashpot e 0.3)", *l, lin);
  EXPECT_GT(l->worst_rebound, 0.1);
}

// The same ball at 8 granule diameters across (r = 1.405 cm: 23,000 granules in the bed), the
// resolution the experiments' law needs more than the 4.5 above (docs/validation.md "At 8
// granule diameters"): four drops, h = 0.1 and 0.8 m at 2500 kg/m^3 and 0.2 m at 800 and 7800
// kg/m^3. Asserted: each depth within 25 % of Uehara et al.'s law for this bed (measured 0.95,
// 1.09, 1.11 and 0.91 of it; at 4.5 diameters 0.35-0.93), no rebound above 2 % of the impact
// speed (measured at most 0.4 %), the exponent of H between the two heights within 0.15 of 1/3
// (measured 0.41; 0.54-0.71 over the three seeds at 4.5 diameters), and the light ball's
// stopping time within 35 % of Ambroso et al.'s 3 d / v0 (measured 3.04; docs/validation.md
// "Penetration dynamics"). About 11 minutes on one core.
TEST(ImpactHeavy, AtEightGranuleDiametersTheDepthsFollowUehara) {
  ImpactSeriesDef sd = series(1.0f / (0.3f * 0.3f), 1.0f);
  sd.base.granule_radius = 0.01405f;
  sd.knobs.granules_per_slot = 400000;
  sd.heights = {0.1, 0.8};
  sd.densities = {800, 7800};
  auto r = run_impact_series(sd);
  ASSERT_TRUE(r.ok()) << r.message();
  print("hysteretic at 8 granule diameters", *r, sd);
  EXPECT_LE(r->worst_rebound, 0.02);
  const double mu = repose_mu(0.5);
  const double Db = 2 * (sd.base.sphere_radius + sd.base.granule_radius);
  for (const auto* v : {&r->by_height, &r->by_density})
    for (const ImpactPoint& p : *v) {
      const double u = uehara_depth(mu, p.density, r->bulk_density, Db, p.drop_height);
      EXPECT_NEAR(p.depth / u, 1.0, 0.25) << "h " << p.drop_height << " rho_b " << p.density;
    }
  ASSERT_EQ(r->by_height.size(), 2u);
  const ImpactPoint &a = r->by_height[0], &b = r->by_height[1];
  const double exponent = std::log(b.depth / a.depth) / std::log(b.total_drop / a.total_drop);
  std::printf("  d ~ H^%.3f between h = 0.1 and 0.8 m\n", exponent);
  EXPECT_NEAR(exponent, 1.0 / 3.0, 0.15);
  // The light ball (800 kg/m^3, a wooden sphere's density) stops after about 3 d / v0, as
  // Ambroso et al.'s wooden spheres in glass beads (Phys. Rev. E 72, 041305 (2005)).
  ASSERT_EQ(r->by_density.size(), 2u);
  EXPECT_NEAR(r->by_density[0].drop.stop_time_ratio, 3.0, 0.35 * 3.0);
}

}  // namespace sandpatch
