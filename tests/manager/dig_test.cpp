// Dig, carry, deposit (docs/manager.md "Tools on a planned path"): a kinematic bucket on
// keyframes digs into a small patch, carries what it scooped a metre in the air and pours it
// out; the planned path makes one patch over the whole cycle (planning.cpp plan_path).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "manager/world.hpp"
#include "scene/mesh.hpp"
#include "tests/manager/rig.hpp"

namespace sandpatch {
namespace {

// The shipped bucket (scenes/meshes/bucket.obj, open at +x): 0.64 m wide and long, 0.48 m
// high, walls 8 cm thick, centred on its centroid (as the scene loader does).
RigidBodyDef bucket_body() {
  RigidBodyDef b;
  b.name = "bucket";
  b.motion = RigidMotion::Kinematic;
  b.shape.kind = RigidShapeKind::Mesh;
  auto mesh = load_obj_mesh(std::string(SANDPATCH_SOURCE_DIR) + "/scenes/meshes/bucket.obj");
  EXPECT_TRUE(mesh.ok()) << (mesh.ok() ? "" : mesh.message());
  if (!mesh.ok()) return b;
  const Eigen::Vector3f c = mesh->centroid().cast<float>();
  for (const auto& v : mesh->vertices) b.shape.vertices.push_back(v - c);
  b.shape.triangles = mesh->triangles;
  b.position = {1.0, 0.85, 1.0};
  return b;
}

World::Keyframe key(double t, double x, double y, double curl_deg) {
  World::Keyframe k;
  k.t = t;
  k.position = {x, y, 1.0};
  k.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(curl_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  return k;
}

// The cycle: down cutting-edge first at x = 1.0 m, a 0.5 m drag 22 cm deep, a quarter-turn
// curl, a lift, 0.9 m carried at 1.05 m (0.2-0.3 m above the surface), mouth down at x = 3.1 m,
// then lifted away.
std::vector<World::Keyframe> cycle() {
  return {key(0.0, 1.0, 0.85, -20), key(0.6, 1.2, 0.62, -20), key(1.3, 1.5, 0.52, 0),
          key(2.3, 2.0, 0.52, 0),   key(3.1, 2.2, 0.75, 90),  key(3.5, 2.2, 1.05, 90),
          key(4.3, 3.1, 1.05, 90),  key(4.7, 3.1, 1.05, 0),   key(5.1, 3.1, 1.05, -90),
          key(5.9, 3.1, 1.05, -90), key(6.3, 3.1, 1.90, -90)};
}

// The bucket cycles' manager: 4 cm granules, 6,000 a slot, a 0.4 m deep patch on 0.8 m of
// soil, a 0.3 m apron, one thread.
TerrainManagerDef bucket_def() {
  TerrainManagerDef def = test::small_manager_def();
  def.material.radius = 0.04f;
  def.granules_per_slot = 6000;
  def.patch_depth = 0.4;
  def.soil_depth = 0.8;
  def.lod.apron = 0.3;
  def.threads = 1;
  return def;
}

// The heightfield's samples (row by row), to compare with after a cycle.
std::vector<float> heights(const Heightfield& hf) {
  std::vector<float> h(std::size_t(hf.samples_x()) * hf.samples_z());
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i) h[std::size_t(j) * hf.samples_x() + i] = hf.height(i, j);
  return h;
}

// Soil volume (m³) between the heightfield now and `before` over the samples with x in
// [x0, x1] (m, world; the terrain's origin is 0): the part above (`above` true) or below it.
double volume_change(const Heightfield& hf, const std::vector<float>& before, double x0, double x1, bool above) {
  double v = 0;
  const double sp = hf.spacing();
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i) {
      const double x = i * sp;
      if (x < x0 || x > x1) continue;
      const double d = hf.height(i, j) - before[std::size_t(j) * hf.samples_x() + i];
      if (above ? d > 0 : d < 0) v += std::abs(d) * sp * sp;
    }
  return v;
}

// Flat sand 4.5 m x 2 m (surface y = 0.5 m), granules of r = 4 cm. The bucket comes down at
// x = 1.0-1.5 m, drags 0.5 m at 0.5 m/s with its bottom 22 cm deep, curls a quarter turn
// (mouth up), lifts, carries 0.9 m in the air, turns mouth down at x = 3.1 m and pours, then
// lifts away out of reach; 6.5 s. Asserted: one patch for the whole cycle (no patch asked for
// ahead, none released), the bucket carries soil in the air (its weight on the bucket), the
// trench and the pile in the heightfield where they were made, at least the carried soil in
// the pile, and the patch's ledger within 1 %: the render alone gains volume (the pile rests
// looser than the bed it was dug from, and renders higher), and the demotion cuts the rise to
// what its granules fill at the tile's packing (docs/manager.md "The volume ledger").
TEST(Dig, BucketDigsCarriesAndDepositsInOnePatch) {
  test::Rig rig(test::flat_terrain(46, 0.1f, 0.5f));
  ASSERT_TRUE(rig.ok()) << rig.error;
  auto bucket = rig.core->add_body(bucket_body());
  ASSERT_TRUE(bucket.ok()) << bucket.message();
  std::vector<World::Keyframe> keys = cycle();
  ASSERT_TRUE(rig.core->set_keyframes(0, keys).ok());
  ASSERT_TRUE(rig.start(bucket_def()).ok()) << rig.error;
  const std::vector<float> before = heights(rig.hf());

  // Carried: the soil's mean vertical force on the bucket while it is in the air (t in
  // [3.6, 4.2] s: lifted and carrying, before it turns).
  double carried_n = 0;
  int carried_frames = 0;
  ASSERT_TRUE(rig.frames(int(std::lround(6.5 / rig.dt)), [&] {
                   const double t = rig.t();
                   if (t > 3.6 && t < 4.2) {
                     carried_n += -rig.core->soil_force(*bucket).force.y();
                     ++carried_frames;
                   }
                   return false;
                 }).ok())
      << rig.error;
  // The granules above the original surface (the pile, the spill ahead of the trench): their
  // spheres' volume, before the patch turns back into heightfield.
  std::vector<float> xyzr;
  rig.manager->particles(xyzr);
  double above_spheres = 0;  // m³, sum of sphere volumes (the tile's packing fraction counts the same)
  for (std::size_t k = 0; k + 3 < xyzr.size(); k += 4)
    if (xyzr[k + 1] > 0.5f) above_spheres += 4.0 / 3.0 * M_PI * std::pow(double(xyzr[k + 3]), 3);
  ASSERT_TRUE(rig.demote_all().ok()) << rig.error;
  const double carried_kg = carried_n / std::max(carried_frames, 1) / 9.81;

  const auto report = rig.manager->report();
  EXPECT_EQ(test::count_events(*rig.manager, PatchEventKind::Promoted), 1);
  EXPECT_EQ(report["pool"]["extensions"].get<int>(), 0);
  EXPECT_EQ(report["pool"]["released"].get<int>(), 0);
  ASSERT_EQ(report["ledger"]["patches"].size(), 1u);
  const double ledger_pct = report["ledger"]["patches"][0]["error_pct"].get<double>();
  const double dug = volume_change(rig.hf(), before, 0.5, 2.3, false);     // m³, the trench
  const double pile = volume_change(rig.hf(), before, 2.7, 3.6, true);     // m³, where it was poured
  const double between = volume_change(rig.hf(), before, 2.3, 2.7, true);  // m³
  // The carried soil's bulk volume at the pre-settled tile's density (granule mass over the
  // volume the ledger's fill counts per granule).
  const double tile_bulk = report["tile"]["packing_fraction"].get<double>();
  const double before_m3 = report["ledger"]["patches"][0]["volume_before_m3"].get<double>();
  const double after_m3 = report["ledger"]["patches"][0]["volume_after_m3"].get<double>();
  const double above_all = volume_change(rig.hf(), before, -1.0, 10.0, true);  // m³ risen anywhere
  // Dilation: the risen soil's volume as rendered, less what its granules fill at the tile's
  // packing (the trench gave them up at that packing).
  const double dilation = above_all - above_spheres / tile_bulk;
  const double closed_pct = 100.0 * (after_m3 - before_m3 - dilation) / before_m3;
  std::printf("risen %.4f m3 holding %.4f m3 of spheres: solid fraction %.3f (tile %.3f), dilation %.4f m3; ledger less dilation %.3f %%\n",
              above_all, above_spheres, above_spheres / above_all, tile_bulk, dilation, closed_pct);
  std::printf("granules %d; carried %.1f kg; trench %.4f m3, pile %.4f m3, between %.4f m3; ledger %.3f %%; tile packing %.3f\n", report["ledger"]["patches"][0]["granules"].get<int>(), carried_kg,
              dug, pile, between, ledger_pct, tile_bulk);
  EXPECT_GT(carried_kg, 30.0);  // soil in the bucket in the air (measured 57 kg)
  EXPECT_GT(dug, 0.08);         // the trench (measured 0.131 m³)
  // The pile where it was poured holds at least the carried soil at the tile's packing
  // (measured 0.107 m³ for 57 kg: 0.040 m³ at the tile's packing; some of the soil pushed
  // ahead of the bucket spilled there too).
  const double granule_density = 2650.0;  // kg/m³ (the default material), of the spheres' volume
  EXPECT_GT(pile, carried_kg / (granule_density * tile_bulk));
  // The ledger over the cycle closes within 1 % (measured 0.000 %), and within 1 % less what
  // the risen soil still holds above its granules at the tile's packing (measured -0.36 %).
  // The render alone gained volume (the loose pile; measured +1.8 %), and the demotion cut the
  // rise to the granules' packing: the risen soil's solid fraction is the tile's within 15 %
  // (measured 0.528 against 0.583; 0.380 as rendered).
  const auto& l = report["ledger"]["patches"][0];
  const auto& t = l["terms"];
  std::printf("report: rendered %+.2f %%, rise at packing %+.2f %%, spread %+.2f %%; risen %.4f m3, solid fraction %.3f, "
              "dilation %.4f m3, ledger less dilation %.3f %%\n",
              t["rendered_pct"].get<double>(), t["rise_at_packing_pct"].get<double>(), t["conserved_pct"].get<double>(),
              l["risen_m3"].get<double>(), l["risen_solid_fraction"].get<double>(), l["dilation_m3"].get<double>(),
              l["error_less_dilation_pct"].get<double>());
  EXPECT_LT(std::abs(ledger_pct), 1.0);
  EXPECT_LT(std::abs(closed_pct), 1.0);
  EXPECT_GT(t["rendered_pct"].get<double>(), 0.0);
  EXPECT_LT(t["rise_at_packing_pct"].get<double>(), 0.0);
  EXPECT_NEAR(above_spheres / above_all, tile_bulk, 0.15 * tile_bulk);
  // The report's ledger makes the same split (demotion_ledger.cpp close_ledger).
  EXPECT_NEAR(l["risen_solid_fraction"].get<double>(), above_spheres / above_all, 0.02);
  EXPECT_LT(std::abs(l["error_less_dilation_pct"].get<double>()), 1.0);
}

// A stretch of path more than a slot holds is not asked for: the bucket is followed by the
// ballistic prediction instead (patches around it, asked for ahead of it), and the report says
// so (planned_paths[].too_big_frames, which `sandpatch run` turns into a warning), rather than
// the run failing or the carried soil being dropped without a word.
TEST(Dig, AStretchTooBigForASlotIsReportedAndFollowedByPatchesAhead) {
  test::Rig rig(test::flat_terrain(46, 0.1f, 0.5f));
  ASSERT_TRUE(rig.ok()) << rig.error;
  auto bucket = rig.core->add_body(bucket_body());
  ASSERT_TRUE(bucket.ok()) << bucket.message();
  ASSERT_TRUE(rig.core->set_keyframes(0, cycle()).ok());
  TerrainManagerDef def = test::small_manager_def();
  def.material.radius = 0.04f;
  def.granules_per_slot = 1000;  // the stretch needs about 1,800; one ballistic request fits
  def.patch_depth = 0.4;
  def.soil_depth = 0.8;
  def.lod.apron = 0.3;
  def.threads = 1;
  ASSERT_TRUE(rig.start(def).ok()) << rig.error;
  ASSERT_TRUE(rig.frames(int(std::lround(1.0 / rig.dt))).ok()) << rig.error;
  const auto report = rig.manager->report();
  ASSERT_TRUE(report.contains("planned_paths")) << report.dump(2);
  const auto& p = report["planned_paths"][0];
  EXPECT_EQ(p["body"].get<std::string>(), "bucket");
  EXPECT_GT(p["too_big_frames"].get<long long>(), 0);
  EXPECT_EQ(p["asked_frames"].get<long long>(), 0);
  EXPECT_GT(p["granules_predicted"].get<int>(), 1000);
  EXPECT_EQ(test::count_events(*rig.manager, PatchEventKind::Promoted), 1);  // the ballistic one
}

// A blade pushing soil into a berm (scenes/blade_berm.json, smaller): a kinematic box blade
// 0.6 m wide, 0.3 m tall, 8 cm thick comes down at x = 1.0 m, cuts 12 cm into flat sand of
// 4 cm granules, pushes 1.0 m along +x at 0.5 m/s and lifts straight up; 4.5 s. Asserted: one
// patch over the planned path; the cut behind the blade's end and the berm in front of it in
// the heightfield; the berm holds the cut's soil (volume and ledger below).
TEST(Dig, BladePushesTheCutIntoABermAheadOfItsEnd) {
  test::Rig rig(test::flat_terrain(41, 0.1f, 0.5f));
  ASSERT_TRUE(rig.ok()) << rig.error;
  RigidBodyDef blade;
  blade.name = "blade";
  blade.motion = RigidMotion::Kinematic;
  blade.shape.kind = RigidShapeKind::Box;
  blade.shape.half_extents = {0.04f, 0.15f, 0.3f};
  blade.position = {1.0, 0.9, 2.0};
  auto id = rig.core->add_body(blade);
  ASSERT_TRUE(id.ok()) << id.message();
  const double x_end = 2.0, y_cut = 0.5 - 0.12 + 0.15;  // m: the blade's centre at the end of the push, its bottom 12 cm deep
  auto at = [](double t, double x, double y) {
    World::Keyframe k;
    k.t = t;
    k.position = {x, y, 2.0};
    return k;
  };
  ASSERT_TRUE(rig.core->set_keyframes(0, {at(0.0, 1.0, 0.9), at(0.6, 1.0, y_cut), at(2.6, x_end, y_cut), at(3.2, x_end, 1.4)}).ok());
  TerrainManagerDef def = bucket_def();  // (a shallower patch)
  def.patch_depth = 0.3;
  def.soil_depth = 0.6;
  ASSERT_TRUE(rig.start(def).ok()) << rig.error;
  const Heightfield& hf = rig.hf();
  const std::vector<float> before = heights(hf);
  ASSERT_TRUE(rig.frames(int(std::lround(4.5 / rig.dt))).ok()) << rig.error;
  ASSERT_TRUE(rig.demote_all().ok()) << rig.error;

  const auto report = rig.manager->report();
  EXPECT_EQ(test::count_events(*rig.manager, PatchEventKind::Promoted), 1);
  ASSERT_EQ(report["ledger"]["patches"].size(), 1u);
  const auto& l = report["ledger"]["patches"][0];
  const double cut = volume_change(rig.hf(), before, -1.0, 10.0, false);   // m³ below the old surface
  const double berm = volume_change(rig.hf(), before, -1.0, 10.0, true);   // m³ above it
  const double cut_behind = volume_change(rig.hf(), before, -1.0, x_end, false);
  // the berm's centre along x (volume-weighted) and its part ahead of the blade's end
  double mx = 0, ahead = 0;
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i) {
      const double d = hf.height(i, j) - before[std::size_t(j) * hf.samples_x() + i];
      if (d <= 0) continue;
      const double x = i * hf.spacing(), v = d * hf.spacing() * hf.spacing();
      mx += x * v;
      if (x > x_end) ahead += v;
    }
  mx /= std::max(berm, 1e-12);
  const double dilation = l["dilation_m3"].get<double>();
  std::printf("granules %d; cut %.4f m3 (%.4f behind the blade's end), berm %.4f m3 (%.4f ahead of x = %.1f m, centre x = %.2f m); "
              "dilation %.4f m3; berm less dilation / cut %.3f; ledger %.3f %%, less dilation %.3f %%\n",
              l["granules"].get<int>(), cut, cut_behind, berm, ahead, x_end, mx, dilation, (berm - dilation) / cut,
              l["error_pct"].get<double>(), l["error_less_dilation_pct"].get<double>());
  EXPECT_GT(cut, 0.04);                  // 1 m x 0.6 m x 12 cm = 0.072 m³ cut by the blade's face
  EXPECT_GT(cut_behind, 0.8 * cut);      // the cut is behind where the blade stopped
  EXPECT_GT(mx, x_end + 0.04);           // the berm is in front of it (the blade's front face)
  EXPECT_GT(ahead, 0.6 * berm);
  // The berm holds the cut's soil at the tile's packing (the demotion cuts the rendered rise,
  // looser, to its granules at that packing: docs/manager.md "The volume ledger"): its volume
  // is the cut's within 15 % (measured 1.00), and so is the berm less the report's remaining
  // dilation (measured 0.92). The ledger over the push within 1 %
  // (measured 0.000 %).
  EXPECT_NEAR(berm / cut, 1.0, 0.15);
  EXPECT_NEAR((berm - dilation) / cut, 1.0, 0.15);
  EXPECT_LT(std::abs(l["error_pct"].get<double>()), 1.0);
}

// Soil lifted out of the patch (docs/manager.md "Carrying soil up"): the shipped bucket digs
// 0.4 m, curls mouth up and lifts its load to 0.7 m above the sand (its lowest point), where
// the patch still carries it (its shell is let go of only above carry_height, 1 m, the top
// of the DEM's domain: before, at 0.5 m, and the soil fell without a word), then to 1.6 m,
// where it is let go of and the soil falls back into the patch: reported (an event naming the
// bucket, its height, the limit, the granules and their volume; the report's soil_dropped and
// warnings). The ledger closes within 1 % either way.
TEST(Dig, SoilLiftedAboveTheCarryHeightIsReportedAndTheLedgerCloses) {
  test::Rig rig(test::flat_terrain(46, 0.1f, 0.5f));
  ASSERT_TRUE(rig.ok()) << rig.error;
  auto bucket = rig.core->add_body(bucket_body());
  ASSERT_TRUE(bucket.ok()) << bucket.message();
  // down at x = 1.0 m, a 0.4 m drag 22 cm deep, curl mouth up; lift to y = 1.5 m (its lowest
  // point about 0.7 m above the sand), hold; lift to y = 2.4 m (about 1.6 m above), hold
  const std::vector<World::Keyframe> keys = {key(0.0, 1.0, 0.85, -20), key(0.6, 1.2, 0.62, -20), key(1.3, 1.5, 0.52, 0),
                                             key(1.9, 1.8, 0.52, 0),   key(2.5, 1.9, 0.75, 90),  key(3.0, 1.9, 1.5, 90),
                                             key(3.8, 1.9, 1.5, 90),   key(4.2, 1.9, 2.4, 90)};
  ASSERT_TRUE(rig.core->set_keyframes(0, keys).ok());
  ASSERT_TRUE(rig.start(bucket_def()).ok()) << rig.error;
  double carried_n = 0, lowest = 0;
  int carried_frames = 0;
  ASSERT_TRUE(rig.frames(int(std::lround(5.0 / rig.dt)), [&] {
                   const double t = rig.t();
                   if (t > 3.2 && t < 3.8) {  // held 0.7 m up
                     carried_n += -rig.core->soil_force(*bucket).force.y();
                     lowest = rig.core->lowest_point(*bucket);
                     ++carried_frames;
                   }
                   return false;
                 }).ok())
      << rig.error;
  ASSERT_TRUE(rig.demote_all().ok()) << rig.error;
  const double carried_kg = carried_n / std::max(carried_frames, 1) / 9.81;
  int drops = 0;
  PatchEvent drop{};
  for (const PatchEvent& e : rig.manager->events())
    if (e.kind == PatchEventKind::SoilDropped) ++drops, drop = e;
  const auto report = rig.core->report();
  std::printf("held %.2f m above the sand: %.1f kg carried; dropped %d time(s): %d granules, %.4f m3 at %.2f m (limit %.1f m) at %.2f s\n",
              lowest - 0.5, carried_kg, drops, drop.granules, drop.volume, drop.value, drop.limit, drop.time);
  EXPECT_GT(lowest - 0.5, 0.6);  // above the old engage limit (0.5 m)
  EXPECT_GT(carried_kg, 20.0);   // its soil still in it
  ASSERT_EQ(drops, 1);
  EXPECT_EQ(drop.body, "bucket");
  EXPECT_GT(drop.value, 1.0);
  EXPECT_NEAR(drop.limit, 1.0, 1e-12);
  EXPECT_GT(drop.granules, 10);
  // its volume: the granules at the tile's packing
  const double pf = report["tile"]["packing_fraction"].get<double>();
  EXPECT_NEAR(drop.volume, drop.granules * 4.0 * 4.0 / 3.0 * M_PI * std::pow(0.04, 3) / pf, 1e-6 * drop.volume);
  ASSERT_TRUE(report.contains("soil_dropped")) << report.dump(2);
  EXPECT_EQ(report["soil_dropped"][0]["granules"].get<int>(), drop.granules);
  EXPECT_NE(report["warnings"].dump().find("bodies.bucket: let go of"), std::string::npos) << report["warnings"].dump();
  ASSERT_EQ(report["ledger"]["patches"].size(), 1u);
  std::printf("ledger %.3f %%\n", report["ledger"]["patches"][0]["error_pct"].get<double>());
  EXPECT_LT(std::abs(report["ledger"]["patches"][0]["error_pct"].get<double>()), 1.0);
}

// The same cycle carried high: lifted to 0.8 m above the sand (the bucket's lowest point;
// below carry_height, 1 m, where a patch still carries a tool's soil), carried 0.9 m, lowered
// to 0.3 m and poured. The stretch of path that works the ground runs on through the carry
// while the tool stays within carry_height of the ground after it has worked it, so the dig,
// the carry and the pour are one patch and the soil is poured where the path pours it. Before,
// the stretch ended where the bucket rose past engage_height / 2 (0.5 m): the pour was a second
// stretch and a second patch, and the soil fell where the bucket left the first one's side.
TEST(Dig, ACarryBelowTheCarryHeightStaysInOnePatch) {
  test::Rig rig(test::flat_terrain(91, 0.1f, 0.5f));  // 9 m square, room to carry 3 m
  ASSERT_TRUE(rig.ok()) << rig.error;
  auto bucket = rig.core->add_body(bucket_body());
  ASSERT_TRUE(bucket.ok()) << bucket.message();
  const std::vector<World::Keyframe> keys = {
      key(0.0, 1.0, 0.85, -20), key(0.6, 1.2, 0.62, -20), key(1.3, 1.5, 0.52, 0), key(2.3, 2.0, 0.52, 0),
      key(3.1, 2.2, 0.75, 90),  key(3.7, 2.2, 1.55, 90),  key(5.3, 5.0, 1.55, 90), key(5.9, 5.0, 1.05, 90),
      key(6.3, 5.0, 1.05, 0),   key(6.7, 5.0, 1.05, -90), key(7.5, 5.0, 1.05, -90), key(7.9, 5.0, 1.90, -90)};
  ASSERT_TRUE(rig.core->set_keyframes(0, keys).ok());
  ASSERT_TRUE(rig.start(bucket_def()).ok()) << rig.error;
  const std::vector<float> before = heights(rig.hf());
  double carried_n = 0;
  int carried_frames = 0;
  ASSERT_TRUE(rig.frames(int(std::lround(8.1 / rig.dt)), [&] {
                   const double t = rig.t();
                   if (t > 3.8 && t < 5.2) {  // high in the air, carrying
                     carried_n += -rig.core->soil_force(*bucket).force.y();
                     ++carried_frames;
                   }
                   return false;
                 }).ok())
      << rig.error;
  ASSERT_TRUE(rig.demote_all().ok()) << rig.error;
  const auto report = rig.manager->report();
  const double carried_kg = carried_n / std::max(carried_frames, 1) / 9.81;
  const double pile = volume_change(rig.hf(), before, 4.6, 5.5, true);  // m³, where it was poured
  std::printf("carried high: %.1f kg in the air; %d patch(es); soil dropped %zu time(s); pile %.4f m3; ledger %.3f %%\n",
              carried_kg, test::count_events(*rig.manager, PatchEventKind::Promoted),
              report.contains("soil_dropped") ? report["soil_dropped"].size() : std::size_t(0), pile,
              report["ledger"]["total"]["error_pct"].get<double>());
  EXPECT_EQ(test::count_events(*rig.manager, PatchEventKind::Promoted), 1);
  EXPECT_EQ(test::count_events(*rig.manager, PatchEventKind::SoilDropped), 0);
  EXPECT_GT(carried_kg, 30.0);  // soil in the bucket high in the air
  EXPECT_GT(pile, carried_kg / (2650.0 * report["tile"]["packing_fraction"].get<double>()));  // poured where the path pours
  EXPECT_LT(std::abs(report["ledger"]["total"]["error_pct"].get<double>()), 1.0);
}

}  // namespace
}  // namespace sandpatch
