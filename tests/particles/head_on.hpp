// Head-on collision through a simulation backend (the CPU Simulation, tests/particles/
// contact_test.cpp; the GL backend, tests/particles/gpu/gl_simulation_test.cpp): measured
// restitution and geometric contact time over several phases of the touch within a step.
//
// Two single-sphere dynamic shells (r = 5 mm, rho = 2500) approach along x at +-v0, or one
// sphere falls onto the floor at v0 (`floor`), no gravity, no friction, dt = t_clamped / N with
// t_clamped the clamped law's contact time (material.hpp clamped_contact_time) for the pair's
// m_eff (m/2 for two spheres, m against the floor). The touch and separation instants are
// interpolated linearly between the two steps around them (symplectic Euler moves a body in a
// straight line within a step, so this is exact for the discrete path); e = rebound speed /
// approach speed, measured 5 steps after the separation.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>

#include "particles/dem.hpp"
#include "particles/material.hpp"

namespace sandpatch::testutil {

struct HeadOnStats {
  double e_lo = 1e9, e_hi = -1e9;  // measured e, min and max over the phases
  double t_lo = 1e9, t_hi = -1e9;  // measured contact time (s), min and max over the phases
  double t_clamped = 0;            // s, the clamped law's contact time
  double t_unit = 0;               // s, 1/w0 = sqrt(m_eff / k_n)
};

inline constexpr double kHeadOnRadius = 0.005, kHeadOnDensity = 2500;
inline double head_on_sphere_mass() {
  return kHeadOnDensity * 4.0 / 3.0 * std::numbers::pi * kHeadOnRadius * kHeadOnRadius * kHeadOnRadius;
}

inline ShellDef head_on_sphere(Vec3 pos, Vec3 vel) {
  const double m = head_on_sphere_mass();
  ShellDef s;
  s.offsets = {{0, 0, 0}};
  s.radii = {float(kHeadOnRadius)};
  s.motion = MotionType::Dynamic;
  s.mass = float(m);
  const float I = float(0.4 * m * kHeadOnRadius * kHeadOnRadius);
  s.inertia = {I, I, I};
  s.position = pos;
  s.velocity = vel;
  return s;
}

// unloading: Material::unloading_stiffness_ratio (1: the linear spring).
inline SimulationDef head_on_def(double e, float unloading = 1.0f) {
  SimulationDef def;
  def.material.restitution = float(e);
  def.material.unloading_stiffness_ratio = unloading;
  def.material.friction = 0;
  def.gravity_world = {0, 0, 0};
  def.floor_height = -1;
  def.bounds_min = {-0.05f, -0.05f, -0.05f};
  def.bounds_max = {0.05f, 0.05f, 0.05f};
  def.accuracy_steps_per_contact = 2;  // the test chooses dt; one substep per step
  def.contact_timing = SimulationDef::ContactTiming::On;  // the guard (Auto) would not see the test's dt
  def.sleep_time = 0;
  def.max_bodies = 4;
  def.max_particles = 4;
  return def;
}

// create(def) returns a Result<Sim>. Fails the test (and returns what it has) on an error.
template <class Sim, class Create>
HeadOnStats head_on(Create&& create, double e, int N, int phases, bool floor, float unloading = 1.0f) {
  SimulationDef def = head_on_def(e, unloading);
  if (floor) def.floor_height = -0.02f;
  const double m = head_on_sphere_mass(), meff = floor ? m : m / 2;
  HeadOnStats out;
  out.t_clamped = clamped_contact_time(def.material, meff);
  out.t_unit = std::sqrt(meff / def.material.normal_stiffness);
  const double dt = out.t_clamped / N;
  const float v0 = 0.2f;  // m/s: large enough that float positions resolve v dt at N = 1000
  const double r = kHeadOnRadius;
  for (int phase = 0; phase < phases; ++phase) {
    auto sim = create(def);
    EXPECT_TRUE(sim.ok()) << sim.message();
    if (!sim.ok()) return out;
    const float g = float(1e-4 + double(phase) / phases * v0 * dt);  // initial gap (per body), m
    BodyId a{}, b{};
    if (floor) {
      auto ib = sim->add_shell(head_on_sphere({0, float(def.floor_height + r) + g, 0}, {0, -v0, 0}));
      EXPECT_TRUE(ib.ok());
      if (!ib.ok()) return out;
      b = *ib;
    } else {
      auto ia = sim->add_shell(head_on_sphere({-float(r) - g, 0, 0}, {v0, 0, 0}));
      auto ib = sim->add_shell(head_on_sphere({float(r) + g, 0, 0}, {-v0, 0, 0}));
      EXPECT_TRUE(ia.ok() && ib.ok());
      if (!ia.ok() || !ib.ok()) return out;
      a = *ia, b = *ib;
    }
    // gap (m) and approach-axis velocity of b relative to a (or to the floor)
    auto gap_of = [&] {
      return floor ? double(sim->body_position(b).y) - def.floor_height - r
                   : double(sim->body_position(b).x - sim->body_position(a).x) - 2 * r;
    };
    auto vel_of = [&] {
      return floor ? double(sim->body_velocity(b).y) : double(sim->body_velocity(b).x - sim->body_velocity(a).x);
    };
    double t_in = -1, t_out = -1, t = 0;
    double gap_prev = gap_of();
    for (int k = 0; k < 20 * N && t_out < 0; ++k) {
      auto st = sim->step(dt);
      EXPECT_TRUE(st.ok()) << st.message();
      if (!st.ok()) return out;
      EXPECT_EQ(sim->last_step().substeps, 1);
      t += dt;
      const double gap = gap_of();
      if (t_in < 0 && gap < 0) t_in = t - dt * gap / (gap - gap_prev);
      if (t_in >= 0 && gap >= 0 && gap_prev < 0) t_out = t - dt * gap / (gap - gap_prev);
      gap_prev = gap;
    }
    EXPECT_GT(t_out, 0) << "no separation, phase " << phase;
    for (int k = 0; k < 5; ++k) EXPECT_TRUE(sim->step(dt).ok());
    const double e_meas = vel_of() / ((floor ? 1 : 2) * double(v0)), t_meas = t_out - t_in;
    out.e_lo = std::min(out.e_lo, e_meas), out.e_hi = std::max(out.e_hi, e_meas);
    out.t_lo = std::min(out.t_lo, t_meas), out.t_hi = std::max(out.t_hi, t_meas);
  }
  return out;
}

}  // namespace sandpatch::testutil
