// Procedural terrains: analytic flat / plane / hills, and fBm value noise (the classic
// lattice value-noise construction with a hashed lattice; hand-written, deterministic).
#include "heightfield/procedural.hpp"

#include <cmath>
#include <cstdio>
#include <vector>

namespace sandpatch {
namespace {

// 32-bit integer hash of a lattice point (xorshift-multiply avalanche).
std::uint32_t lattice_hash(std::uint32_t seed, std::uint32_t octave, std::int64_t ix, std::int64_t iz) {
  std::uint32_t h = seed * 0x9e3779b9u;
  h ^= octave * 0x85ebca6bu + 0x7f4a7c15u;
  h ^= static_cast<std::uint32_t>(ix) * 0xc2b2ae35u;
  h = (h ^ (h >> 15)) * 0x2c1b3c6du;
  h ^= static_cast<std::uint32_t>(iz) * 0x27d4eb2fu;
  h = (h ^ (h >> 13)) * 0x297a2d39u;
  h ^= h >> 16;
  return h;
}

// Lattice value in [-1, 1].
double lattice_value(std::uint32_t seed, int octave, std::int64_t ix, std::int64_t iz) {
  return double(lattice_hash(seed, std::uint32_t(octave), ix, iz) >> 8) / double(1u << 23) - 1.0;
}

double fade(double t) { return t * t * t * (t * (t * 6 - 15) + 10); }  // quintic, C2

double value_noise(std::uint32_t seed, int octave, double x, double z) {
  const double fx = std::floor(x), fz = std::floor(z);
  const auto ix = static_cast<std::int64_t>(fx), iz = static_cast<std::int64_t>(fz);
  const double u = fade(x - fx), v = fade(z - fz);
  const double a = lattice_value(seed, octave, ix, iz), b = lattice_value(seed, octave, ix + 1, iz);
  const double c = lattice_value(seed, octave, ix, iz + 1), d = lattice_value(seed, octave, ix + 1, iz + 1);
  return (1 - u) * (1 - v) * a + u * (1 - v) * b + (1 - u) * v * c + u * v * d;
}

double hill_wave(double s, double wavelength) {
  const double q = s / wavelength;
  const double t = std::fabs(2 * (q - std::floor(q)) - 1);  // triangle wave in [0, 1]
  return 2 * t * t * (3 - 2 * t) - 1;
}

}  // namespace

Result<Heightfield> make_procedural(const HeightfieldDef& grid, const ProceduralHeightsDef& p) {
  // ---- validate ----
  std::vector<Error> errs;
  const std::string& k = p.kind;
  if (k != "flat" && k != "plane" && k != "hills" && k != "noise")
    errs.push_back({"", "kind", "\"" + k + "\"", "must be one of flat, plane, hills, noise", ""});
  if (!std::isfinite(p.height)) errs.push_back({"", "height", format_number(p.height), "must be finite (m)", ""});
  if (!std::isfinite(p.slope_x)) errs.push_back({"", "slope_x", format_number(p.slope_x), "must be finite", ""});
  if (!std::isfinite(p.slope_z)) errs.push_back({"", "slope_z", format_number(p.slope_z), "must be finite", ""});
  if (!std::isfinite(p.amplitude) || p.amplitude < 0)
    errs.push_back({"", "amplitude", format_number(p.amplitude), "must be finite and >= 0 (m)", ""});
  if (!std::isfinite(p.wavelength) || !(p.wavelength > 0))
    errs.push_back({"", "wavelength", format_number(p.wavelength), "must be finite and > 0 (m)", ""});
  if (p.octaves < 1 || p.octaves > 16)
    errs.push_back({"", "octaves", std::to_string(p.octaves), "must be in [1, 16]", ""});
  if (!errs.empty()) return errs;

  auto created = Heightfield::create(grid);
  if (!created) return created.errors();
  Heightfield hf = std::move(created).value();

  // ---- evaluate row by row ----
  const double s = hf.spacing();
  double norm = 0;
  for (int o = 0; o < p.octaves; ++o) norm += std::ldexp(1.0, -o);
  std::vector<float> row(static_cast<std::size_t>(hf.samples_x()));
  for (int j = 0; j < hf.samples_z(); ++j) {
    const double z = j * s;
    for (int i = 0; i < hf.samples_x(); ++i) {
      const double x = i * s;
      double h = p.height;
      if (k == "plane") {
        h += double(p.slope_x) * x + double(p.slope_z) * z;
      } else if (k == "hills") {
        h += double(p.amplitude) * hill_wave(x, p.wavelength) * hill_wave(z, p.wavelength);
      } else if (k == "noise") {
        double sum = 0;
        for (int o = 0; o < p.octaves; ++o) {
          const double f = std::ldexp(1.0, o) / p.wavelength;  // lattice cells per metre
          sum += std::ldexp(1.0, -o) * value_noise(p.seed, o, x * f, z * f);
        }
        h += double(p.amplitude) * sum / norm;
      }
      row[std::size_t(i)] = static_cast<float>(h);
    }
    hf.write({0, j, hf.samples_x(), 1}, row.data());
  }
  return hf;
}

}  // namespace sandpatch
