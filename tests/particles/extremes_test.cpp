// DEM extremes (docs/dem.md "Extremes"): each case is either correct (checked against
// a formula with a stated tolerance) or refused with an Error naming the field; never NaN,
// never a body through the floor.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

#include "particles/bed.hpp"
#include "particles/dem.hpp"

namespace sandpatch {
namespace {

SimulationDef box(float side, float height) {
  SimulationDef d;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {side, height, side};
  d.side_walls = true;
  d.sleep_time = 0;
  return d;
}

bool finite(Vec3 v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

// Lowest sphere centre of all granules (m) and whether every body state is finite.
struct Scan {
  float lowest = 1e30f;
  bool ok = true;
};
Scan scan(const Simulation& s) {
  Scan r;
  for (Vec3 p : s.particle_positions()) {
    r.ok = r.ok && finite(p);
    r.lowest = std::min(r.lowest, p.y);
  }
  for (int i = 0; i < s.body_count(); ++i)
    r.ok = r.ok && finite(s.body_velocity(BodyId{i})) && finite(s.body_angular_velocity(BodyId{i}));
  return r;
}

// Orientation putting face (1,-1,-1),(-1,1,-1),(-1,-1,1) of the granule (granule.cpp) down:
// the vertex (1,1,1) rotated onto +y.
Quat face_down() {
  const Vec3 from{0.57735027f, 0.57735027f, 0.57735027f}, to{0, 1, 0};
  const Vec3 axis = cross(from, to);
  const float ang = std::acos(dot(from, to));
  return axis_angle(axis * (1.0f / length(axis)), ang);
}

}  // namespace

// dt beyond the explicit limit cannot be asked for: the substep is t_c/N with N >= 2
// (w dt <= pi/2 < 2, the symplectic-Euler limit); N = 1 is refused naming the field.
// (0.5x and 2x the stable substep: Simulation.StabilityGuard in dem_test.cpp.)
TEST(Extremes, SubstepBeyondExplicitLimitRefused) {
  SimulationDef d = box(0.1f, 0.1f);
  d.accuracy_steps_per_contact = 1;
  auto s = Simulation::create(d);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "SimulationDef.accuracy_steps_per_contact");
}

// A 3x3x3 bed dropped with frames of 0.5x and 2x the largest substep (1 and 2 substeps per
// frame) settles to the same mean height within 0.1 d, finite and above the floor.
TEST(Extremes, HalfAndTwiceTheStableFrame) {
  double mean_y[2];
  for (int c = 0; c < 2; ++c) {
    SimulationDef d = box(0.08f, 0.12f);
    auto s = Simulation::create(d);
    ASSERT_TRUE(s.ok());
    LatticeBedDef bed;
    bed.nx = bed.nz = bed.layers = 3;
    bed.min = {0.015f, 0.012f, 0.015f};
    bed.seed = 5;
    ASSERT_TRUE(add_lattice_bed(*s, bed).ok());
    const double frame = (c == 0 ? 0.5 : 2.0) * s->max_substep_dt();
    for (double t = 0; t < 0.6; t += frame) ASSERT_TRUE(s->step(frame).ok());
    EXPECT_EQ(s->last_step().substeps, c == 0 ? 1 : 2);
    Scan sc = scan(*s);
    EXPECT_TRUE(sc.ok);
    EXPECT_GT(sc.lowest, 0.9f * d.particle_radius);  // resting on the floor, not in it
    EXPECT_LT(s->max_granule_speed(), 0.05);
    double m = 0;
    for (int i = 0; i < s->body_count(); ++i) m += s->body_position(BodyId{i}).y / s->body_count();
    mean_y[c] = m;
  }
  EXPECT_NEAR(mean_y[0], mean_y[1], 0.1 * 0.01);
  std::printf("mean granule height: 0.5x frame %.5f m, 2x frame %.5f m\n", mean_y[0], mean_y[1]);
}

// Stiffness 1e2 ... 1e9 N/m: a granule placed face down on the floor rests with each of its
// three floor contacts overlapped by m g / (3 k_n), within 2% + 2e-9 m (4 float ulps of a
// position at y = 5 mm: from 1e7 N/m on, the overlap is below what a float position resolves,
// so there the check is only "not in the floor by more than 4 ulps");
// at 1e9 N/m a 1/60 s frame is refused (Simulation.StabilityGuard) and frames of 1e-4 s with
// a raised max_substeps run.
TEST(Extremes, StiffnessRange) {
  for (double k : {1e2, 1e3, 3292.0, 1e5, 1e7, 1e9}) {
    SimulationDef d = box(0.06f, 0.06f);
    d.material.normal_stiffness = float(k);
    d.max_substeps = 1 << 20;
    auto s = Simulation::create(d);
    ASSERT_TRUE(s.ok());
    const GranuleShape& g = s->granule_shape();
    const Quat q = face_down();
    float low = 0;  // lowest sphere offset below the centre
    for (Vec3 o : g.offsets) low = std::min(low, rotate(q, o).y);
    ASSERT_TRUE(s->add_granule({0.03f, g.radius - low, 0.03f}, q).ok());
    // settle for 8 undamped contact periods of the granule on its 3 springs
    const double period = 2 * std::numbers::pi * std::sqrt(g.mass / (3 * k));
    const double frame = std::min(1.0 / 60, period / 4);
    for (double t = 0; t < std::max(8 * period, 0.05); t += frame) {
      auto st = s->step(frame);
      ASSERT_TRUE(st.ok()) << st.message();
    }
    Scan sc = scan(*s);
    ASSERT_TRUE(sc.ok) << k;
    const double overlap = g.radius - sc.lowest, expect = g.mass * 9.81 / (3 * k);
    EXPECT_NEAR(overlap, expect, 0.02 * expect + 2e-9) << "k_n = " << k;
    std::printf("k_n %.0e N/m: floor overlap %.4g m (m g / 3 k_n = %.4g m), %d substeps per frame\n", k, overlap,
                expect, s->last_step().substeps);
  }
}

// A 50 m/s impact into a bed. At the peer stiffness it would overlap a contact by
// v sqrt(m_pt/k_n) = 6.3 cm = 13 r: step() refuses naming the body's speed and the stiffness
// needed. With the stiffness raised to (2 v / r)^2 m_pt (4x the guard's minimum, so the
// allowed speed f r sqrt(k/m_pt) is 2 x 50 m/s at f = 1 and 4 x at the default f = 2; and
// max_substeps), the impactor (a sphere of granule mass) goes through a loose 3x3x2 bed and is
// stopped by the floor: nothing non-finite, no sphere centre below the floor, the impactor's
// floor overlap < 0.5 r.
TEST(Extremes, Impact50MetresPerSecond) {
  const float v_in = 50.0f;
  for (int pass = 0; pass < 2; ++pass) {
    SimulationDef d = box(0.08f, 0.3f);
    d.max_bodies = 32;
    d.max_particles = 128;
    double k_needed = 0;
    if (pass == 1) {
      auto probe = Simulation::create(d);
      const GranuleShape& g = probe->granule_shape();
      // k = (2 v / r)^2 m_pt, m_pt = the impactor's mass (a single sphere: no rotation)
      k_needed = std::pow(2.0 * v_in / g.radius, 2) * g.mass;
      d.material.normal_stiffness = float(k_needed);
      d.max_substeps = 1 << 16;
    }
    auto s = Simulation::create(d);
    ASSERT_TRUE(s.ok());
    LatticeBedDef bed;
    bed.nx = bed.nz = 3;
    bed.layers = 2;
    bed.min = {0.015f, 0.0125f, 0.015f};
    bed.seed = 9;
    ASSERT_TRUE(add_lattice_bed(*s, bed).ok());
    const GranuleShape& g = s->granule_shape();
    ShellDef imp;
    imp.offsets = {{0, 0, 0}};
    imp.radii = {g.radius};
    imp.motion = MotionType::Dynamic;
    imp.mass = g.mass;
    imp.inertia = {0.4f * g.mass * g.radius * g.radius, 0.4f * g.mass * g.radius * g.radius,
                   0.4f * g.mass * g.radius * g.radius};
    imp.position = {0.04f, 0.08f, 0.04f};
    imp.velocity = {0, -v_in, 0};
    auto id = s->add_shell(imp);
    ASSERT_TRUE(id.ok()) << id.message();
    if (pass == 0) {
      auto st = s->step(1e-3);
      ASSERT_FALSE(st.ok());
      EXPECT_EQ(st.error().field, "step.body[18].speed");
      EXPECT_NE(st.error().detail.find("normal_stiffness"), std::string::npos) << st.message();
      EXPECT_EQ(s->time(), 0.0);
      std::printf("50 m/s at k_n = 3292 N/m: refused: %s", st.message().c_str());
      continue;
    }
    float lowest_imp = 1e30f;
    for (int f = 0; f < 100; ++f) {  // 10 ms: through the bed's depth twice at 50 m/s
      auto st = s->step(1e-4);
      ASSERT_TRUE(st.ok()) << st.message();
      lowest_imp = std::min(lowest_imp, s->body_position(*id).y);
    }
    Scan sc = scan(*s);
    EXPECT_TRUE(sc.ok);
    EXPECT_GT(sc.lowest, 0.0f);  // no sphere centre below the floor
    EXPECT_GT(lowest_imp, g.radius * 0.5f);
    std::printf("50 m/s at k_n = %.3g N/m: lowest impactor centre %.4f m, lowest sphere centre %.4f m, %d substeps per "
                "0.1 ms\n",
                k_needed, lowest_imp, sc.lowest, s->last_step().substeps);
  }
}

// Body/granule mass ratio 1e5: a 4x4-sphere plate of 1e5 granule masses. At the peer
// stiffness its weight alone overlaps each of its 16 sphere contacts by >= m g/(16 k_n) =
// 9.8 cm = 19.5 r: add_shell refuses naming ShellDef.mass. At 10x the stiffness it asks for, the
// plate placed on a layer of 4x4 granules stays above the granules' floor contacts: finite,
// no sphere centre below the floor, plate centre above 2 r.
TEST(Extremes, MassRatio1e5) {
  for (int pass = 0; pass < 2; ++pass) {
    SimulationDef d = box(0.11f, 0.1f);
    d.max_bodies = 32;
    d.max_particles = 128;
    auto probe = Simulation::create(d);
    const GranuleShape& g0 = probe->granule_shape();
    const double mass = 1e5 * g0.mass;
    if (pass == 1) {
      d.material.normal_stiffness = float(10 * mass * 9.81 / (16 * g0.radius));
      d.max_substeps = 1 << 16;
    }
    auto s = Simulation::create(d);
    ASSERT_TRUE(s.ok());
    const GranuleShape& g = s->granule_shape();
    const Quat q = face_down();
    float low = 0, high = 0;
    for (Vec3 o : g.offsets) low = std::min(low, rotate(q, o).y), high = std::max(high, rotate(q, o).y);
    const float a = 0.025f;
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) ASSERT_TRUE(s->add_granule({0.018f + a * i, g.radius - low, 0.018f + a * k}, q).ok());
    ShellDef p;
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) p.offsets.push_back({a * (i - 1.5f), 0, a * (k - 1.5f)});
    p.radii = {g.radius};
    p.motion = MotionType::Dynamic;
    p.mass = float(mass);
    const float I = float(mass * 2 * a * a);
    p.inertia = {I, 2 * I, I};
    p.position = {0.018f + 1.5f * a, g.radius - low + high + 2 * g.radius, 0.018f + 1.5f * a};
    auto id = s->add_shell(p);
    if (pass == 0) {
      ASSERT_FALSE(id.ok());
      EXPECT_EQ(id.error().field, "ShellDef.mass");
      EXPECT_NE(id.error().detail.find("normal_stiffness"), std::string::npos);
      EXPECT_EQ(s->body_count(), 16);  // nothing half-added
      std::printf("mass ratio 1e5 at k_n = 3292 N/m: refused: %s", id.message().c_str());
      continue;
    }
    ASSERT_TRUE(id.ok()) << id.message();
    for (int f = 0; f < 200; ++f) {
      auto st = s->step(2.5e-4);
      ASSERT_TRUE(st.ok()) << st.message();
    }
    Scan sc = scan(*s);
    EXPECT_TRUE(sc.ok);
    EXPECT_GT(sc.lowest, 0.0f);
    const float py = s->body_position(*id).y;
    EXPECT_GT(py, 2 * g.radius);
    std::printf("mass ratio 1e5 at k_n = %.3g N/m: plate centre %.4f m (placed %.4f), lowest granule sphere %.4f m\n",
                d.material.normal_stiffness, py, p.position.y, sc.lowest);
  }
}

// A bed 60 layers deep: a 2x2x60 column of granules in a walled box settles; nothing
// non-finite; the floor contacts overlap by < 0.5 r; the column comes to rest (< 0.05 m/s).
TEST(Extremes, Bed60LayersDeep) {
  const GranuleShape g0 = make_granule_shape(0.005f, 1.0f, 2500.0f);
  const float a = 2.0f * (g0.centre_distance + g0.radius) * 1.02f;
  SimulationDef d = box(2 * a + 0.004f, 60 * a + 0.05f);
  d.max_bodies = 240;
  d.max_particles = 960;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok());
  LatticeBedDef bed;
  bed.nx = bed.nz = 2;
  bed.layers = 60;
  bed.spacing = a;
  bed.min = {0.5f * a + 0.002f, g0.centre_distance + g0.radius + 1e-4f, 0.5f * a + 0.002f};
  bed.seed = 11;
  ASSERT_TRUE(add_lattice_bed(*s, bed).ok());
  for (int f = 0; f < 1500; ++f) {
    auto st = s->step(1e-3);
    ASSERT_TRUE(st.ok()) << st.message();
  }
  Scan sc = scan(*s);
  EXPECT_TRUE(sc.ok);
  EXPECT_GT(sc.lowest, 0.5f * g0.radius);
  EXPECT_LT(s->max_granule_speed(), 0.05);
  float top = 0;
  for (int i = 0; i < s->body_count(); ++i) top = std::max(top, s->body_position(BodyId{i}).y);
  std::printf("60 layers: top granule at %.3f m (lattice top %.3f m), floor overlap %.3g r, max speed %.3g m/s\n", top,
              bed.min.y + 59 * a, (g0.radius - sc.lowest) / g0.radius, s->max_granule_speed());
}

// Far from the origin: the simulation is patch-relative (float) and the patch origin is a
// double in ParticleScale, so a patch 10 km away runs bit-for-bit like one at the origin and
// maps back to the world exactly (to 1e-6 m); bounds 10 km from the simulation origin, where
// a float resolves only 1 mm (0.2 r), are refused naming the bound and the origin to use.
TEST(Extremes, PatchTenKilometresFromOrigin) {
  std::uint64_t hash[2];
  std::array<double, 3> world[2];
  for (int c = 0; c < 2; ++c) {
    SimulationDef d = box(0.06f, 0.06f);
    auto sc = ParticleScale::create(1.0, c == 0 ? std::array<double, 3>{0, 0, 0} : std::array<double, 3>{1e4, 0, 1e4});
    ASSERT_TRUE(sc.ok());
    d.scale = *sc;
    auto s = Simulation::create(d);
    ASSERT_TRUE(s.ok());
    ASSERT_TRUE(s->add_granule({0.03f, 0.02f, 0.03f}).ok());
    for (int f = 0; f < 300; ++f) ASSERT_TRUE(s->step(1e-3).ok());
    hash[c] = s->state_hash();
    world[c] = d.scale.position_to_world(s->body_position(BodyId{0}));
  }
  EXPECT_EQ(hash[0], hash[1]);
  EXPECT_NEAR(world[1][0] - 1e4, world[0][0], 1e-6);
  EXPECT_NEAR(world[1][1], world[0][1], 1e-6);
  EXPECT_NEAR(world[1][2] - 1e4, world[0][2], 1e-6);

  SimulationDef far = box(0.06f, 0.06f);
  far.bounds_min = {1e4f, 0, 1e4f};
  far.bounds_max = {1e4f + 0.06f, 0.06f, 1e4f + 0.06f};
  auto s = Simulation::create(far);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().field, "SimulationDef.bounds_min.x");
  EXPECT_NE(s.message().find("scale"), std::string::npos) << s.message();
}

// The overlap guard with heavy damping: e = 0.01 needs zeta = 4.8 (over-damped). The
// explicit damper limit dt <= m_eff/c_n then binds the substep (below t_c/N), and a granule
// dropped onto the floor at 1 m/s comes to rest without a bounce above 1 mm, finite.
TEST(Extremes, OverdampedGuard) {
  SimulationDef d = box(0.06f, 0.1f);
  d.material.restitution = 0.01f;
  auto s = Simulation::create(d);
  ASSERT_TRUE(s.ok());
  const GranuleShape& g = s->granule_shape();
  const double zeta = damping_ratio_from_restitution(0.01);
  EXPECT_GT(zeta, 4.0);
  const double m_pt = point_effective_mass(g.mass, g.inertia, g.centre_distance) / 2;  // guard pair
  const double cn = 2 * zeta * std::sqrt(3292.0 * g.mass / 2);                         // granule pair
  EXPECT_NEAR(s->max_substep_dt(), m_pt / cn, 1e-6 * m_pt / cn);
  EXPECT_LT(s->max_substep_dt(), std::numbers::pi * std::sqrt(m_pt / 3292.0) / 20);
  const Quat q = face_down();
  float low = 0;
  for (Vec3 o : g.offsets) low = std::min(low, rotate(q, o).y);
  auto id = s->add_granule({0.03f, g.radius - low + 1e-4f, 0.03f}, q, {0, -1.0f, 0});
  ASSERT_TRUE(id.ok());
  float top_after = 0;
  bool touched = false;
  for (int f = 0; f < 300; ++f) {
    ASSERT_TRUE(s->step(1e-3).ok());
    const float y = s->body_position(*id).y;
    if (s->last_step().wall_contacts > 0) touched = true;
    if (touched) top_after = std::max(top_after, y);
  }
  Scan sc = scan(*s);
  EXPECT_TRUE(sc.ok);
  EXPECT_LT(top_after - (g.radius - low), 1e-3);
  EXPECT_LT(s->max_granule_speed(), 1e-3);
}

}  // namespace sandpatch
