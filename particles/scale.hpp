// Particle scale (Leach & Marais §4.3): a simulation always runs at unit scale; the outside
// world sees it scaled by `scale` about the patch origin.
//
// Mapping (s = scale, O = patch origin in world coordinates, double; time is not scaled):
//   world position      x_w = O + s x_sim           sizes      r_w = s r_sim
//   world velocity      v_w = s v_sim               (a length per unscaled second)
//   gravity into sim    g_sim = g_w / s             (a falling body covers the same world distance)
//   body velocity in    v_sim = v_w / s,  angular velocity unchanged (angles are not scaled)
//   forces out          F_w = mu_m s F_sim          torques out  T_w = mu_m s^2 T_sim
// where mu_m = m_w / m_sim is the mass ratio of a body outside vs. inside the sim (1 when the
// body enters with its own mass, the default). Derivation: the world body must get the world
// acceleration a_w = s a_sim = s F_sim / m_sim, so F_w = m_w a_w = mu_m s F_sim; angular
// acceleration is unscaled and inertia scales as m L^2, I_w = mu_m s^2 I_sim, so
// T_w = I_w alpha = mu_m s^2 T_sim.
#pragma once

#include <array>

#include "common/error.hpp"
#include "particles/math.hpp"

namespace sandpatch {

class ParticleScale {
 public:
  // scale > 0 and finite; mass_ratio > 0 and finite (checked by create()).
  static Result<ParticleScale> create(double scale, std::array<double, 3> origin = {0, 0, 0},
                                      double mass_ratio = 1.0);
  ParticleScale() = default;

  double scale() const { return s_; }
  const std::array<double, 3>& origin() const { return o_; }
  double mass_ratio() const { return mu_; }

  std::array<double, 3> position_to_world(Vec3 p_sim) const;
  Vec3 position_to_sim(const std::array<double, 3>& p_world) const;
  double length_to_world(double l_sim) const { return s_ * l_sim; }
  double length_to_sim(double l_world) const { return l_world / s_; }
  Vec3 velocity_to_world(Vec3 v_sim) const { return v_sim * float(s_); }
  Vec3 velocity_to_sim(Vec3 v_world) const { return v_world * float(1.0 / s_); }
  Vec3 gravity_to_sim(Vec3 g_world) const { return g_world * float(1.0 / s_); }
  Vec3 force_to_world(Vec3 f_sim) const { return f_sim * float(mu_ * s_); }
  Vec3 torque_to_world(Vec3 t_sim) const { return t_sim * float(mu_ * s_ * s_); }

 private:
  double s_ = 1.0;
  std::array<double, 3> o_{0, 0, 0};
  double mu_ = 1.0;
};

}  // namespace sandpatch
