// A power law fitted by least squares on log-log, for the comparisons with experiments
// (bench/impact.cpp against Uehara et al., bench/bench_collapse.cpp against the collapse laws).
#pragma once

#include <vector>

namespace sandpatch {

// y = k x^n by least squares on (ln x, ln y) over the positive pairs with lo <= x <= hi: n, its
// standard error, k and the standard error of ln k (both errors 0 with fewer than 3 points;
// everything 0 with fewer than 2).
struct PowerFit {
  double exponent = 0, exponent_se = 0;
  double prefactor = 0, log_prefactor_se = 0;
  int points = 0;
};
PowerFit fit_power_law(const std::vector<double>& x, const std::vector<double>& y, double lo = 0, double hi = 1e300);

}  // namespace sandpatch
