// Particle-scale mapping; the derivation is in scale.hpp.
#include "particles/scale.hpp"

#include <cmath>
#include <cstdio>
#include <string>

namespace sandpatch {

Result<ParticleScale> ParticleScale::create(double scale, std::array<double, 3> origin, double mass_ratio) {
  auto num = [](double v) {
    char b[32];
    std::snprintf(b, sizeof b, "%g", v);
    return std::string(b);
  };
  if (!(scale > 0) || !std::isfinite(scale))
    return Error{"", "particle_scale", num(scale), "must be a finite number > 0", ""};
  if (!(mass_ratio > 0) || !std::isfinite(mass_ratio))
    return Error{"", "particle_scale.mass_ratio", num(mass_ratio), "must be a finite number > 0", ""};
  for (int i = 0; i < 3; ++i)
    if (!std::isfinite(origin[i]))
      return Error{"", "particle_scale.origin[" + std::to_string(i) + "]", num(origin[i]), "must be finite", ""};
  ParticleScale p;
  p.s_ = scale;
  p.o_ = origin;
  p.mu_ = mass_ratio;
  return p;
}

std::array<double, 3> ParticleScale::position_to_world(Vec3 p) const {
  return {o_[0] + s_ * double(p.x), o_[1] + s_ * double(p.y), o_[2] + s_ * double(p.z)};
}

Vec3 ParticleScale::position_to_sim(const std::array<double, 3>& w) const {
  return {float((w[0] - o_[0]) / s_), float((w[1] - o_[1]) / s_), float((w[2] - o_[2]) / s_)};
}

}  // namespace sandpatch
