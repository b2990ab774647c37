// The coupling (manager/coupling.cpp): bodies joined by joints are one collision group in the
// patch's DEM (BulletWorld::joint_groups), so their shells do not push each other; a body
// moving onto a patch does not hop.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <nlohmann/json.hpp>

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


// The box of examples/push_box (0.6 m x 0.4 m x 0.6 m, 40 kg) driven along +x at 3.5 m/s (its
// x velocity set before every frame of 1/60 s, the rest left to Bullet and the soil) over flat
// terrain at y = 1 m (granules of r = 2.5 cm), from rest, until its centre passes x = 5 m.
enum class Meet {
  Plain,        // no terrain manager: the heightfield only (from x = 2.3 m)
  OnPatch,      // set down on a patch over x in [3.2, 5.4] and driven from rest on it (x = 3.5 m)
  Promoted,     // the box's own request promoted under it as it sets off (x = 2.0 m)
  Ahead,        // a patch asked for over x in [4.0, 5.6], live when it arrives (x = 2.3 m)
  AheadAsleep,  // the same patch, asleep when it arrives
};
struct Hop {
  // Over the window: the 12 frames (0.2 s, 0.7 m) from the first frame a patch carries the box
  // (Plain: from the first driven frame; OnPatch: from its 13th, once it ploughs steadily).
  double vy_max = 0;   // m/s, largest upward velocity after a frame
  double rise = 0;     // m, largest rise of its bottom above its resting bottom before the drive
  double vy_start = 0; // m/s, largest upward velocity over the first 12 driven frames
  double rest = 0;     // m, its resting bottom before the drive above the heightfield's surface
  int first = -1;      // the window's first frame
  int frames = 0;      // frames driven
  nlohmann::ordered_json arrivals;  // the manager's report: arrivals (null if none)
};
Hop drive_box(Meet meet) {
  Hop h;
  test::Rig rig(test::terrain_8m("flat"));
  EXPECT_TRUE(rig.ok()) << rig.error;
  BulletWorld& world = *rig.world;
  RigidBodyDef box;
  box.name = "box";
  box.shape.kind = RigidShapeKind::Box;
  box.shape.half_extents = {0.3f, 0.2f, 0.3f};
  box.mass = 40.0f;
  box.position = {meet == Meet::Promoted ? 2.0 : meet == Meet::OnPatch ? 3.5 : 2.3, 1.2, 4.0};
  TerrainManagerDef def = test::small_manager_def();
  def.slots = 1;
  def.granules_per_slot = meet == Meet::OnPatch ? 16000 : 10000;
  def.lod.apron = 0.3;
  def.threads = 1;
  if (meet == Meet::OnPatch) {
    EXPECT_TRUE(rig.start(def).ok()) << rig.error;
    rig.manager->request_patch(3.2, 3.5, 5.4, 4.5, rig.t());
    EXPECT_TRUE(rig.frames(30, [&] { return rig.manager->ready_patches() == 1; }).ok()) << rig.error;
    box.position.y() += 0.03;
  }
  auto id = rig.core->add_body(box);
  EXPECT_TRUE(id.ok());
  if (!id.ok()) return h;
  auto bottom = [&] {
    Eigen::Vector3d lo, hi;
    world.bounds(*id, &lo, &hi);
    return lo.y();
  };
  if (meet == Meet::OnPatch) {
    EXPECT_TRUE(rig.frames(60).ok()) << rig.error;  // settled on the granules
    EXPECT_FALSE(world.terrain_collision(*id)) << "carried";
  } else {
    // Set down at rest on the heightfield, then (but for Plain) the terrain manager: a body
    // at rest asks for no patch.
    EXPECT_TRUE(rig.frames(45).ok()) << rig.error;
    if (meet != Meet::Plain) {
      EXPECT_TRUE(rig.start(def).ok()) << rig.error;
      EXPECT_TRUE(rig.frames(5).ok()) << rig.error;
      EXPECT_EQ(rig.manager->active_patches(), 0);
    }
  }
  if (meet == Meet::Ahead || meet == Meet::AheadAsleep) {
    rig.manager->request_patch(4.0, 3.4, 5.6, 4.6, rig.t());
    EXPECT_TRUE(rig.frames(300, [&] {
                  if (meet == Meet::Ahead) return rig.manager->ready_patches() == 1;
                  return rig.manager->asleep_patches() == 1;
                }).ok())
        << rig.error;
    EXPECT_EQ(rig.manager->ready_patches(), 1);
    EXPECT_EQ(rig.manager->asleep_patches(), meet == Meet::AheadAsleep ? 1 : rig.manager->asleep_patches());
  }
  const double y0 = bottom();
  h.rest = y0 - 1.0;
  for (int f = 0; f < 120 && world.state(*id).position.x() < 5.0; ++f) {
    BodyState st = world.state(*id);
    st.linear_velocity.x() = 3.5f;
    st.linear_velocity.z() = 0.0f;
    world.set_state(*id, st);
    EXPECT_TRUE(rig.frame().ok()) << rig.error;
    ++h.frames;
    const double vy = world.state(*id).linear_velocity.y();
    const bool carried = rig.core->soil_force(*id).carried;
    if (h.first < 0 && (meet == Meet::Plain || (meet == Meet::OnPatch ? f == 12 : carried))) h.first = f;
    if (f < 12) h.vy_start = std::max(h.vy_start, vy);
    if (h.first < 0 || f >= h.first + 12) continue;
    h.vy_max = std::max(h.vy_max, vy);
    h.rise = std::max(h.rise, bottom() - y0);
  }
  if (meet != Meet::Plain) {
    const auto rep = rig.manager->report();
    if (rep.contains("arrivals")) h.arrivals = rep["arrivals"];
  }
  return h;
}

// No hop where a moving body meets particles: the box driven at 3.5 m/s onto a patch live or
// asleep ahead of it, or with its own patch promoted under it as it goes, gains upward speed
// and height only as the granules' surface does it when it is driven across the middle of a
// patch. A body is carried about 1.6 r higher on granules than on the heightfield: its shell's
// spheres are centred on its surface (r proud of it), and the tops of the fill's granules
// stand some 0.6 r above the surface the fill was cut to (measured: the box rests 0.040 m above
// the heightfield's surface on a patch). Arriving, it is set on the granules in its path
// (coupling.cpp couple_before) and rises to that height without a kick.
// Measured (threads 1): the same box ploughing across the middle of a patch: up to 0.24 m/s
// upward (0.36 m/s in the 12 frames after setting off), rising 0.024 m above where it rested
// there; at the switch 0.45-0.56 m/s upward, its bottom at most 0.069 m above its heightfield
// rest (0.029 m, 0.59 d, above its rest on the granules, onto the asleep patch). Before, its shell started up to a granule
// radius deep in the DEM's terrain grid and the fill: promoted under it +0.90 m/s and 0.066 m
// up, onto a live patch +2.00 m/s and 0.139 m, an asleep one +2.16 m/s and 0.170 m. On the
// plain heightfield: 0.02 m/s.
TEST(Coupling, FastBoxMeetingPatchesDoesNotHop) {
  const double r = test::small_manager_def().material.radius, d = 2.0 * r;  // m
  auto show = [](const char* what, const Hop& h) {
    std::printf("%-20s from frame %2d of %2d: vy max %+.3f m/s (first 12 frames %+.3f), bottom rise %.4f m; rest %+.4f m "
                "above the surface; arrivals %s\n",
                what, h.first, h.frames, h.vy_max, h.vy_start, h.rise, h.rest, h.arrivals.dump().c_str());
  };
  const Hop plain = drive_box(Meet::Plain), ref = drive_box(Meet::OnPatch);
  show("plain heightfield", plain);
  show("across a patch", ref);
  EXPECT_LT(plain.vy_max, 0.1) << "m/s";
  // on the granules: higher than on the heightfield by about 1.6 r
  EXPECT_NEAR(ref.rest, 1.6 * r, 0.5 * r) << "m";
  for (Meet m : {Meet::Promoted, Meet::Ahead, Meet::AheadAsleep}) {
    const Hop h = drive_box(m);
    show(m == Meet::Promoted ? "promoted under it" : m == Meet::Ahead ? "live patch ahead" : "asleep patch ahead", h);
    ASSERT_GE(h.first, 0) << "a patch carried it";
    // upward speed: twice what ploughing the middle of a patch gives at most (before: 0.90-2.16)
    EXPECT_LT(h.vy_max, 2.0 * std::max(ref.vy_max, ref.vy_start)) << "m/s";
    // height: less than 0.75 granule diameter above where the granules hold the box (measured
    // 0.59 d onto the asleep patch since promotions and demotions run one part a frame: the
    // patch ahead is a few frames older when the box meets it; 0.16 d before that)
    EXPECT_LT(h.rise - ref.rest, 0.75 * d) << "m";
    if (m != Meet::Promoted) {
      ASSERT_FALSE(h.arrivals.is_null()) << "set on the patch's ground as it arrived";
      EXPECT_GE(h.arrivals["lifted"].get<int>(), 1);
      EXPECT_LE(h.arrivals["largest_lift_m"].get<double>(), 2.0 * r + 1e-6);
    }
  }
}


// Two spheres landing on two patches at once: with two threads the patches step side by side,
// one thread each (coupling.cpp concurrent_patches), and the world ends in the same state, bit
// for bit, as with one thread stepping them one after the other (the DEM's results do not
// depend on its threads, and the coupling runs in the same order either way).
struct SideBySide {
  std::uint64_t hash = 0;
  int frames_side_by_side = 0, frames_two_patches = 0;
  double step_share = 0;
  std::vector<int> spheres;  // each patch's, at its last step
};
SideBySide two_landings(int threads, float second_radius = 0.1f) {
  SideBySide out;
  test::Rig rig(test::terrain_8m("flat"));
  EXPECT_TRUE(rig.ok()) << rig.error;
  EXPECT_TRUE(rig.add_sphere(0.1f, 5.0f, {2.5, 1.4, 2.5}).ok());
  EXPECT_TRUE(rig.add_sphere(second_radius, 5.0f, {5.5, 1.3 + second_radius, 5.5}).ok());
  TerrainManagerDef def = test::sphere_patch_def();
  def.slots = 2;
  def.threads = threads;
  def.granules_per_slot = 12000;
  EXPECT_TRUE(rig.start(def).ok()) << rig.error;
  for (int f = 0; f < 45; ++f) {
    EXPECT_TRUE(rig.frame().ok()) << rig.error;
    const TerrainManager::FrameWork& w = rig.manager->last_frame_work();
    out.frames_two_patches += w.patches_stepped == 2;
    out.frames_side_by_side += w.side_by_side == 2;
    EXPECT_TRUE(w.side_by_side == 0 || w.side_by_side == w.patches_stepped) << "frame " << f;
  }
  out.hash = rig.core->state_hash();
  const auto report = rig.core->report();  // (named: a loop over a temporary's member would dangle)
  out.step_share = report["dem"]["total"]["step_share_of_frame_stage"].get<double>();
  for (const auto& p : report["dem"]["patches"]) out.spheres.push_back(p["spheres"].get<int>());
  return out;
}

TEST(Coupling, TwoPatchesStepSideBySideToTheSameState) {
  const SideBySide one = two_landings(1), two = two_landings(2);
  std::printf("frames stepping two patches %d; side by side with two threads %d, with one %d; share of the dem stage %.3f / %.3f\n",
              two.frames_two_patches, two.frames_side_by_side, one.frames_side_by_side, two.step_share, one.step_share);
  EXPECT_GT(two.frames_two_patches, 20) << "both patches live for most of the run";
  EXPECT_EQ(two.frames_side_by_side, two.frames_two_patches) << "two equal patches on two threads step side by side";
  EXPECT_EQ(one.frames_side_by_side, 0) << "one thread steps them one after the other";
  EXPECT_EQ(one.hash, two.hash);
  // the patches' shares of the section add up to its wall time: within the frame's dem stage
  EXPECT_GT(two.step_share, 0.0);
  EXPECT_LE(two.step_share, 1.0);
}

// The second sphere 0.5 m across instead: its patch is more than 2.2 times the first's, so on
// two threads one after another (each on both) is predicted shorter than side by side (the
// larger on one thread): they step one after the other, to the same state.
TEST(Coupling, UnequalPatchesStepOneAfterAnother) {
  const SideBySide one = two_landings(1, 0.5f), two = two_landings(2, 0.5f);
  ASSERT_EQ(two.spheres.size(), 2u);
  const int small = std::min(two.spheres[0], two.spheres[1]), large = std::max(two.spheres[0], two.spheres[1]);
  std::printf("patches of %d and %d spheres: frames stepping both %d, side by side %d\n", small, large,
              two.frames_two_patches, two.frames_side_by_side);
  EXPECT_GT(large, 2.2 * small) << "spheres of the larger patch against the smaller";
  EXPECT_GT(two.frames_two_patches, 20);
  EXPECT_EQ(two.frames_side_by_side, 0);
  EXPECT_EQ(one.hash, two.hash);
}

}  // namespace
}  // namespace sandpatch
