// Granule DEM, CPU backend: the stability guard (contact time, largest substep), the overlap
// guard and the contact timing correction (velocity predictor gain, first-substep dashpot;
// docs/dem.md "Step size"). dem_impl.hpp.
#include "particles/dem_impl.hpp"

#include <algorithm>
#include <numbers>
#include <string>

namespace sandpatch {

// ---- guard
double Simulation::Impl::guard_meff() const {
  double mp = std::min(min_point_mass,
                       point_effective_mass(shape.mass, shape.inertia, shape.centre_distance));
  return 0.5 * mp;
}

double Simulation::Impl::contact_time_() const {
  double m = guard_meff();
  double c = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) * body_pair_meff());
  double rad = def.material.normal_stiffness / m - (c / (2 * m)) * (c / (2 * m));
  return rad > 0 ? std::numbers::pi / std::sqrt(rad) : std::numbers::pi * std::sqrt(m / def.material.normal_stiffness);
}

// Lightest dynamic point mass (kg): granules' and dynamic shells'.
double Simulation::Impl::lightest_point_mass() const {
  return std::min(min_point_mass, point_effective_mass(shape.mass, shape.inertia, shape.centre_distance));
}

double Simulation::Impl::max_impact_speed(double m_pt) const {
  const double f = def.max_overlap_fraction;
  if (!(f > 0)) return std::numeric_limits<double>::infinity();
  if (!(m_pt > 0)) m_pt = lightest_point_mass();
  return f * def.particle_radius * std::sqrt(double(def.material.normal_stiffness) / m_pt);
}

Simulation::Impl::ImpactCheck Simulation::Impl::impact_of(int i, double kn, double m_light) const {
  ImpactCheck c;
  c.speed = length(ld3(b.vel, i)) + length(ld3(b.omega, i)) * guard_arm[i];
  c.m = (b.flags[i] & kBodyDynamic) ? double(guard_pt_mass[i]) : m_light;
  c.r = std::min(double(guard_rmin[i]), double(def.particle_radius));
  c.overlap = c.speed * std::sqrt(c.m / kn);
  return c;
}

// The overlap guard before a step: every moving body's speed against the immovable case.
// The scan is parallel (it ran on one thread and was ~5 % of a two-thread step of a
// 64,000-sphere bed); the error names the lowest body index that fails, as a serial scan would.
Status Simulation::Impl::check_impacts() const {
  const double f = def.max_overlap_fraction;
  if (!(f > 0)) return Ok{};
  const double kn = def.material.normal_stiffness, m_light = lightest_point_mass();
  int first_bad = nb;
#pragma omp parallel for num_threads(threads) schedule(static) reduction(min : first_bad) if (nb > kParallelSpheres / 2)
  for (int i = 0; i < nb; ++i) {
    if (b.flags[i] & kBodyStatic) continue;
    const ImpactCheck c = impact_of(i, kn, m_light);
    if (c.overlap > f * c.r) first_bad = std::min(first_bad, i);
  }
  if (first_bad == nb) return Ok{};
  const int i = first_bad;
  const ImpactCheck c = impact_of(i, kn, m_light);
  const double speed = c.speed, m = c.m, r = c.r, overlap = c.overlap;
  const double k_needed = kn * (overlap / (f * r)) * (overlap / (f * r));
  return Error{"", "step.body[" + std::to_string(i) + "].speed", format_number(speed) + " m/s",
               "must be <= " + format_number(f * r * std::sqrt(kn / m)) +
                   " m/s: hitting something immovable it would overlap by speed sqrt(m_pt/k_n) = " +
                   format_number(overlap) + " m > max_overlap_fraction x r = " + format_number(f * r) +
                   " m and could pass through (m_pt = " + format_number(m) + " kg, k_n = " + format_number(kn) +
                   " N/m)",
               "raise SimulationDef.material.normal_stiffness to >= " + format_number(k_needed) +
                   " N/m (and max_substeps), slow the body, or set max_overlap_fraction = 0 to accept it"};
}

// Gain p of the velocity predictor (`bodies`: the spheres get v + p (v - v_old)) for a
// substep dt: 1/2 (v at the contact stage's time) while the dashpot's damping per substep,
// h = c_n dt / m_eff = 2 zeta w0 dt of a granule pair, is at most 0.2, falling linearly to 0
// at h = 0.25. Extrapolating the velocity with the last acceleration (which holds the damping
// forces) shrinks the explicit damper's stability region: for one contact the predicted
// dashpot needs h < 1 instead of 2, less for the stiffer, more damped modes of a body caged
// by several contacts. Measured (5x5x5 granule bed, 0.8-1.6 s after the drop): with p = 1/2
// at e = 0.1 (h = 0.14) it settled like the plain step; at e = 0.01 (h = 0.27) and e = 0.02
// (h = 0.37) it kept moving at 0.008-0.15 m/s (also with p = 0.46 and 0.26) against
// 0.001-0.008 m/s with p = 0. The head-on case (e = 0.1, dt = t_contact/50) has
// h = 0.11 (0.15 against the floor). docs/dem.md "Step size".
bool Simulation::Impl::timing_on(double /*dt*/) const {
  switch (def.contact_timing) {
    case SimulationDef::ContactTiming::On: return true;
    case SimulationDef::ContactTiming::Off: return false;
    default: return def.accuracy_steps_per_contact >= 50;  // the guard keeps dt <= t_c/50
  }
}

double Simulation::Impl::predictor_gain(double dt) const {
  if (!timing_on(dt)) return 0.0;
  const double hd = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) / body_pair_meff()) * dt;
  return hd <= 0.2 ? 0.5 : (hd >= 0.25 ? 0.0 : 0.5 * (0.25 - hd) / 0.05);
}

double Simulation::Impl::max_dt() const {
  double m = guard_meff();
  double tc = std::min(contact_time_(), std::numbers::pi * std::sqrt(m / def.material.normal_stiffness));
  double dt = tc / def.accuracy_steps_per_contact;
  double c = 2.0 * zeta * std::sqrt(double(def.material.normal_stiffness) * body_pair_meff());
  if (c > 0) dt = std::min(dt, m / c);  // explicit damper: dt < 2 m/c, with a factor 2 margin
  return dt;
}

}  // namespace sandpatch
