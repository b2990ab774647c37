// Shared by the extremes suite's manager tests (tests/extremes/*_test.cpp): small terrains,
// coarse granules, a frame loop, and the per-frame watch (finite states, lowest clearance of
// every body above the terrain surface).
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
#include "heightfield/procedural.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain_manager.hpp"

namespace sandpatch::extremes {

// n × n samples at `spacing` (m), flat at `height` (m, local).
inline Heightfield flat_terrain(int n, float spacing, float height) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = n;
  g.spacing = spacing;
  ProceduralHeightsDef p;
  p.kind = "flat";
  p.height = height;
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << (hf.ok() ? "" : hf.message());
  return std::move(*hf);
}

// Hills of ±amplitude (m) over `wavelength` (m) around `height`.
inline Heightfield hills_terrain(int n, float spacing, float height, float amplitude, float wavelength) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = n;
  g.spacing = spacing;
  ProceduralHeightsDef p;
  p.kind = "hills";
  p.height = height;
  p.amplitude = amplitude;
  p.wavelength = wavelength;
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << (hf.ok() ? "" : hf.message());
  return std::move(*hf);
}

inline RigidBodyDef sphere(float radius, float mass, Eigen::Vector3d position) {
  RigidBodyDef b;
  b.shape.kind = RigidShapeKind::Sphere;
  b.shape.radius = radius;
  b.mass = mass;
  b.position = position;
  return b;
}

// Coarse granules (r = 5 cm: a patch of a few hundred granules), a shallow patch, a CPU depth
// render, and short sleep / idle times so that slots come back within a test.
inline TerrainManagerDef coarse_def() {
  TerrainManagerDef d;
  d.material.radius = 0.05f;
  d.material.stiffness = 2.0e4f;
  d.slots = 2;
  d.granules_per_slot = 3000;
  d.shell_particles_per_slot = 2048;
  d.patch_depth = 0.2;
  d.depth_resolution = 256;
  d.use_gl = false;
  d.sleep_time = 0.3;
  d.idle_timeout = 0.2;
  d.lod.apron = 0.2;
  d.threads = 1;  // patches of a few hundred granules: one thread (OpenMP on a loaded machine only waits)
  return d;
}

// Lowest point of the body's bounds minus the terrain surface under its centre (m).
inline double clearance(const Heightfield& hf, const BulletWorld& world, RigidBodyId id) {
  Eigen::Vector3d lo, hi;
  world.bounds(id, &lo, &hi);
  const Eigen::Vector3d c = 0.5 * (lo + hi);
  const double s = hf.origin_y() + hf.sample(float(c.x() - hf.origin_x()), float(c.z() - hf.origin_z()));
  return lo.y() - s;
}

inline bool on_terrain(const Heightfield& hf, const BulletWorld& world, RigidBodyId id) {
  const Eigen::Vector3d p = world.state(id).position;
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

inline int count_events(const TerrainManager& m, PatchEventKind k) {
  int n = 0;
  for (const PatchEvent& e : m.events()) n += e.kind == k;
  return n;
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
    if (e.kind == PatchEventKind::Promoted) g += (g.empty() ? "" : ",") + std::to_string(e.granules);
  const auto tile = m.report()["tile"];
  std::printf("%s: granules per patch [%s]; tiles %zu settled in %.0f ms; stage ms %s\n", name, g.c_str(),
              tile["tiles"].size(), tile["settle_wall_ms_all_tiles"].get<double>(), p.to_json().dump().c_str());
}

// Every frame: every body's state finite, and the lowest clearance over the run (bodies off
// the terrain are skipped when skip_off_terrain).
struct Watch {
  Watch(const Heightfield& h, double) : hf(h) {}
  const Heightfield& hf;
  bool skip_off_terrain = false;
  bool finite = true;
  double min_clearance = std::numeric_limits<double>::infinity();
  std::string note;
  void check(const BulletWorld& world, double t) {
    for (RigidBodyId id : world.bodies()) {
      const BodyState st = world.state(id);
      const bool ok = st.position.allFinite() && st.linear_velocity.allFinite() && st.angular_velocity.allFinite() &&
                      st.orientation.coeffs().allFinite();
      if (!ok && finite) note += "non-finite body " + std::to_string(id.index) + " at t = " + std::to_string(t) + " s; ";
      finite = finite && ok;
      if (skip_off_terrain && !on_terrain(hf, world, id)) continue;
      const double c = clearance(hf, world, id);
      if (c < min_clearance) {
        min_clearance = c;
        note = "lowest clearance " + std::to_string(c) + " m: body " + std::to_string(id.index) + " at t = " + std::to_string(t) + " s";
      }
    }
  }
};

// The frame of manager/run.cpp: manager before the bodies, Bullet, manager after.
struct Stepper {
  Stepper(TerrainManager& mm, BulletWorld& ww, Watch& wa) : m(mm), world(ww), watch(wa) {}
  TerrainManager& m;
  BulletWorld& world;
  Watch& watch;
  double t = 0, dt = 1.0 / 60.0;
  long frame = 0;
  Profile profile;
  std::string last_error;
  std::function<void()> each_frame;
  Status frames(int n) {
    for (int f = 0; f < n; ++f) {
      if (Status s = m.before_bodies(t, dt, profile); !s) return last_error = s.message(), s;
      world.step(float(dt));
      if (Status s = m.after_bodies(t, dt, profile); !s) return last_error = s.message(), s;
      t += dt;
      watch.check(world, t);
      if (each_frame) each_frame();
      // EXTREMES_VERBOSE=1: every 0.25 s the queue, the patches and the fastest body.
      if (std::getenv("EXTREMES_VERBOSE") && (++frame % 15) == 0) {
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
        std::printf("t %.2f s: queued %d, patches %d (filling %d, asleep %d), granules %d, fastest body %.3f m/s\n", t,
                    m.queued_requests(), m.active_patches(), m.filling_patches(), m.asleep_patches(), m.granules(), vmax);
      }
    }
    return Ok{};
  }
  Status demote_all() {
    Status s = m.demote_all(t, profile);
    if (!s) last_error = s.message();
    watch.check(world, t);
    return s;
  }
};

}  // namespace sandpatch::extremes
