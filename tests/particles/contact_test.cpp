// Contact laws (particles/contact.hpp) and the collisions they produce in a Simulation:
// head-on restitution and contact time, sliding and sticking on an incline.
#include "particles/contact.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "particles/dem.hpp"
#include "tests/particles/head_on.hpp"
#include "tests/particles/textbook_law.hpp"

namespace sandpatch {
namespace {

const double kR = 0.005, kRho = 2500;
double sphere_mass() { return kRho * 4.0 / 3.0 * std::numbers::pi * kR * kR * kR; }

}  // namespace

// Normal force is never attractive: a fast separating contact gives f_n = 0, not < 0.
TEST(ContactLaw, NeverAttractive) {
  ContactParams p{1000, 10, 300, 5, 0.5f, 1e-4f, false};
  Vec3 xi{};
  ContactForce f = contact_force(p, {0, 1, 0}, 1e-4f, {0, 10, 0}, xi);  // separating at 10 m/s
  EXPECT_EQ(f.f.y, 0.0f);
  EXPECT_EQ(f.f.x, 0.0f);
  // golden value: approaching at 0.1 m/s, overlap 1e-4 m: f_n = 1000*1e-4 + 10*0.1 = 1.1 N
  xi = {};
  f = contact_force(p, {0, 1, 0}, 1e-4f, {0, -0.1f, 0}, xi);
  EXPECT_NEAR(f.f.y, 1.1f, 1e-6f);
}

// First substep of a contact (new_contact): the dashpot is c_n (min(delta/dt, |v.n|) + |v.n|/2)
// with the sign of v.n, i.e. the impulse c_n (delta + |v.n| dt/2) from the touch to half a step
// past the substep's time; ongoing contacts keep c_n v.n; the force is never attractive.
TEST(ContactLaw, FirstSubstepDashpot) {
  ContactParams p{1000, 10, 300, 5, 0.5f, 1e-4f, false};
  p.new_contact = true;
  Vec3 xi{};
  // approaching at 1 m/s, delta = 2.5e-5 m < |v| dt = 1e-4 m: f_n = 1000*2.5e-5 + 10*(0.25 + 0.5) = 7.525 N
  ContactForce f = contact_force(p, {0, 1, 0}, 2.5e-5f, {0, -1.0f, 0}, xi);
  EXPECT_NEAR(f.f.y, 7.525f, 1e-5f);
  // delta = 2e-4 m > |v| dt (did not start by approach): delta/dt capped at |v|: 0.2 + 10*1.5 = 15.2 N
  xi = {};
  f = contact_force(p, {0, 1, 0}, 2e-4f, {0, -1.0f, 0}, xi);
  EXPECT_NEAR(f.f.y, 15.2f, 1e-5f);
  // separating at 1 m/s: 0.025 - 7.5 < 0, clamped to 0, never attractive
  xi = {};
  f = contact_force(p, {0, 1, 0}, 2.5e-5f, {0, 1.0f, 0}, xi);
  EXPECT_EQ(f.f.y, 0.0f);
  // an ongoing contact (flag off) keeps the plain dashpot: 0.025 + 10
  p.new_contact = false;
  xi = {};
  f = contact_force(p, {0, 1, 0}, 2.5e-5f, {0, -1.0f, 0}, xi);
  EXPECT_NEAR(f.f.y, 10.025f, 1e-5f);
}

// Spring law: xi grows by v_t dt while it sticks, then is capped at mu f_n (slip).
// Hysteretic normal spring (Walton & Braun 1986; contact_force_h): loading along k_n while the
// overlap is at its largest (dmax), unloading and reloading along kn2 from
// delta0 = dmax (1 - k_n / kn2), never attractive. Golden values with k_n = 1000, kn2 = 4000 N/m,
// no dashpot: delta0 = 0.75 dmax.
TEST(ContactLaw, HystereticSpringUnloadsAlongTheStifferBranch) {
  ContactParams p{1000, 0, 300, 0, 0.5f, 1e-4f, false};
  const float kn2 = 4000;
  Vec3 xi{};
  float dm = 0;
  ContactForce f = contact_force_h(p, kn2, {0, 1, 0}, 1e-3f, {0, -0.1f, 0}, xi, dm);  // loading: k_n delta
  EXPECT_NEAR(f.f.y, 1.0f, 1e-6f);
  EXPECT_EQ(dm, 1e-3f);
  f = contact_force_h(p, kn2, {0, 1, 0}, 0.8e-3f, {0, 0.1f, 0}, xi, dm);  // unloading: 4000 (0.8e-3 - 0.75e-3)
  EXPECT_NEAR(f.f.y, 0.2f, 1e-5f);
  EXPECT_NEAR(f.energy, 0.2f * 0.2f / (2 * 4000.0f), 1e-9f);  // recoverable: f^2 / (2 kn2)
  EXPECT_EQ(dm, 1e-3f);
  f = contact_force_h(p, kn2, {0, 1, 0}, 0.7e-3f, {0, 0.1f, 0}, xi, dm);  // below delta0: no force
  EXPECT_EQ(f.f.y, 0.0f);
  f = contact_force_h(p, kn2, {0, 1, 0}, 0.9e-3f, {0, -0.1f, 0}, xi, dm);  // reloading along kn2
  EXPECT_NEAR(f.f.y, 0.6f, 1e-5f);
  f = contact_force_h(p, kn2, {0, 1, 0}, 1.2e-3f, {0, -0.1f, 0}, xi, dm);  // past dmax: k_n again
  EXPECT_NEAR(f.f.y, 1.2f, 1e-5f);
  EXPECT_EQ(dm, 1.2e-3f);
  // kn2 <= k_n: the linear spring, bit for bit contact_force's, dmax untouched
  Vec3 xa{}, xb{};
  float d0 = 0;
  const ContactForce a = contact_force(p, {0, 1, 0}, 1e-3f, {0.05f, -0.1f, 0}, xa);
  const ContactForce b = contact_force_h(p, 1000, {0, 1, 0}, 1e-3f, {0.05f, -0.1f, 0}, xb, d0);
  EXPECT_EQ(a.f.x, b.f.x);
  EXPECT_EQ(a.f.y, b.f.y);
  EXPECT_EQ(a.energy, b.energy);
  EXPECT_EQ(d0, 0.0f);
}

// A collision with the hysteretic spring and no dashpot (restitution 1) gives back 1/lambda of
// the energy: e = 1/sqrt(lambda) (Walton & Braun 1986), measured through the Simulation at
// dt = t_clamped / 50 over 4 phases of the touch, pairs and onto the floor, within 2 %.
TEST(HeadOnHysteretic, RestitutionIsOneOverRootLambda) {
  auto create = [](const SimulationDef& d) { return Simulation::create(d); };
  for (float lambda : {4.0f, 11.111111f})
    for (bool floor : {false, true}) {
      const auto st = testutil::head_on<Simulation>(create, 1.0, 50, 4, floor, lambda);
      const double e = 1.0 / std::sqrt(double(lambda));
      std::printf("hysteretic lambda %.3f %s: e %.4f ... %.4f (1/sqrt(lambda) = %.4f)\n", lambda,
                  floor ? "floor" : "pair", st.e_lo, st.e_hi, e);
      EXPECT_NEAR(st.e_lo, e, 0.02 * e);
      EXPECT_NEAR(st.e_hi, e, 0.02 * e);
    }
}

// The hysteretic spring with a weak dashpot as well (docs/calibration.md: restitution e_d
// beside lambda, so that resting contacts are damped): the binary collision rebounds at about
// e_d / sqrt(lambda). lambda = 11.1 with e_d = 0.9 and lambda = 9 with e_d = 0.9 (e = 0.3 the
// calibration's way): within 5 % of e_d / sqrt(lambda), pairs and floor, 4 phases.
TEST(HeadOnHysteretic, WeakDashpotGivesAboutRestitutionOverRootLambda) {
  auto create = [](const SimulationDef& d) { return Simulation::create(d); };
  for (float lambda : {9.0f, 11.111111f})
    for (bool floor : {false, true}) {
      const double ed = 0.9;
      const auto st = testutil::head_on<Simulation>(create, ed, 50, 4, floor, lambda);
      const double e = ed / std::sqrt(double(lambda));
      std::printf("hysteretic lambda %.3f + dashpot e_d %.2f %s: e %.4f ... %.4f (e_d/sqrt(lambda) = %.4f)\n", lambda, ed,
                  floor ? "floor" : "pair", st.e_lo, st.e_hi, e);
      EXPECT_NEAR(st.e_lo, e, 0.05 * e);
      EXPECT_NEAR(st.e_hi, e, 0.05 * e);
    }
}

TEST(ContactLaw, SpringStickThenSlip) {
  ContactParams p{1000, 0, 300, 0, 0.5f, 1e-3f, false};
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

// Head-on collision (tests/particles/head_on.hpp): two single-sphere shells, or one sphere
// onto the floor, no gravity, no friction, at dt = t_clamped / N, 8 phases of the first touch
// within a step. Restitution and geometric contact time:
//   e: against the REQUESTED e (Material::restitution is the measured e: zeta is chosen by
//      inverting the clamped law, material.hpp);
//   contact time: against the clamped law's closed form t_clamped = clamped_contact_time
//      (Schwager & Poeschel 2007; material.hpp), the time from touch until the spheres stop
//      overlapping. The textbook t_c = pi/(w0 sqrt(1 - zeta^2)) assumes a force that turns
//      attractive, so it is too long for the clamped law and undefined for zeta >= 1 (e = 0.1
//      needs zeta = 1.243); at e = 0.9 both agree, so there it is asserted too.
// Step size (docs/dem.md "Step size"): the contact stage sees the bodies' velocities predicted
// to its time (v + (dt/2) a_prev) and gives a contact's first substep the dashpot impulse of
// the time since the touch (ContactParams::new_contact); without both, e = 0.1 at N = 50 came
// out -17 % ... +2 % with the phase. Asserted within 2 % at N = 50 for e = 0.1, 0.5,
// 0.9 (sphere pairs and the floor), and at N = 100 and 1000. HeadOnLaw below runs the same 1-D
// collision through contact_force alone.
struct HeadOnCase {
  double e;
  int steps_per_contact;
  bool floor = false;
};
class HeadOn : public ::testing::TestWithParam<HeadOnCase> {};

TEST_P(HeadOn, RestitutionAndContactTime) {
  const HeadOnCase c = GetParam();
  const double tol = 0.02;
  const testutil::HeadOnStats h =
      testutil::head_on<Simulation>([](const SimulationDef& d) { return Simulation::create(d); }, c.e,
                                    c.steps_per_contact, 8, c.floor);
  const double zeta = damping_ratio_from_restitution(c.e);
  const double tc_textbook = h.t_unit * std::numbers::pi / std::sqrt(std::max(0.0, 1 - zeta * zeta));
  for (double e_meas : {h.e_lo, h.e_hi}) EXPECT_NEAR(e_meas, c.e, tol * c.e);
  for (double t_meas : {h.t_lo, h.t_hi}) {
    EXPECT_NEAR(t_meas, h.t_clamped, tol * h.t_clamped);
    if (c.e >= 0.9) {
      EXPECT_NEAR(t_meas, tc_textbook, tol * tc_textbook);
    }
  }
  RecordProperty("e_measured_min", std::to_string(h.e_lo));
  RecordProperty("e_measured_max", std::to_string(h.e_hi));
  std::printf("%s e %.2f, dt = t_clamped/%d: zeta %.4f (textbook %.4f); measured e %.4f..%.4f (%+.2f%%..%+.2f%%), "
              "contact %.4f..%.4f/w0 (clamped theory %.4f/w0, %+.2f%%..%+.2f%%; textbook t_c %.4f/w0)\n",
              c.floor ? "floor" : "pair ", c.e, c.steps_per_contact, zeta, testutil::textbook_damping_ratio(c.e), h.e_lo, h.e_hi,
              100 * (h.e_lo / c.e - 1), 100 * (h.e_hi / c.e - 1), h.t_lo / h.t_unit, h.t_hi / h.t_unit,
              h.t_clamped / h.t_unit, 100 * (h.t_lo / h.t_clamped - 1), 100 * (h.t_hi / h.t_clamped - 1),
              tc_textbook / h.t_unit);
}

INSTANTIATE_TEST_SUITE_P(Restitutions, HeadOn,
                         ::testing::Values(HeadOnCase{0.1, 50}, HeadOnCase{0.1, 100}, HeadOnCase{0.1, 1000},
                                           HeadOnCase{0.5, 50}, HeadOnCase{0.5, 100}, HeadOnCase{0.9, 50},
                                           HeadOnCase{0.9, 100}, HeadOnCase{0.1, 50, true},
                                           HeadOnCase{0.5, 50, true}, HeadOnCase{0.9, 50, true}),
                         [](const ::testing::TestParamInfo<HeadOnCase>& i) {
                           return std::string(i.param.floor ? "floor_" : "") + "e0" +
                                  std::to_string(int(std::lround(10 * i.param.e))) + "_N" +
                                  std::to_string(i.param.steps_per_contact);
                         });

// The same head-on collision integrated here in 1-D with symplectic Euler (as the Simulation
// does: v += F/m dt, then x += v dt) through contact_force, 32 phases of the touch, with and
// without what particles/dem.cpp does: the contact stage's velocities predicted to t_n,
// v + (dt/2) a_prev (a_prev = the last substep's acceleration, zero in the first), and
// ContactParams::new_contact in the contact's first substep. Without them the first substep
// applies the dashpot c_n v0 for a whole step whatever the phase of the touch (e = 0.1 at
// dt = t_clamped/50: -19 % ... +3 %), and the dashpot sees a velocity half a step old (e high,
// contact short, first order in dt). With them, at N = 50: e = 0.1 -1.2 ... -1.0 %, contact
// +0.5 ... +0.8 %; e = 0.5 -0.2 %, 0.0 %. Asserted: spread of e > 10 % without (e = 0.1); with:
// spread < 0.5 % and e and contact time within 2 % for e = 0.1, 0.5, 0.9. The Simulation test
// above gives the same numbers (the model is the Simulation's integrator for one pair).
namespace {
struct LawRun {
  double e_lo = 1e9, e_hi = -1e9, t_lo = 1e9, t_hi = -1e9;
};
LawRun head_on_law(double e, int N, bool fixed) {
  Material mat;
  mat.restitution = float(e);
  const double m = sphere_mass(), meff = m / 2;
  const double cn = normal_damping(mat, meff);
  const double t_cl = clamped_contact_time(mat, meff);
  const float dt = float(t_cl / N);
  const float v0 = 0.2f;
  LawRun out;
  for (int phase = 0; phase < 32; ++phase) {
    ContactParams p{mat.normal_stiffness, float(cn), 0, 0, 0, dt, false};
    float xa = 0, xb = float(2 * kR) + 1e-5f + phase / 32.0f * 2 * v0 * dt, va = v0, vb = -v0;
    float va_old = va, vb_old = vb;  // velocities before the last kick: a_prev = (v - v_old)/dt
    double gap_prev = xb - xa - 2 * kR, t = 0, t_in = -1, t_out = -1;
    bool touching = false;
    for (int k = 0; k < 40 * N && t_out < 0; ++k) {
      const float delta = float(2 * kR) - (xb - xa);
      float fb = 0;  // force on b along +x (n from a to b)
      if (delta > 0) {
        p.new_contact = fixed && !touching;
        const float ua = fixed ? va + 0.5f * (va - va_old) : va, ub = fixed ? vb + 0.5f * (vb - vb_old) : vb;
        Vec3 xi{};
        fb = contact_force(p, {1, 0, 0}, delta, {ub - ua, 0, 0}, xi).f.x;
      }
      touching = delta > 0;
      va_old = va, vb_old = vb;
      vb += float(fb / m) * dt, va -= float(fb / m) * dt;
      xb += vb * dt, xa += va * dt;
      t += dt;
      const double gap = double(xb) - double(xa) - 2 * kR;
      if (t_in < 0 && gap < 0) t_in = t - dt * gap / (gap - gap_prev);
      if (t_in >= 0 && gap >= 0 && gap_prev < 0) t_out = t - dt * gap / (gap - gap_prev);
      gap_prev = gap;
    }
    const double em = (vb - va) / (2.0 * v0), tm = (t_out - t_in) / t_cl;
    out.e_lo = std::min(out.e_lo, em / e - 1), out.e_hi = std::max(out.e_hi, em / e - 1);
    out.t_lo = std::min(out.t_lo, tm - 1), out.t_hi = std::max(out.t_hi, tm - 1);
  }
  std::printf("law, e %.1f, dt = t_clamped/%d, predictor + first substep %s: e %+.2f%%..%+.2f%%, "
              "contact %+.2f%%..%+.2f%%\n",
              e, N, fixed ? "on " : "off", 100 * out.e_lo, 100 * out.e_hi, 100 * out.t_lo, 100 * out.t_hi);
  return out;
}
}  // namespace

TEST(HeadOnLaw, PredictorAndFirstSubstepRemovePhaseSpread) {
  const LawRun off = head_on_law(0.1, 50, false);
  EXPECT_GT(off.e_hi - off.e_lo, 0.10);
  for (double e : {0.1, 0.5, 0.9}) {
    const LawRun on = head_on_law(e, 50, true);
    EXPECT_LT(on.e_hi - on.e_lo, 0.005) << "e " << e;
    EXPECT_LT(std::max(std::abs(on.e_lo), std::abs(on.e_hi)), 0.02) << "e " << e;
    EXPECT_LT(std::max(std::abs(on.t_lo), std::abs(on.t_hi)), 0.02) << "e " << e;
  }
}

namespace {
// A rigid 3 x 3 plate of spheres (spacing 2r) resting on the floor, gravity tilted by theta
// about z (equivalent to a plane tilted by theta). Returns x(t) samples.
struct Incline {
  double a_measured = 0, drift = 0;
  int resorts = 0, shell_lists = 0;  // grid + both lists, the shell list alone (StepStats)
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
  BodyId far{};
  if (force_rebuilds) {
    // a kinematic sphere far away moving at 2 m/s: moves more than the shell list's trip every
    // ~20 steps, so the shell list is rebuilt again and again under the resting plate; and its
    // collision group changed every 10 steps rebuilds the grid and both lists
    ShellDef k;
    k.offsets = {{0, 0, 0}};
    k.radii = {float(kR)};
    k.motion = MotionType::Kinematic;
    k.position = {1.5f, 0.03f, 0};
    k.velocity = {0, 0, 0};
    auto kid = sim->add_shell(k);
    EXPECT_TRUE(kid.ok());
    EXPECT_TRUE(sim->set_kinematic_velocity(*kid, {0, 0, 2.0f}, {}).ok());
    far = *kid;
  }
  const double dt = 5e-5;
  Incline out;
  double x0 = 0, v0 = 0;
  int n0 = int(t0 / dt), n1 = int(t1 / dt);
  for (int k = 1; k <= n1; ++k) {
    if (force_rebuilds && k % 10 == 0) EXPECT_TRUE(sim->set_body_group(far, (k / 10) % 2).ok());
    EXPECT_TRUE(sim->step(dt).ok());
    out.resorts += sim->last_step().resorts;
    out.shell_lists += sim->last_step().shell_lists;
    if (k == n0) {
      x0 = sim->body_position(*id).x;
      v0 = sim->body_velocity(*id).x;
    }
  }
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
// partner id, the boundary planes' with the sort): the same plate stays put while the grid and
// both lists are rebuilt every 10 steps and the shell list alone in between.
TEST(Friction, SpringsSurviveListRebuilds) {
  Incline r = run_incline(20.0, ShearLaw::SpringHistory, 0.1, 0.6, true);
  EXPECT_LT(std::abs(r.drift), 0.001 * 2 * kR);
  EXPECT_GE(r.resorts, 1000);     // 12,000 steps
  EXPECT_GE(r.shell_lists, 100);
}


}  // namespace sandpatch
