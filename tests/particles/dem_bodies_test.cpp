// The body stage (particles/dem_bodies.cpp): a shell of more than Impl::kWideShell spheres is
// summed and rebuilt in chunks over the threads. Its sums must hold every sphere once, in an
// order that does not depend on the thread count, and every sphere must be rebuilt.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "particles/dem.hpp"

namespace sandpatch {
namespace {

// kWideShell (particles/dem_impl.hpp) is 2,048 spheres: 46 x 46 = 2,116 is past it, in five
// chunks of 512 (the last one short).
constexpr int kSide = 46;
constexpr float kR = 0.002f;    // m, the plate's sphere radius
constexpr float kGap = 0.004f;  // m, between sphere centres

ShellDef plate(MotionType motion, Vec3 position, Vec3 velocity) {
  ShellDef p;
  for (int i = 0; i < kSide; ++i)
    for (int k = 0; k < kSide; ++k) p.offsets.push_back({(i - 0.5f * (kSide - 1)) * kGap, 0, (k - 0.5f * (kSide - 1)) * kGap});
  p.radii = {kR};
  p.motion = motion;
  p.mass = 2.0f;  // kg
  const float side = kSide * kGap;
  p.inertia = {p.mass * side * side / 12, p.mass * side * side / 6, p.mass * side * side / 12};  // a thin square
  p.position = position;
  p.velocity = velocity;
  return p;
}

SimulationDef box(int threads) {
  SimulationDef d;
  d.bounds_min = {-0.15f, 0, -0.15f};
  d.bounds_max = {0.15f, 0.1f, 0.15f};
  d.particle_radius = kR;
  d.material.normal_stiffness = 2e4f;  // N/m: stiff enough for the stability guard at the plate's landing speed
  d.sleep_time = 0;
  d.threads = threads;
  d.max_bodies = 4;
  d.max_particles = 2 * kSide * kSide;
  return d;
}

struct PlateRun {
  std::uint64_t hash = 0;
  double rest_force = 0;  // N, the floor's mean upward force on the resting plate
  double tilt = 0;        // largest |q.x|, |q.z| of the plate over the run
  double kin_error = 0;   // m, the kinematic plate's spheres against where its pose puts them
  double rest_y = 0;      // m, the dynamic plate's height at the end
};

// A dynamic plate dropped 2 mm onto the floor and left to rest; above it a kinematic plate
// moving sideways at 5 cm/s, touching nothing.
PlateRun run(int threads) {
  PlateRun out;
  auto s = Simulation::create(box(threads));
  EXPECT_TRUE(s.ok()) << s.message();
  if (!s.ok()) return out;
  auto dyn = s->add_shell(plate(MotionType::Dynamic, {0, kR + 0.002f, 0}, {}));
  const Vec3 v_kin{0.05f, 0, 0};
  auto kin = s->add_shell(plate(MotionType::Kinematic, {-0.02f, 0.06f, 0}, v_kin));
  EXPECT_TRUE(dyn.ok() && kin.ok());
  if (!dyn.ok() || !kin.ok()) return out;
  const double dt = 2e-5;
  const int steps = 5000;  // 0.1 s: falls for 20 ms, then rings down on the floor
  int counted = 0;
  for (int k = 0; k < steps; ++k) {
    const Status st = s->step(dt);
    EXPECT_TRUE(st.ok()) << st.message();
    if (!st.ok()) return out;
    const Quat q = s->body_orientation(*dyn);
    out.tilt = std::max({out.tilt, double(std::abs(q.x)), double(std::abs(q.z))});
    if (k >= steps - 1000) {
      out.rest_force += s->body_force(*dyn).y;
      ++counted;
    }
  }
  out.rest_force /= counted;
  out.rest_y = s->body_position(*dyn).y;
  // every sphere of the kinematic plate where its pose puts it (the plate does not turn)
  const std::vector<Vec3> pos = s->particle_positions();
  const ShellDef k = plate(MotionType::Kinematic, {}, {});
  const Vec3 c = s->body_position(*kin);
  for (int j = 0; j < kSide * kSide; ++j) {
    const Vec3 want = c + k.offsets[std::size_t(j)];
    const Vec3 got = pos[std::size_t(kSide * kSide + j)];  // (the second body's spheres follow the first's)
    out.kin_error = std::max(out.kin_error, double(length(got - want)));
  }
  EXPECT_NEAR(c.x, -0.02 + 0.05 * dt * steps, 1e-4) << "the kinematic plate moved at its velocity";
  out.hash = s->state_hash();
  return out;
}

TEST(WideShells, SummedInChunksAsOneBodyOnAnyThreadCount) {
  const PlateRun one = run(1), two = run(2);
  EXPECT_EQ(one.hash, two.hash) << "the chunks' order does not depend on the threads";
  // Resting on the floor, the floor's force on it is its weight: every sphere's floor contact
  // summed once (a chunk left out or counted twice would be 1/5 off).
  const double weight = 2.0 * 9.81;
  EXPECT_NEAR(two.rest_force, weight, 0.01 * weight);
  // The floor pushes every sphere alike: the torques about the centre cancel and it stays level.
  EXPECT_LT(two.tilt, 1e-4);
  EXPECT_NEAR(two.rest_y, kR, 0.5 * kR) << "resting on its spheres";
  // Every chunk rebuilt: each sphere of the moving kinematic plate is where its pose puts it.
  EXPECT_LT(two.kin_error, 1e-6);
  std::printf("wide plate of %d spheres: floor force %.4f N against its weight %.4f N, tilt %.2g, kinematic spheres off by %.2g m\n",
              kSide * kSide, two.rest_force, weight, two.tilt, two.kin_error);
}

}  // namespace
}  // namespace sandpatch
