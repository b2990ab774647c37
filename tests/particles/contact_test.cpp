// Contact laws (particles/contact.hpp) and the collisions they produce in a Simulation:
// head-on restitution and contact time, sliding and sticking on an incline.
#include "particles/contact.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "particles/dem.hpp"

namespace sandpatch {
namespace {

const double kR = 0.005, kRho = 2500;
double sphere_mass() { return kRho * 4.0 / 3.0 * std::numbers::pi * kR * kR * kR; }

ShellDef sphere_shell(Vec3 pos, Vec3 vel) {
  ShellDef s;
  s.offsets = {{0, 0, 0}};
  s.radii = {float(kR)};
  s.motion = MotionType::Dynamic;
  s.mass = float(sphere_mass());
  float I = float(0.4 * sphere_mass() * kR * kR);
  s.inertia = {I, I, I};
  s.position = pos;
  s.velocity = vel;
  return s;
}

}  // namespace

// Normal force is never attractive: a fast separating contact gives f_n = 0, not < 0.
TEST(ContactLaw, NeverAttractive) {
  ContactParams p{1000, 10, 300, 5, 0.5f, 2, 1e-4f, false};
  Vec3 xi{};
  ContactForce f = contact_force(p, {0, 1, 0}, 1e-4f, {0, 10, 0}, xi);  // separating at 10 m/s
  EXPECT_EQ(f.f.y, 0.0f);
  EXPECT_EQ(f.f.x, 0.0f);
  // golden value: approaching at 0.1 m/s, overlap 1e-4 m: f_n = 1000*1e-4 + 10*0.1 = 1.1 N
  xi = {};
  f = contact_force(p, {0, 1, 0}, 1e-4f, {0, -0.1f, 0}, xi);
  EXPECT_NEAR(f.f.y, 1.1f, 1e-6f);
}

// Spring law: xi grows by v_t dt while it sticks, then is capped at mu f_n (slip).
TEST(ContactLaw, SpringStickThenSlip) {
  ContactParams p{1000, 0, 300, 0, 0.5f, 0, 1e-3f, false};
  Vec3 xi{};
  // f_n = 1000 * 1e-3 = 1 N; cap 0.5 N; v_t = 0.1 m/s -> after one step xi = 1e-4, f_t = -0.03
  ContactForce f = contact_force(p, {0, 1, 0}, 1e-3f, {0.1f, 0, 0}, xi);
  EXPECT_NEAR(f.ft.x, -0.03f, 1e-6f);
  EXPECT_NEAR(xi.x, 1e-4f, 1e-9f);
  for (int k = 0; k < 100; ++k) f = contact_force(p, {0, 1, 0}, 1e-3f, {0.1f, 0, 0}, xi);
  EXPECT_NEAR(f.ft.x, -0.5f, 1e-6f);             // capped at mu f_n
  EXPECT_NEAR(xi.x, 0.5f / 300.0f, 1e-7f);       // spring holds the cap force
  // history rotates with the normal: a tilted normal keeps |xi| and removes its normal part
  Vec3 n{std::sin(0.1f), std::cos(0.1f), 0};
  float len = length(xi);
  f = contact_force(p, n, 1e-3f, {0, 0, 0}, xi);
  EXPECT_NEAR(dot(xi, n), 0.0f, 1e-7f);
  EXPECT_NEAR(length(xi), len, len * 1e-5f);
}

// Bell's law: f_t = -min(mu f_n, k_b |v_t|) v_t/|v_t|.
TEST(ContactLaw, BellVelocityCapped) {
  ContactParams p{1000, 0, 0, 0, 0.5f, 2, 1e-3f, true};
  Vec3 xi{};
  ContactForce f = contact_force(p, {0, 1, 0}, 1e-3f, {0.1f, 0, 0}, xi);  // k_b v = 0.2 < 0.5
  EXPECT_NEAR(f.ft.x, -0.2f, 1e-6f);
  f = contact_force(p, {0, 1, 0}, 1e-3f, {1.0f, 0, 0}, xi);  // capped at 0.5
  EXPECT_NEAR(f.ft.x, -0.5f, 1e-6f);
  f = contact_force(p, {0, 1, 0}, 1e-3f, {0, 0, 0}, xi);  // at rest: no shear force at all
  EXPECT_EQ(f.ft.x, 0.0f);
}

// Head-on collision of two spheres (single-sphere shells, no gravity, no friction) at
// dt = t_clamped / N. Restitution and geometric contact time are measured with linear
// interpolation of the touching instants, for 8 phases of the first touch within a step.
//   e: within 2% of the REQUESTED e (Material::restitution is the measured e: zeta is
//      chosen by inverting the clamped law, material.hpp);
//   contact time: within 2% of the clamped law's closed form (clamped_contact_time,
//      Schwager & Poeschel 2007). The textbook t_c = pi/(w0 sqrt(1 - zeta^2)) assumes a force
//      that turns attractive, so it is too long for the clamped law and undefined for
//      zeta >= 1 (e = 0.1 needs zeta = 1.243); at e = 0.9 both agree, so the measured time is
//      also asserted within 2% of it.
// Step size: the damper force jumps from 0 to c_n v0 at the first touch, and symplectic Euler
// applies a whole step of it whatever the phase of the touch, a first-order error in dt that
// grows with zeta. Worst case over the phases (docs/dem.md): e = 0.5 and 0.9 are within 2% at
// N = 50 (the dt <= t_c/50), e = 0.1 needs N ~ 500. Asserted at N = 100, 100, 1000.
struct HeadOnCase {
  double e;
  int steps_per_contact;
};
class HeadOn : public ::testing::TestWithParam<HeadOnCase> {};

TEST_P(HeadOn, RestitutionAndContactTime) {
  const double e = GetParam().e;
  const int N = GetParam().steps_per_contact;
  Material mat;
  mat.restitution = float(e);
  mat.friction = 0;
  const double meff = sphere_mass() / 2;
  const double t_clamped = clamped_contact_time(mat, meff);
  const double zeta = damping_ratio_from_restitution(e);
  const double tc_textbook = textbook_contact_time(zeta, mat.normal_stiffness, meff);
  const double dt = t_clamped / N;
  const float v0 = 0.2f;  // m/s: large enough that float positions resolve v dt at N = 1000
  double e_lo = 1e9, e_hi = -1e9, t_lo = 1e9, t_hi = -1e9;
  for (int phase = 0; phase < 8; ++phase) {
    SimulationDef def;
    def.material = mat;
    def.gravity_world = {0, 0, 0};
    def.floor_height = -1;
    def.bounds_min = {-0.05f, -0.05f, -0.05f};
    def.bounds_max = {0.05f, 0.05f, 0.05f};
    def.accuracy_steps_per_contact = 2;  // the test chooses dt; one substep per step
    def.sleep_time = 0;
    auto sim = Simulation::create(def);
    ASSERT_TRUE(sim.ok()) << sim.message();
    const float g = float(1e-4 + phase / 8.0 * v0 * dt);  // half the initial gap, m
    auto a = sim->add_shell(sphere_shell({-float(kR) - g, 0, 0}, {v0, 0, 0}));
    auto b = sim->add_shell(sphere_shell({float(kR) + g, 0, 0}, {-v0, 0, 0}));
    ASSERT_TRUE(a.ok() && b.ok());
    double t_in = -1, t_out = -1;
    double gap_prev = 2 * g;
    for (int k = 0; k < 20 * N && t_out < 0; ++k) {
      ASSERT_TRUE(sim->step(dt).ok());
      ASSERT_EQ(sim->last_step().substeps, 1);
      double gap = double(sim->body_position(*b).x - sim->body_position(*a).x) - 2 * kR;
      double t = sim->time();
      if (t_in < 0 && gap < 0) t_in = t - dt * gap / (gap - gap_prev);
      if (t_in >= 0 && gap >= 0 && gap_prev < 0) t_out = t - dt * gap / (gap - gap_prev);
      gap_prev = gap;
    }
    ASSERT_GT(t_out, 0);
    for (int k = 0; k < 5; ++k) ASSERT_TRUE(sim->step(dt).ok());
    const double v_rel = double(sim->body_velocity(*b).x - sim->body_velocity(*a).x);
    const double e_meas = v_rel / (2 * v0), t_meas = t_out - t_in;
    EXPECT_NEAR(e_meas, e, 0.02 * e) << "e = " << e << ", phase " << phase;
    EXPECT_NEAR(t_meas, t_clamped, 0.02 * t_clamped) << "e = " << e << ", phase " << phase;
    if (e >= 0.9) {
      EXPECT_NEAR(t_meas, tc_textbook, 0.02 * tc_textbook);
    }
    e_lo = std::min(e_lo, e_meas), e_hi = std::max(e_hi, e_meas);
    t_lo = std::min(t_lo, t_meas), t_hi = std::max(t_hi, t_meas);
  }
  RecordProperty("e_measured_min", std::to_string(e_lo));
  RecordProperty("e_measured_max", std::to_string(e_hi));
  const double t0 = std::sqrt(meff / mat.normal_stiffness);  // 1/w0, s
  std::printf("e %.2f, dt = t_clamped/%d: zeta %.4f (textbook %.4f); measured e %.4f..%.4f (%+.2f%%..%+.2f%%), "
              "contact %.4f..%.4f/w0 (clamped theory %.4f/w0, %+.2f%%..%+.2f%%; textbook t_c %.4f/w0)\n",
              e, N, zeta, textbook_damping_ratio(e), e_lo, e_hi, 100 * (e_lo / e - 1), 100 * (e_hi / e - 1), t_lo / t0,
              t_hi / t0, t_clamped / t0, 100 * (t_lo / t_clamped - 1), 100 * (t_hi / t_clamped - 1), tc_textbook / t0);
}

INSTANTIATE_TEST_SUITE_P(Restitutions, HeadOn,
                         ::testing::Values(HeadOnCase{0.1, 1000}, HeadOnCase{0.5, 100}, HeadOnCase{0.9, 100}),
                         [](const ::testing::TestParamInfo<HeadOnCase>& i) {
                           return "e0" + std::to_string(int(std::lround(10 * i.param.e)));
                         });

namespace {
// A rigid 3 x 3 plate of spheres (spacing 2r) resting on the floor, gravity tilted by theta
// about z (equivalent to a plane tilted by theta). Returns x(t) samples.
struct Incline {
  double a_measured = 0, drift = 0;
};
Incline run_incline(double theta_deg, ShearLaw law, double t0, double t1, bool force_rebuilds = false) {
  SimulationDef def;
  def.material.friction = 0.5f;
  def.material.shear = law;
  double th = theta_deg * std::numbers::pi / 180;
  def.gravity_world = {float(9.81 * std::sin(th)), float(-9.81 * std::cos(th)), 0};
  def.bounds_min = {-0.1f, -0.02f, -0.1f};
  def.bounds_max = {2.0f, 0.05f, 0.1f};
  def.sleep_time = 0;
  auto sim = Simulation::create(def);
  EXPECT_TRUE(sim.ok());
  ShellDef p;
  double ms = sphere_mass();
  double I = 0;
  for (int i = -1; i <= 1; ++i)
    for (int k = -1; k <= 1; ++k) {
      p.offsets.push_back({float(2 * kR * i), 0, float(2 * kR * k)});
      I += 0.4 * ms * kR * kR + ms * 4 * kR * kR * (i * i + k * k) / 2.0;
    }
  p.radii = {float(kR)};
  p.motion = MotionType::Dynamic;
  p.mass = float(9 * ms);
  p.inertia = {float(I), float(2 * I), float(I)};
  p.position = {0, float(kR), 0};
  auto id = sim->add_shell(p);
  EXPECT_TRUE(id.ok());
  if (force_rebuilds) {
    // a kinematic sphere far away moving at 2 m/s: moves > skin/2 every 10 steps, so the grid
    // and neighbour list are rebuilt again and again under the resting plate
    ShellDef k;
    k.offsets = {{0, 0, 0}};
    k.radii = {float(kR)};
    k.motion = MotionType::Kinematic;
    k.position = {1.5f, 0.03f, 0};
    k.velocity = {0, 0, 0};
    auto kid = sim->add_shell(k);
    EXPECT_TRUE(kid.ok());
    EXPECT_TRUE(sim->set_kinematic_velocity(*kid, {0, 0, 2.0f}, {}).ok());
  }
  const double dt = 5e-5;
  double x0 = 0, v0 = 0;
  int n0 = int(t0 / dt), n1 = int(t1 / dt);
  for (int k = 1; k <= n1; ++k) {
    EXPECT_TRUE(sim->step(dt).ok());
    if (k == n0) {
      x0 = sim->body_position(*id).x;
      v0 = sim->body_velocity(*id).x;
    }
  }
  Incline out;
  out.a_measured = (sim->body_velocity(*id).x - v0) / (t1 - t0);
  out.drift = sim->body_position(*id).x - x0;
  return out;
}
}  // namespace

// Above atan(mu) = 26.57 deg: at 35 deg the plate slides with a = g (sin - mu cos) within 2%.
TEST(Friction, SlidesAboveFrictionAngle) {
  Incline r = run_incline(35.0, ShearLaw::SpringHistory, 0.1, 0.4);
  double th = 35.0 * std::numbers::pi / 180;
  double a = 9.81 * (std::sin(th) - 0.5 * std::cos(th));
  EXPECT_NEAR(r.a_measured, a, 0.02 * a);
}

// Below: at 20 deg the plate stays; after 0.1 s its displacement over the next 1 s is below
// 0.001 sphere diameters (elastic deflection of the tangential springs is ~5e-4 d).
TEST(Friction, StaysBelowFrictionAngle) {
  Incline r = run_incline(20.0, ShearLaw::SpringHistory, 0.1, 1.1);
  EXPECT_LT(std::abs(r.drift), 0.001 * 2 * kR);
}

// The tangential springs survive grid/neighbour-list rebuilds (they are carried over by
// partner id): the same plate stays put while the lists are rebuilt every ~10 steps.
TEST(Friction, SpringsSurviveListRebuilds) {
  Incline r = run_incline(20.0, ShearLaw::SpringHistory, 0.1, 0.6, true);
  EXPECT_LT(std::abs(r.drift), 0.001 * 2 * kR);
}

// Bell's velocity-capped law cannot stick: at 20 deg the plate creeps at the speed where
// 9 k_b v = M g sin(theta), i.e. v = m_s g sin(theta) / k_b (within 5%).
TEST(Friction, BellLawCreepsBelowFrictionAngle) {
  Incline r = run_incline(20.0, ShearLaw::BellVelocityCapped, 0.5, 1.5);
  double v = sphere_mass() * 9.81 * std::sin(20.0 * std::numbers::pi / 180) / Material{}.bell_shear_viscosity;
  EXPECT_NEAR(r.drift / 1.0, v, 0.05 * v);
}

}  // namespace sandpatch
