// A settled bed of granules stays at rest (fast variant: 4x4x4 granules, 0.6 s settle,
// 1 s window). Spring-history shear: max granule speed < 2e-3 m/s after settling and surface
// drift < 0.05 sphere diameters.
#include "bed_common.hpp"

namespace sandpatch {

TEST(Bed, SpringHistoryStaysAtRest) {
  auto r = bedtest::run_bed(ShearLaw::SpringHistory, 4, 4, 0.6, 1.0);
  EXPECT_LT(r.final_speed, 2e-3);
  EXPECT_LT(r.drift_max, 0.05 * 0.01);
}

}  // namespace sandpatch
