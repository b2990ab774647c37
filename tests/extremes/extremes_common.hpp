// Shared by the extremes suite's manager tests (tests/extremes/*_test.cpp): coarse granules,
// a frame loop over the manager tests' rig (tests/manager/rig.hpp: terrains, heightfield +
// world + manager) and the per-frame watch (finite states, lowest clearance of every body
// above the terrain surface).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <limits>
#include <string>

#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain_manager.hpp"
#include "tests/manager/rig.hpp"

namespace sandpatch::extremes {

using test::count_events;
using test::flat_terrain;
using test::hills_terrain;
using test::Rig;

// Coarse granules (r = 5 cm: a patch of a few hundred granules), a shallow patch, a CPU depth
// render, and short sleep / idle times so that slots come back within a test.
inline TerrainManagerDef coarse_def() {
  TerrainManagerDef d = test::small_manager_def();  // k_n = 2e4 N/m, CPU depth render
  d.material.radius = 0.05f;
  d.slots = 2;
  d.granules_per_slot = 3000;
  d.shell_particles_per_slot = 2048;
  d.patch_depth = 0.2;
  d.depth_resolution = 256;
  d.sleep_time = 0.3;
  d.idle_timeout = 0.2;
  d.lod.apron = 0.2;
  d.threads = 1;  // patches of a few hundred granules: one thread (OpenMP on a loaded machine only waits)
  return d;
}

// Lowest point of the body's bounds minus the terrain surface under its centre (m).
inline double clearance(const Rig& rig, RigidBodyId id) {
  const Heightfield& hf = rig.hf();
  Eigen::Vector3d lo, hi;
  rig.world->bounds(id, &lo, &hi);
  const Eigen::Vector3d c = 0.5 * (lo + hi);
  const double s = hf.origin_y() + hf.sample(float(c.x() - hf.origin_x()), float(c.z() - hf.origin_z()));
  return lo.y() - s;
}

inline bool on_terrain(const Rig& rig, RigidBodyId id) {
  const Heightfield& hf = rig.hf();
  const Eigen::Vector3d p = rig.world->state(id).position;
  const double x = p.x() - hf.origin_x(), z = p.z() - hf.origin_z();
  const double w = (hf.samples_x() - 1) * double(hf.spacing()), d = (hf.samples_z() - 1) * double(hf.spacing());
  return x >= 0 && x <= w && z >= 0 && z <= d;
}

inline bool heights_finite(const Heightfield& hf) {
  for (int j = 0; j < hf.samples_z(); ++j)
    for (int i = 0; i < hf.samples_x(); ++i)
      if (!std::isfinite(hf.height(i, j))) return false;
  return true;
}

inline double worst_ledger_pct(const nlohmann::ordered_json& rep) {
  double w = 0;
  for (const auto& p : rep["ledger"]["patches"]) w = std::max(w, std::abs(p["error_pct"].get<double>()));
  return w;
}

// One line for the test log: granules of each patch the run made, and wall ms per stage.
inline void print_summary(const char* name, const TerrainManager& m, const Profile& p) {
  std::string g;
  for (const PatchEvent& e : m.events())
    if (e.kind == PatchEventKind::Promoted) {
      if (!g.empty()) g += ',';
      g += std::to_string(e.granules);
    }
  const auto tile = m.report()["tile"];
  std::printf("%s: granules per patch [%s]; tiles %zu settled in %.0f ms; stage ms %s\n", name, g.c_str(),
              tile["tiles"].size(), tile["settle_wall_ms_all_tiles"].get<double>(), p.to_json().dump().c_str());
}

// Every frame: every body's state finite, and the lowest clearance over the run (bodies off
// the terrain are skipped when skip_off_terrain).
struct Watch {
  explicit Watch(const Rig& r) : rig(r) {}
  const Rig& rig;
  bool skip_off_terrain = false;
  bool finite = true;
  double min_clearance = std::numeric_limits<double>::infinity();
  std::string note;
  void check() {
    const double t = rig.t();
    for (RigidBodyId id : rig.world->bodies()) {
      const BodyState st = rig.world->state(id);
      const bool ok = st.position.allFinite() && st.linear_velocity.allFinite() && st.angular_velocity.allFinite() &&
                      st.orientation.coeffs().allFinite();
      if (!ok && finite) note += "non-finite body " + std::to_string(id.index) + " at t = " + std::to_string(t) + " s; ";
      finite = finite && ok;
      if (skip_off_terrain && !on_terrain(rig, id)) continue;
      const double c = clearance(rig, id);
      if (c < min_clearance) {
        min_clearance = c;
        note = "lowest clearance " + std::to_string(c) + " m: body " + std::to_string(id.index) + " at t = " + std::to_string(t) + " s";
      }
    }
  }
};

// The rig's frames (manager/run.cpp's frame: manager before the bodies, Bullet, manager
// after), each followed by the watch and each_frame.
struct Stepper {
  Stepper(Rig& r, Watch& wa) : rig(r), watch(wa) {}
  Rig& rig;
  Watch& watch;
  long frame = 0;
  std::function<void()> each_frame;
  Status frames(int n) {
    return rig.frames(n, [&] {
      watch.check();
      if (each_frame) each_frame();
      // EXTREMES_VERBOSE=1: every 0.25 s the queue, the patches and the fastest body.
      if (std::getenv("EXTREMES_VERBOSE") && (++frame % 15) == 0) print_state();
      return false;
    });
  }
  Status demote_all() {
    Status s = rig.demote_all();
    watch.check();
    return s;
  }
  void print_state() const {
    const BulletWorld& world = *rig.world;
    const TerrainManager& m = *rig.manager;
    double vmax = 0;
    RigidBodyId fast;
    for (RigidBodyId id : world.bodies())
      if (world.state(id).linear_velocity.norm() > vmax) vmax = world.state(id).linear_velocity.norm(), fast = id;
    if (fast.valid()) {
      const BodyState st = world.state(fast);
      std::printf("  fastest: body %d at (%.3f, %.3f, %.3f) v (%.3f, %.3f, %.3f) w %.3f heightfield %d\n", fast.index,
                  st.position.x(), st.position.y(), st.position.z(), st.linear_velocity.x(), st.linear_velocity.y(),
                  st.linear_velocity.z(), st.angular_velocity.norm(), int(world.terrain_collision(fast)));
    }
    std::printf("t %.2f s: queued %d, patches %d (filling %d, asleep %d), granules %d, fastest body %.3f m/s\n", rig.t(),
                m.queued_requests(), m.active_patches(), m.filling_patches(), m.asleep_patches(), m.granules(), vmax);
  }
};

}  // namespace sandpatch::extremes
