// The coupling (manager/coupling.cpp): bodies joined by joints are one collision group in the
// patch's DEM (BulletWorld::joint_groups), so their shells do not push each other.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "manager/world.hpp"
#include "tests/manager/rig.hpp"

namespace sandpatch {
namespace {

// Two 0.3 m cubes of 20 kg dropped from 5 cm onto flat sand of 2.5 cm granules, side by side
// along x with a 3 cm gap: their shells (sphere centres on the faces, r = 2.5 cm) overlap by
// 2 cm across it, while Bullet sees no contact. Returns the soil force along x (N) on the left
// cube over its first 10 carried frames: the mean and the largest in size, with its sign.
struct Push {
  double mean_fx = 0, max_abs_fx = 0, fx_at_max = 0;
  int frames = 0;
};
Push left_cube_push(bool jointed) {
  test::Rig rig(test::terrain_8m("flat"));
  EXPECT_TRUE(rig.ok()) << rig.error;
  auto cube = [&](double x) {
    RigidBodyDef b;
    b.name = x < 4.0 ? "left" : "right";
    b.shape.kind = RigidShapeKind::Box;
    b.shape.half_extents = {0.15f, 0.15f, 0.15f};
    b.mass = 20.0f;
    b.position = {x, 1.2, 4.0};
    auto id = rig.core->add_body(b);
    EXPECT_TRUE(id.ok()) << id.message();
    return *id;
  };
  const RigidBodyId a = cube(4.0 - 0.165), b = cube(4.0 + 0.165);
  if (jointed) {
    RigidJointDef j;
    j.name = "weld";
    j.kind = JointKind::Fixed;
    j.a = a;
    j.b = b;
    j.anchor = {4.0, 1.2, 4.0};
    auto jid = rig.core->add_joint(j);
    EXPECT_TRUE(jid.ok()) << jid.message();
  }
  TerrainManagerDef def = test::small_manager_def();
  def.threads = 1;
  EXPECT_TRUE(rig.start(def).ok()) << rig.error;
  Push p;
  EXPECT_TRUE(rig.frames(60, [&] {
                  const World::SoilForce fa = rig.core->soil_force(a), fb = rig.core->soil_force(b);
                  if (!fa.carried || !fb.carried) return false;
                  p.mean_fx += fa.force.x();
                  if (std::abs(fa.force.x()) > p.max_abs_fx) p.max_abs_fx = std::abs(fa.force.x()), p.fx_at_max = fa.force.x();
                  return ++p.frames == 10;
                }).ok())
      << rig.error;
  p.mean_fx /= std::max(p.frames, 1);
  return p;
}

// Welded by a fixed joint, the cubes' overlapping shells do not push each other: the left
// cube feels only the granules, a few tens of newtons sideways (measured at most 52 N, a
// quarter of its weight); without the joint the shells push it away from the right cube (-x)
// in the frame they first overlap, with k_n delta per facing pair of spheres (2e4 N/m x 2 cm
// = 400 N each; measured 1,048 N), and the cubes part.
TEST(Coupling, JointedBodiesShellsDoNotPushEachOther) {
  const Push free = left_cube_push(false), welded = left_cube_push(true);
  std::printf("left cube, soil force along x over %d / %d carried frames: free: mean %.1f N, largest %.1f N; "
              "welded: mean %.1f N, largest %.1f N; its weight 196 N\n",
              free.frames, welded.frames, free.mean_fx, free.fx_at_max, welded.mean_fx, welded.fx_at_max);
  ASSERT_EQ(free.frames, 10);
  ASSERT_EQ(welded.frames, 10);
  EXPECT_LT(free.fx_at_max, -400.0);                  // pushed away from the other cube's shell
  EXPECT_LT(welded.max_abs_fx, 0.5 * 9.81 * 20.0);    // the granules' sideways push only: < half its weight
  EXPECT_LT(welded.max_abs_fx, 0.1 * free.max_abs_fx);
}

}  // namespace
}  // namespace sandpatch
