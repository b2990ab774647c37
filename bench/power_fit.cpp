#include "bench/power_fit.hpp"

#include <cmath>

namespace sandpatch {

PowerFit fit_power_law(const std::vector<double>& x, const std::vector<double>& y, double lo, double hi) {
  std::vector<double> lx, ly;
  for (std::size_t i = 0; i < x.size() && i < y.size(); ++i)
    if (x[i] >= lo && x[i] <= hi && x[i] > 0 && y[i] > 0) {
      lx.push_back(std::log(x[i]));
      ly.push_back(std::log(y[i]));
    }
  PowerFit fit;
  fit.points = int(lx.size());
  if (fit.points < 2) return fit;
  const double m = double(lx.size());
  double mx = 0, my = 0;
  for (std::size_t i = 0; i < lx.size(); ++i) mx += lx[i] / m, my += ly[i] / m;
  double sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < lx.size(); ++i) sxx += (lx[i] - mx) * (lx[i] - mx), sxy += (lx[i] - mx) * (ly[i] - my);
  if (!(sxx > 0)) return PowerFit{0, 0, 0, 0, fit.points};
  fit.exponent = sxy / sxx;
  const double b0 = my - fit.exponent * mx;
  fit.prefactor = std::exp(b0);
  if (fit.points >= 3) {
    double rss = 0;
    for (std::size_t i = 0; i < lx.size(); ++i) {
      const double e = ly[i] - (b0 + fit.exponent * lx[i]);
      rss += e * e;
    }
    const double s2 = rss / (m - 2);
    fit.exponent_se = std::sqrt(s2 / sxx);
    fit.log_prefactor_se = std::sqrt(s2 * (1.0 / m + mx * mx / sxx));
  }
  return fit;
}

}  // namespace sandpatch
