// The soil laws, their fits and the rigid-wheel model of bench/terra.hpp (no simulation here).
#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>
#include <vector>

#include "bench/terra.hpp"

namespace sandpatch::terra {

namespace {

Error fit_error(const std::string& field, const std::string& value, const std::string& allowed) {
  return Error{"", field, value, allowed, ""};
}

// Solves the symmetric positive definite system A x = b (n <= 8) by Gauss-Jordan; returns the
// inverse in `inv`. False when singular.
bool invert(std::vector<std::vector<double>> a, std::vector<std::vector<double>>* inv) {
  const std::size_t n = a.size();
  std::vector<std::vector<double>> m(n, std::vector<double>(n, 0.0));
  for (std::size_t i = 0; i < n; ++i) m[i][i] = 1.0;
  for (std::size_t c = 0; c < n; ++c) {
    std::size_t piv = c;
    for (std::size_t r = c + 1; r < n; ++r)
      if (std::abs(a[r][c]) > std::abs(a[piv][c])) piv = r;
    if (!(std::abs(a[piv][c]) > 1e-300)) return false;
    std::swap(a[c], a[piv]);
    std::swap(m[c], m[piv]);
    const double d = a[c][c];
    for (std::size_t k = 0; k < n; ++k) {
      a[c][k] /= d;
      m[c][k] /= d;
    }
    for (std::size_t r = 0; r < n; ++r) {
      if (r == c) continue;
      const double f = a[r][c];
      for (std::size_t k = 0; k < n; ++k) {
        a[r][k] -= f * a[c][k];
        m[r][k] -= f * m[c][k];
      }
    }
  }
  *inv = m;
  return true;
}

// Sum of squares of tau/tau_max - (1 - exp(-j/K)) over the curves' points.
double shear_sse(const std::vector<ShearCurve>& cs, double K) {
  double s = 0;
  for (const ShearCurve& c : cs) {
    if (!(c.tau_max > 0)) continue;
    for (std::size_t i = 0; i < c.j.size(); ++i) {
      if (c.j[i] < 0) continue;
      const double e = c.tau[i] / c.tau_max - (1.0 - std::exp(-c.j[i] / K));
      s += e * e;
    }
  }
  return s;
}

// K minimising shear_sse over [1e-4, 1] m (golden section on ln K).
double fit_K(const std::vector<ShearCurve>& cs) {
  double a = std::log(1e-4), b = std::log(1.0);
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - g * (b - a), x2 = a + g * (b - a);
  double f1 = shear_sse(cs, std::exp(x1)), f2 = shear_sse(cs, std::exp(x2));
  for (int it = 0; it < 100; ++it) {
    if (f1 < f2) {
      b = x2;
      x2 = x1;
      f2 = f1;
      x1 = b - g * (b - a);
      f1 = shear_sse(cs, std::exp(x1));
    } else {
      a = x1;
      x1 = x2;
      f1 = f2;
      x2 = a + g * (b - a);
      f2 = shear_sse(cs, std::exp(x2));
    }
  }
  return std::exp(0.5 * (a + b));
}

}  // namespace

double Bekker::pressure(double b, double z) const {
  if (!(z > 0) || !(b > 0)) return 0.0;
  return (k_c / b + k_phi) * std::pow(z, n);
}

double ShearLaw::stress(double sigma, double j) const {
  if (!(j > 0)) return 0.0;
  return (c + sigma * std::tan(phi)) * (1.0 - std::exp(-j / K));
}

Result<BekkerFit> fit_bekker(const std::vector<PlateCurve>& plates, double z_lo, double z_hi) {
  const std::size_t m = plates.size();
  if (m < 2 || m > 6)
    return fit_error("plates", std::to_string(m), "2 to 6 plate widths (k_c and k_phi need two)");
  if (!(z_lo > 0 && z_hi > z_lo)) return fit_error("z_lo, z_hi", std::to_string(z_lo) + ", " + std::to_string(z_hi), "0 < z_lo < z_hi (m)");
  double bmin = 1e300, bmax = 0;
  for (const PlateCurve& c : plates) bmin = std::min(bmin, c.width), bmax = std::max(bmax, c.width);
  if (!(bmax > 1.05 * bmin))
    return fit_error("plates.width", std::to_string(bmin) + " .. " + std::to_string(bmax),
                     "two widths at least 5 % apart (k_c and k_phi are told apart by the width)");
  // Unknowns: n, ln k_1 .. ln k_m. Normal equations of ln p = n ln z + ln k_i.
  const std::size_t u = m + 1;
  std::vector<std::vector<double>> ata(u, std::vector<double>(u, 0.0));
  std::vector<double> aty(u, 0.0);
  std::vector<int> count(m, 0);
  for (std::size_t i = 0; i < m; ++i) {
    if (!(plates[i].width > 0)) return fit_error("plates[" + std::to_string(i) + "].width", std::to_string(plates[i].width), "> 0 m");
    for (std::size_t k = 0; k < plates[i].z.size() && k < plates[i].p.size(); ++k) {
      const double z = plates[i].z[k], p = plates[i].p[k];
      if (!(z >= z_lo && z <= z_hi && p > 0 && std::isfinite(p))) continue;
      const double lz = std::log(z), lp = std::log(p);
      ata[0][0] += lz * lz;
      ata[0][1 + i] += lz;
      ata[1 + i][0] += lz;
      ata[1 + i][1 + i] += 1;
      aty[0] += lz * lp;
      aty[1 + i] += lp;
      ++count[i];
    }
  }
  for (std::size_t i = 0; i < m; ++i)
    if (count[i] < 3)
      return fit_error("plates[" + std::to_string(i) + "]", std::to_string(count[i]) + " points",
                       "at least 3 points with z in [z_lo, z_hi] and p > 0");
  std::vector<std::vector<double>> inv;
  if (!invert(ata, &inv)) return fit_error("plates", "singular", "sinkages that vary within the window");
  std::vector<double> x(u, 0.0);
  for (std::size_t r = 0; r < u; ++r)
    for (std::size_t c = 0; c < u; ++c) x[r] += inv[r][c] * aty[c];
  // residuals
  double ss = 0;
  int npts = 0;
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t k = 0; k < plates[i].z.size() && k < plates[i].p.size(); ++k) {
      const double z = plates[i].z[k], p = plates[i].p[k];
      if (!(z >= z_lo && z <= z_hi && p > 0 && std::isfinite(p))) continue;
      const double e = std::log(p) - (x[0] * std::log(z) + x[1 + i]);
      ss += e * e;
      ++npts;
    }
  const double dof = std::max(1, npts - int(u));
  const double s2 = ss / dof;
  BekkerFit f;
  f.points = npts;
  f.rms_log = std::sqrt(ss / std::max(1, npts));
  f.soil.n = x[0];
  f.n_se = std::sqrt(s2 * inv[0][0]);
  // k_i = exp(a_i); cov(k_i, k_j) = k_i k_j cov(a_i, a_j)
  std::vector<double> k(m), w(m);
  for (std::size_t i = 0; i < m; ++i) {
    k[i] = std::exp(x[1 + i]);
    f.widths.push_back(plates[i].width);
    f.k.push_back(k[i]);
    f.k_se.push_back(k[i] * std::sqrt(s2 * inv[1 + i][1 + i]));
  }
  for (std::size_t i = 0; i < m; ++i) {
    double sx = 0, sy = 0, sxx = 0, sxy = 0, syy = 0;
    int q = 0;
    for (std::size_t k2 = 0; k2 < plates[i].z.size() && k2 < plates[i].p.size(); ++k2) {
      const double z = plates[i].z[k2], p = plates[i].p[k2];
      if (!(z >= z_lo && z <= z_hi && p > 0 && std::isfinite(p))) continue;
      const double lz = std::log(z), lp = std::log(p);
      sx += lz, sy += lp, sxx += lz * lz, sxy += lz * lp, syy += lp * lp, ++q;
    }
    const double vxx = sxx - sx * sx / q, vxy = sxy - sx * sy / q, vyy = syy - sy * sy / q;
    const double slope = vxy / vxx;
    const double res = std::max(0.0, vyy - slope * vxy);
    f.n_alone.push_back(slope);
    f.n_alone_se.push_back(q > 2 ? std::sqrt(res / (q - 2) / vxx) : 0.0);
  }
  // k_i = k_c (1/b_i) + k_phi: generalised least squares with the k covariance (exact for m = 2).
  std::vector<std::vector<double>> ck(m, std::vector<double>(m)), ckinv;
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t j = 0; j < m; ++j) ck[i][j] = k[i] * k[j] * s2 * inv[1 + i][1 + j];
  if (!invert(ck, &ckinv)) return fit_error("plates", "singular", "distinct pressures");
  std::vector<std::vector<double>> g(2, std::vector<double>(2, 0.0));
  std::vector<double> gy(2, 0.0);
  for (std::size_t i = 0; i < m; ++i)
    for (std::size_t j = 0; j < m; ++j) {
      const double xi[2] = {1.0 / plates[i].width, 1.0}, xj[2] = {1.0 / plates[j].width, 1.0};
      for (int a = 0; a < 2; ++a) {
        for (int b = 0; b < 2; ++b) g[a][b] += xi[a] * ckinv[i][j] * xj[b];
        gy[a] += xi[a] * ckinv[i][j] * k[j];
      }
    }
  std::vector<std::vector<double>> ginv;
  if (!invert(g, &ginv)) return fit_error("plates.width", "all equal", "two different plate widths");
  f.soil.k_c = ginv[0][0] * gy[0] + ginv[0][1] * gy[1];
  f.soil.k_phi = ginv[1][0] * gy[0] + ginv[1][1] * gy[1];
  f.k_c_se = std::sqrt(std::max(0.0, ginv[0][0]));
  f.k_phi_se = std::sqrt(std::max(0.0, ginv[1][1]));
  return f;
}

namespace {

// For a given K, tau = c g + tan(phi) sigma g with g = 1 - exp(-j / K) is linear in (c,
// tan phi): least squares over every point of every curve. Returns the sum of squares; x the
// two coefficients, inv the inverse of the normal matrix, n the points.
double shear_linear(const std::vector<ShearCurve>& cs, double K, double x[2], double inv[2][2], int* n) {
  double a00 = 0, a01 = 0, a11 = 0, b0 = 0, b1 = 0, yy = 0;
  *n = 0;
  for (const ShearCurve& c : cs)
    for (std::size_t i = 0; i < c.j.size() && i < c.tau.size(); ++i) {
      if (!(c.j[i] >= 0) || !std::isfinite(c.tau[i])) continue;
      const double g = 1.0 - std::exp(-c.j[i] / K);
      const double u = g, v = c.sigma * g, y = c.tau[i];
      a00 += u * u, a01 += u * v, a11 += v * v, b0 += u * y, b1 += v * y, yy += y * y;
      ++*n;
    }
  const double det = a00 * a11 - a01 * a01;
  if (!(std::abs(det) > 0)) {
    x[0] = x[1] = 0;
    return 1e300;
  }
  inv[0][0] = a11 / det, inv[1][1] = a00 / det, inv[0][1] = inv[1][0] = -a01 / det;
  x[0] = inv[0][0] * b0 + inv[0][1] * b1;
  x[1] = inv[1][0] * b0 + inv[1][1] * b1;
  return std::max(0.0, yy - x[0] * b0 - x[1] * b1);
}

}  // namespace

Result<ShearFit> fit_shear(std::vector<ShearCurve>& curves, double plateau_from) {
  if (curves.size() < 2) return fit_error("curves", std::to_string(curves.size()), "at least 2 normal stresses (c and phi)");
  double smin = 1e300, smax = -1e300;
  for (std::size_t i = 0; i < curves.size(); ++i) {
    ShearCurve& c = curves[i];
    smin = std::min(smin, c.sigma), smax = std::max(smax, c.sigma);
    double s = 0, s2 = 0;
    int n = 0;
    for (std::size_t k = 0; k < c.j.size() && k < c.tau.size(); ++k)
      if (c.j[k] >= plateau_from && std::isfinite(c.tau[k])) {
        s += c.tau[k];
        s2 += c.tau[k] * c.tau[k];
        ++n;
      }
    if (n < 3)
      return fit_error("curves[" + std::to_string(i) + "]", std::to_string(n) + " plateau points",
                       "at least 3 points with j >= plateau_from (drag further)");
    c.tau_max = s / n;
    c.tau_max_sd = std::sqrt(std::max(0.0, s2 / n - c.tau_max * c.tau_max));
    if (!(c.tau_max > 0)) return fit_error("curves[" + std::to_string(i) + "].tau_max", std::to_string(c.tau_max), "> 0 Pa");
    c.K = fit_K({c});
    c.tau_peak = 0;
    for (std::size_t k = 4; k + 4 < c.tau.size() && k < c.j.size(); ++k) {
      double m = 0;
      for (std::size_t q = k - 4; q <= k + 4; ++q) m += c.tau[q];
      m /= 9.0;
      if (m > c.tau_peak) c.tau_peak = m, c.j_peak = c.j[k];
    }
  }
  if (!(smax > 1.05 * smin)) return fit_error("curves.sigma", "all equal", "at least two normal stresses 5 % apart");
  // the whole curves: golden section on ln K of the linear fit's sum of squares
  double x[2], inv[2][2];
  int n = 0;
  auto sse = [&](double lk) { return shear_linear(curves, std::exp(lk), x, inv, &n); };
  double a = std::log(1e-4), b = std::log(1.0);
  const double g = 0.5 * (std::sqrt(5.0) - 1.0);
  double x1 = b - g * (b - a), x2 = a + g * (b - a), f1 = sse(x1), f2 = sse(x2);
  for (int it = 0; it < 100; ++it) {
    if (f1 < f2) {
      b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a), f1 = sse(x1);
    } else {
      a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a), f2 = sse(x2);
    }
  }
  const double lk = 0.5 * (a + b);
  const double best = sse(lk);
  if (n < 6) return fit_error("curves", std::to_string(n) + " points", "at least 6 points (j >= 0)");
  const double s2 = best / double(n - 3);
  ShearFit f;
  f.soil.K = std::exp(lk);
  f.soil.c = x[0];
  f.soil.phi = std::atan(x[1]);
  f.c_se = std::sqrt(s2 * inv[0][0]);
  f.phi_se = std::sqrt(s2 * inv[1][1]) / (1.0 + x[1] * x[1]);
  // K: where the sum of squares has risen by s2 on either side (one standard error)
  double lo = lk, hi = lk;
  for (int it = 0; it < 400 && sse(lo) - best < s2; ++it) lo -= 0.005;
  for (int it = 0; it < 400 && sse(hi) - best < s2; ++it) hi += 0.005;
  f.K_se = 0.5 * (std::exp(hi) - std::exp(lo));
  sse(lk);  // leave x at the best fit
  return f;
}

WheelModel wheel_at_entry(const Bekker& bk, const ShearLaw& sh, const WheelGeometry& g, double slip, double theta1,
                          const WongReece& wr) {
  WheelModel m;
  m.theta1 = theta1;
  const double r = g.radius, b = g.width;
  m.sinkage = r * (1.0 - std::cos(theta1));
  if (!(theta1 > 0 && theta1 < 0.5 * M_PI)) return m;
  const double thm = std::clamp((wr.c1 + wr.c2 * slip) * theta1, 1e-6 * theta1, theta1);
  const double keq = bk.k_c / b + bk.k_phi;
  const double c1 = std::cos(theta1), s1 = std::sin(theta1);
  // Simpson's rule over [0, theta1]
  const int N = 400;
  const double h = theta1 / N;
  double iw = 0, idp = 0, it = 0;
  for (int i = 0; i <= N; ++i) {
    const double th = i * h;
    const double wgt = (i == 0 || i == N) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    // the normal stress: Bekker's pressure at the sinkage under the rim, the rear part mapped
    // onto the front's profile so that it peaks at theta_m and falls to 0 at the exit
    const double arg = th >= thm ? std::cos(th) - c1 : std::cos(theta1 - th / thm * (theta1 - thm)) - c1;
    const double sigma = arg > 0 ? keq * std::pow(r * arg, bk.n) : 0.0;
    const double j = r * ((theta1 - th) - (1.0 - slip) * (s1 - std::sin(th)));
    const double tau = sh.stress(sigma, j);
    iw += wgt * (sigma * std::cos(th) + tau * std::sin(th));
    idp += wgt * (tau * std::cos(th) - sigma * std::sin(th));
    it += wgt * tau;
  }
  m.load = r * b * iw * h / 3.0;
  m.drawbar_pull = r * b * idp * h / 3.0;
  m.torque = r * r * b * it * h / 3.0;
  m.ok = true;
  return m;
}

WheelModel wheel_under_load(const Bekker& bk, const ShearLaw& sh, const WheelGeometry& g, double slip, double load,
                            const WongReece& wr) {
  double lo = 1e-4, hi = 0.5 * M_PI - 1e-4;
  WheelModel top = wheel_at_entry(bk, sh, g, slip, hi, wr);
  if (!(top.load >= load)) {
    top.ok = false;  // sinks past the axle
    return top;
  }
  for (int it = 0; it < 80; ++it) {
    const double mid = 0.5 * (lo + hi);
    if (wheel_at_entry(bk, sh, g, slip, mid, wr).load < load)
      lo = mid;
    else
      hi = mid;
  }
  return wheel_at_entry(bk, sh, g, slip, 0.5 * (lo + hi), wr);
}

}  // namespace sandpatch::terra
