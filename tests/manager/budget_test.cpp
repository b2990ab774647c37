// The frame budget (manager/budget.cpp): what it chooses for a new patch, what it reports, and
// that a budget with room to spare changes nothing. Choices that depend on a machine's speed
// are tested with the cost model pinned (TerrainManagerDef::budget_substep_ms / _sphere_ns),
// so they are the same on every machine and under any load.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "manager/terrain_manager.hpp"
#include "tests/manager/rig.hpp"

namespace sandpatch {
namespace {

using ojson = nlohmann::ordered_json;

// The small sphere's patch on the 8 m flat terrain, with one frame at 1/60 s.
TerrainManagerDef budget_def(double budget_ms) {
  TerrainManagerDef d = test::sphere_patch_def();
  d.granules_per_slot = 12000;
  d.lod.apron = 0.6;  // a patch of some size: the coarser rungs' tile periods are wider
  d.frame_budget_ms = budget_ms;
  d.budget_substep_ms = 0.01;  // pinned: 10 µs a substep ...
  d.budget_sphere_ns = 100;    // ... and 100 ns a sphere-substep
  return d;
}

// A 0.1 m sphere dropped from 0.3 m onto the flat sand at (4, 4); the final world hash and
// the manager's report after `frames` frames and demote_all.
struct Drop {
  std::uint64_t hash = 0;
  ojson report;
  std::string error;
};
// (`radius`: the sphere's, m; it is named "sphere")
Drop drop(const TerrainManagerDef& def, int frames, float radius = 0.1f) {
  Drop d;
  test::Rig rig(test::terrain_8m("flat"));
  if (!rig.ok()) return {0, {}, rig.error};
  RigidBodyDef body = test::sphere_body(radius, 5.0f, {4.0, 1.0 + radius + 0.3, 4.0});
  body.name = "sphere";
  if (!rig.core->add_body(body).ok()) return {0, {}, "add_body"};
  if (!rig.start(def).ok() || !rig.frames(frames).ok() || !rig.demote_all().ok()) return {0, {}, rig.error};
  d.hash = rig.core->state_hash();
  d.report = rig.manager->report();
  return d;
}

// With room to spare the budget chooses what no budget would (rung 0: the requested scale and
// apron) and the run is bit-for-bit the same: its calibration leaves nothing in the slot.
TEST(Budget, AGenerousBudgetChangesNothing) {
  const Drop off = drop(test::sphere_patch_def(), 40);
  ASSERT_TRUE(off.error.empty()) << off.error;
  TerrainManagerDef d = test::sphere_patch_def();
  d.frame_budget_ms = 1e5;  // measured cost model (calibrated at creation)
  const Drop on = drop(d, 40);
  ASSERT_TRUE(on.error.empty()) << on.error;
  EXPECT_FALSE(off.report["budget"]["on"].get<bool>());
  EXPECT_TRUE(on.report["budget"]["on"].get<bool>());
  ASSERT_GE(on.report["budget"]["patches"].size(), 1u);
  for (const auto& p : on.report["budget"]["patches"]) {
    EXPECT_EQ(p["rung"].get<int>(), 0);
    EXPECT_TRUE(p["fits"].get<bool>());
    EXPECT_EQ(p["particle_scale"].get<double>(), 1.0);
  }
  EXPECT_EQ(on.report["budget"]["patches_degraded"].get<int>(), 0);
  EXPECT_EQ(on.hash, off.hash) << "a budget with room to spare must not change the run";
}

// A tight budget: the patch is promoted at the finest rung whose predicted DEM cost fits 80 %
// of the budget, and the prediction is the cost model's formula; every finer rung did not fit.
TEST(Budget, ATightBudgetCoarsensTheNewPatchUntilItFits) {
  // What the requested patch costs, from the report of a run without a budget: its granules.
  TerrainManagerDef no_budget = budget_def(1.0);
  no_budget.frame_budget_ms = std::numeric_limits<double>::infinity();
  const Drop off = drop(no_budget, 2);
  ASSERT_TRUE(off.error.empty()) << off.error;
  const TerrainManagerDef d = budget_def(5.0);
  const Drop on = drop(d, 2);
  ASSERT_TRUE(on.error.empty()) << on.error;
  const auto& b = on.report["budget"];
  ASSERT_EQ(b["patches"].size(), 1u) << b.dump(1);
  const auto& p = b["patches"][0];
  // The sphere's r = 2.5 cm granules at 1/60 s frames; the substeps the DEM takes come from
  // the material, so the prediction is checked against what a frame of these spheres costs.
  const double spheres = 4.0 * p["granules_predicted"].get<double>();
  const double per_substep = d.budget_substep_ms + d.budget_sphere_ns * 1e-6 * spheres;
  const double substeps = p["predicted_ms"].get<double>() / per_substep;
  EXPECT_NEAR(substeps, std::round(substeps), 1e-6) << "predicted = n_sub (a + b spheres), n_sub whole";
  EXPECT_GE(std::round(substeps), 1.0);
  EXPECT_NEAR(p["available_ms"].get<double>(), 0.8 * 5.0, 1e-12) << "80 % of the budget, nothing else live";
  EXPECT_TRUE(p["fits"].get<bool>());
  EXPECT_LE(p["predicted_ms"].get<double>(), p["available_ms"].get<double>());
  EXPECT_GT(p["rung"].get<int>(), 0) << "5 ms cannot hold the requested patch of " << off.report["ledger"]["patches"][0]["granules"];
  EXPECT_EQ(b["patches_degraded"].get<int>(), 1);
  EXPECT_EQ(b["overruns"].get<int>(), 0);
  // The granules it predicted are the ones it filled, within 25 % (the soil volume at the tile's
  // packing against the tile's own granules cut to the surface, less those a body displaces).
  EXPECT_NEAR(p["granules"].get<double>(), p["granules_predicted"].get<double>(), 0.25 * p["granules_predicted"].get<double>());
}

// Nothing fits and nothing else is live: the patch still comes (at the coarsest rung) and the
// report counts the overrun with the milliseconds it needed, never a silent stall. (A 0.2 m
// sphere: 0.4 m across, it allows scale 3 of these 2.5 cm granules.)
TEST(Budget, NothingFitsIsReportedWithTheCostItNeeded) {
  const Drop on = drop(budget_def(0.001), 2, 0.2f);
  ASSERT_TRUE(on.error.empty()) << on.error;
  const auto& b = on.report["budget"];
  ASSERT_EQ(b["patches"].size(), 1u);
  EXPECT_FALSE(b["patches"][0]["fits"].get<bool>());
  EXPECT_EQ(b["overruns"].get<int>(), 1);
  EXPECT_GT(b["patches"][0]["predicted_ms"].get<double>(), b["patches"][0]["available_ms"].get<double>());
  EXPECT_EQ(b["patches"][0]["rung"].get<int>(), 4) << "the coarsest rung";
}

// The particle-scale cap: a body of smallest dimension D never gets a patch whose granules
// (bounding diameter 2 (1 + sqrt(3/2)) r s) are wider than D / 0.9, however tight the budget,
// unless it asked for that scale itself; the report names the body and its size.
TEST(Budget, ABodyCapsTheParticleScale) {
  const double r = 0.025;                                   // m, the rig's granule radius
  const double diameter1 = 2.0 * (1.0 + std::sqrt(1.5)) * r;  // m, a granule at scale 1
  const double n = 0.9;                                     // granule diameters a body keeps across
  for (float radius : {0.05f, 0.08f, 0.11f, 0.2f}) {
    const Drop on = drop(budget_def(0.001), 2, radius);  // nothing fits: the coarsest it may
    ASSERT_TRUE(on.error.empty()) << on.error;
    const auto& b = on.report["budget"];
    ASSERT_EQ(b["patches"].size(), 1u) << b.dump(1);
    const auto& p = b["patches"][0];
    const double size = 2.0 * radius, s = p["particle_scale"].get<double>();
    EXPECT_NEAR(p["capped_by"]["smallest_dimension_m"].get<double>(), size, 1e-6) << p.dump();
    EXPECT_EQ(p["capped_by"]["body"].get<std::string>(), "sphere");
    EXPECT_NEAR(p["body_cap_scale"].get<double>(), size / (n * diameter1), 1e-4) << p.dump();
    EXPECT_TRUE(s == 1.0 || diameter1 * s <= size / n + 1e-9)
        << "a " << size << " m body on granules " << diameter1 * s << " m across (scale " << s << ")";
    std::printf("sphere %.2f m across: scale %g (cap %.2f), rung %d, traded %s\n", size, s, p["body_cap_scale"].get<double>(),
                p["rung"].get<int>(), p["traded"].dump().c_str());
  }
  // 0.1 m across: scale 1 only (cap 1.00); 0.16 m: scale 1.5 (cap 1.60); 0.22 m: scale 2 (cap
  // 2.20); 0.4 m: scale 3, the coarsest rung, the cap not binding.
  EXPECT_EQ(drop(budget_def(0.001), 2, 0.05f).report["budget"]["patches"][0]["particle_scale"].get<double>(), 1.0);
  EXPECT_EQ(drop(budget_def(0.001), 2, 0.08f).report["budget"]["patches"][0]["particle_scale"].get<double>(), 1.5);
  EXPECT_EQ(drop(budget_def(0.001), 2, 0.11f).report["budget"]["patches"][0]["particle_scale"].get<double>(), 2.0);
  const ojson big = drop(budget_def(0.001), 2, 0.2f).report["budget"]["patches"][0];
  EXPECT_EQ(big["particle_scale"].get<double>(), 3.0);
  EXPECT_FALSE(big["cap_bound"].get<bool>());
  EXPECT_TRUE(big["traded"].empty());
}

// When the cap bars the coarser scales, the budget trades the apron (down to 4 r s, the margin
// at which a patch ahead would be asked for), then half the DEM's substeps (N 20 -> 10), and
// says so: `traded`, the rung, the apron used and the N the patch runs at, which its DEM report
// shows as half the substeps of the same patch without the trades.
TEST(Budget, WhatTheCapBarsTheBudgetTradesAndReports) {
  const Drop on = drop(budget_def(0.001), 2, 0.11f);
  ASSERT_TRUE(on.error.empty()) << on.error;
  const auto& p = on.report["budget"]["patches"][0];
  EXPECT_TRUE(p["cap_bound"].get<bool>()) << p.dump();
  EXPECT_EQ(p["particle_scale"].get<double>(), 2.0);
  EXPECT_EQ(p["traded"], ojson::array({"apron", "substeps"})) << p.dump();
  EXPECT_EQ(p["rung"].get<int>(), 6);
  EXPECT_NEAR(p["apron_used_m"].get<double>(), 4.0 * 0.025 * 2.0, 1e-6) << "apron 0.6 m trimmed to 4 r s";
  EXPECT_EQ(p["steps_per_contact"].get<int>(), 10);
  EXPECT_FALSE(p["fits"].get<bool>());  // (nothing fits 1 µs: promoted anyway, counted)
  // The same sphere with room for everything: N = 20, the whole apron, nothing traded.
  const Drop wide = drop(budget_def(1e5), 2, 0.11f);
  ASSERT_TRUE(wide.error.empty()) << wide.error;
  const auto& q = wide.report["budget"]["patches"][0];
  EXPECT_EQ(q["steps_per_contact"].get<int>(), 20);
  EXPECT_TRUE(q["traded"].empty());
  EXPECT_EQ(q["apron_used_m"].get<double>(), 0.6);
  const double sub_traded = on.report["dem"]["patches"][0]["substeps_per_frame"].get<double>();
  const double sub_full = wide.report["dem"]["patches"][0]["substeps_per_frame"].get<double>();
  EXPECT_NEAR(sub_traded, 0.5 * sub_full, 1.0) << "half the substeps (rounded up)";
  std::printf("traded %s: substeps per frame %.0f against %.0f, apron %.2f m of 0.6 m\n", p["traded"].dump().c_str(),
              sub_traded, sub_full, p["apron_used_m"].get<double>());
}

// A patch no body wants any more (its sphere was removed while the bed still moved) is held
// by the budget when it does not fit beside the patch under a new body: the new body's patch
// is promoted at the requested scale (the one left behind leaves it the room) and steps every
// frame; the other one waits, at most 30 frames in a row, so it still settles.
TEST(Budget, APatchNoBodyWantsIsHeldWhenItDoesNotFit) {
  // One patch's cost under the pinned model, from a run with all the room it wants.
  const Drop one = drop(budget_def(1e5), 2);
  ASSERT_TRUE(one.error.empty()) << one.error;
  const double one_ms = one.report["budget"]["patches"][0]["predicted_ms"].get<double>();
  test::Rig rig(test::terrain_8m("flat"));
  ASSERT_TRUE(rig.ok()) << rig.error;
  auto first = rig.add_sphere(0.1f, 5.0f, {2.0, 1.0 + 0.1 + 0.3, 4.0});
  ASSERT_TRUE(first.ok());
  TerrainManagerDef d = budget_def(1.5 * one_ms / 0.8);  // room for one such patch, not two
  d.slots = 2;
  d.threads = 1;  // (two OpenMP threads on a busy 2-core machine spin at every barrier)
  ASSERT_TRUE(rig.start(d).ok()) << rig.error;
  ASSERT_TRUE(rig.frames(20).ok()) << rig.error;  // landed: its patch is up and moving
  ASSERT_EQ(rig.manager->report()["budget"]["patches"].size(), 1u);
  rig.core->remove_body(*first);
  // (a removed body stays in Bullet until the next step, 1000 m above where it was: over its
  // patch, which it would still want; the new body comes after it is gone)
  ASSERT_TRUE(rig.frames(1).ok()) << rig.error;
  ASSERT_TRUE(rig.add_sphere(0.1f, 5.0f, {6.0, 1.0 + 0.1 + 0.3, 4.0}).ok());
  // Frame by frame, TerrainManager::patches() says which awake patch did not step (the CSV's
  // `held` rows): as many patch-frames as the budget says it held.
  long long held_seen = 0;
  for (int k = 0; k < 40; ++k) {
    ASSERT_TRUE(rig.frames(1).ok()) << rig.error;
    for (const auto& p : rig.manager->patches()) {
      if (!p.ready || p.asleep) continue;
      held_seen += !p.stepped;
      if (p.stepped) {
        EXPECT_GT(p.last_substeps, 0);
      }
    }
  }
  const ojson b = rig.manager->report()["budget"];
  EXPECT_EQ(held_seen, b["held_patch_frames"].get<long long>());
  ASSERT_EQ(b["patches"].size(), 2u) << b.dump(1);
  EXPECT_EQ(b["patches"][1]["rung"].get<int>(), 0) << "the patch left behind does not take the new one's room";
  EXPECT_GT(b["held_patch_frames"].get<long long>(), 0) << b.dump(1);
  EXPECT_LE(b["longest_hold_frames"].get<int>(), 30);
  // The new body's patch stepped every frame it was awake: its DEM frames are the frames
  // since it was promoted (less the ones it slept, if it did).
  const ojson dem = rig.manager->report()["dem"]["patches"];
  ASSERT_EQ(dem.size(), 2u) << dem.dump(1);
  EXPECT_GT(dem[1]["frames"].get<int>(), dem[0]["frames"].get<int>() - 20)
      << "the wanted patch steps; the one left behind waits";
  std::printf("held %lld patch-frames, longest hold %d frames; frames stepped: left behind %d, new %d\n",
              b["held_patch_frames"].get<long long>(), b["longest_hold_frames"].get<int>(), dem[0]["frames"].get<int>(),
              dem[1]["frames"].get<int>());
}

// Bad budgets are refused naming the field.
TEST(Budget, BadBudgetsAreRefused) {
  for (double v : {0.0, -1.0, std::nan("")}) {
    test::Rig rig(test::terrain_8m("flat"));
    TerrainManagerDef d = test::sphere_patch_def();
    d.frame_budget_ms = v;
    const Status s = rig.start(d);
    ASSERT_FALSE(s.ok()) << v;
    EXPECT_NE(s.message().find("frame_budget_ms"), std::string::npos) << s.message();
  }
  test::Rig rig(test::terrain_8m("flat"));
  TerrainManagerDef d = test::sphere_patch_def();
  d.frame_budget_fraction = -0.5;
  const Status s = rig.start(d);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("frame_budget_fraction"), std::string::npos) << s.message();
}

// The frames section of World's report counts the frames over the budget against the budget
// it states, and the frames with a patch awake.
TEST(Budget, FramesOverBudgetAreCounted) {
  test::Rig rig(test::terrain_8m("flat"));
  ASSERT_TRUE(rig.add_sphere(0.1f, 5.0f, {4.0, 1.0 + 0.1 + 0.3, 4.0}).ok());
  ASSERT_TRUE(rig.start(budget_def(1e-3)).ok()) << rig.error;
  ASSERT_TRUE(rig.frames(20).ok()) << rig.error;
  const ojson f = rig.core->report()["frames"];
  EXPECT_DOUBLE_EQ(f["budget_ms"].get<double>(), 1e-3);
  EXPECT_EQ(f["over_budget"].get<long long>(), 20) << "every frame takes more than 1 µs";
  EXPECT_GT(f["max_over_budget"].get<double>(), 1.0);
  EXPECT_GT(f["patch_awake_frames"].get<long long>(), 0);
  EXPECT_LE(f["patch_awake_frames"].get<long long>(), 20);
}

// A patch asked for ahead of a body that does not fit even at half the substeps (rung 6) is
// promoted anyway (the body must not reach its patch's edge first) and counted as an overrun;
// the patch the body is leaving, made when it fitted at the full N = 20, then takes N = 10 as
// well, so the frames in which the two step together cost what the last rung assumed. A
// 0.1 m sphere (the bodies cap the scale at 1), landed, then driven sideways at 0.4 m/s; the
// budget (pinned cost model) holds the first patch at rung 0 and barely more. (A patch that
// travels with its body replaces the patch it leaves: no two step together; this is the patch
// abutting ahead that a body gets where its patch cannot travel, lod.travel off here.)
TEST(Budget, ALivePatchTakesTheHalvedSubstepsOfAnOverrunningPatchAhead) {
  auto run = [](double budget_ms, std::vector<int>* first_substeps, ojson* report) {
    test::Rig rig(test::terrain_8m("flat"));
    ASSERT_TRUE(rig.ok()) << rig.error;
    auto id = rig.add_sphere(0.05f, 2.0f, {3.0, 1.25, 4.0});
    ASSERT_TRUE(id.ok());
    TerrainManagerDef d = budget_def(budget_ms);
    d.slots = 2;  // the patch it is in and the one ahead
    d.patch_depth = 0.2;
    d.depth_resolution = 256;
    d.lod.apron = 0.2;
    d.lod.travel = false;
    ASSERT_TRUE(rig.start(d).ok()) << rig.error;
    for (int f = 0; f < 200; ++f) {
      if (rig.t() >= 1.0) {  // landed and settled: drive it
        BodyState st = rig.world->state(*id);
        st.linear_velocity = {0.4f, st.linear_velocity.y(), 0.0f};
        rig.world->set_state(*id, st);
      }
      ASSERT_TRUE(rig.frame().ok()) << rig.error;
      for (const auto& p : rig.manager->patches())
        if (p.patch == 0 && p.stepped && first_substeps) first_substeps->push_back(p.last_substeps);
    }
    *report = rig.manager->report();
  };
  // The first patch's cost with room for everything: the budget then holds it and 5 % more.
  ojson wide;
  ASSERT_NO_FATAL_FAILURE(run(1e5, nullptr, &wide));
  ASSERT_GE(wide["budget"]["patches"].size(), 2u) << "a patch is asked for ahead";
  EXPECT_EQ(wide["budget"]["live_substeps_traded"].get<int>(), 0);
  const double one_ms = wide["budget"]["patches"][0]["predicted_ms"].get<double>();
  std::vector<int> substeps;
  ojson rep;
  ASSERT_NO_FATAL_FAILURE(run(1.05 * one_ms / 0.8, &substeps, &rep));
  const ojson& b = rep["budget"];
  ASSERT_GE(b["patches"].size(), 2u) << b.dump(1);
  const ojson& first = b["patches"][0];
  const ojson& ahead = b["patches"][1];
  EXPECT_EQ(first["rung"].get<int>(), 0) << first.dump();
  EXPECT_TRUE(first["fits"].get<bool>());
  EXPECT_FALSE(ahead["fits"].get<bool>()) << ahead.dump();
  EXPECT_EQ(ahead["rung"].get<int>(), 6);
  EXPECT_EQ(ahead["steps_per_contact"].get<int>(), 10);
  EXPECT_EQ(b["live_substeps_traded"].get<int>(), 1);
  EXPECT_EQ(first["traded"], ojson::array({"substeps (live)"})) << first.dump();
  EXPECT_EQ(first["steps_per_contact"].get<int>(), 10);
  EXPECT_DOUBLE_EQ(first["live_trade_s"].get<double>(), ahead["time_s"].get<double>());
  // The first patch's substeps a frame: N = 20's before, half after (rounded up)
  ASSERT_GE(substeps.size(), 2u);
  const int before = substeps.front(), after = substeps.back();
  std::printf("first patch: %d substeps a frame, %d after the patch ahead (%zu frames stepped)\n", before, after, substeps.size());
  EXPECT_NEAR(after, 0.5 * before, 1.0);
}

}  // namespace
}  // namespace sandpatch

namespace sandpatch {
namespace {

// Ten spheres landing at once, each on its own patch, ten slots: the budget promotes what fits
// and the rest wait in the queue (or lapse once their sphere rests on the heightfield); every
// patch promoted fit the budget beside the ones already simulating, with the pinned cost model.
TEST(Budget, TenBodiesLandingAtOnceKeepWithinIt) {
  test::Rig rig(test::terrain_8m("flat"));
  ASSERT_TRUE(rig.ok()) << rig.error;
  for (int k = 0; k < 10; ++k)
    ASSERT_TRUE(rig.add_sphere(0.1f, 5.0f, {1.0 + 1.5 * (k % 5), 1.0 + 0.1 + 0.3, 2.5 + 3.0 * (k / 5)}).ok());
  TerrainManagerDef d = budget_def(20.0);
  d.slots = 10;
  d.lod.apron = 0.2;
  ASSERT_TRUE(rig.start(d).ok()) << rig.error;
  ASSERT_TRUE(rig.frames(40).ok()) << rig.error;
  const ojson b = rig.manager->report()["budget"];
  ASSERT_GE(b["patches"].size(), 2u) << b.dump(1);
  int fitting = 0;
  for (const auto& p : b["patches"]) {
    EXPECT_TRUE(p["fits"].get<bool>()) << p.dump();
    EXPECT_LE(p["predicted_ms"].get<double>(), p["available_ms"].get<double>() + 1e-9) << p.dump();
    fitting += p["fits"].get<bool>();
  }
  EXPECT_EQ(b["overruns"].get<int>(), 0);
  EXPECT_GT(b["waited_request_frames"].get<long long>(), 0) << "some had to wait";
  EXPECT_LT(int(b["patches"].size()), 10) << "not every one fits 20 ms at once";
  // Requests that waited and then lapsed (their sphere came to rest on the heightfield) are
  // listed with the spheres lying in them: what the budget gave up.
  const auto& lapsed = b["lapsed_after_waiting"];
  ASSERT_TRUE(lapsed.is_array());
  EXPECT_LE(int(lapsed.size()), rig.manager->report()["pool"]["lapsed_requests"].get<int>());
  for (const auto& l : lapsed) {
    EXPECT_GT(l["waited_frames"].get<int>(), 0) << l.dump();
    EXPECT_FALSE(l["bodies"].empty()) << l.dump();
  }
  std::printf("%zu requests lapsed after waiting: %s\n", lapsed.size(), lapsed.dump().c_str());
  std::printf("ten bodies, budget 20 ms (pinned model): %d patches promoted, %lld request-frames waited\n", fitting,
              b["waited_request_frames"].get<long long>());
}

}  // namespace
}  // namespace sandpatch
