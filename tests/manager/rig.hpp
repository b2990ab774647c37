// The terrain manager's test rig, shared by tests/manager/terrain_manager*_test.cpp and the
// extremes suite (tests/extremes/): small procedural terrains, the small CPU manager
// definition, sphere bodies, and a Rig that owns a heightfield, the Bullet world over it and a
// TerrainManager over both and steps them frame by frame as manager/run.cpp does.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/error.hpp"
#include "heightfield/heightfield.hpp"
#include "heightfield/procedural.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain_manager.hpp"

namespace sandpatch::test {

// n × n samples at `spacing` (m) with the heights of `p`.
inline Heightfield procedural_terrain(int n, float spacing, const ProceduralHeightsDef& p) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = n;
  g.spacing = spacing;
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << (hf.ok() ? "" : hf.message());
  return std::move(*hf);
}

// Flat at `height` (m, local).
inline Heightfield flat_terrain(int n, float spacing, float height) {
  ProceduralHeightsDef p;
  p.kind = "flat";
  p.height = height;
  return procedural_terrain(n, spacing, p);
}

// Hills of ±amplitude (m) over a period of `wavelength` (m) around `height`.
inline Heightfield hills_terrain(int n, float spacing, float height, float amplitude, float wavelength) {
  ProceduralHeightsDef p;
  p.kind = "hills";
  p.height = height;
  p.amplitude = amplitude;
  p.wavelength = wavelength;
  return procedural_terrain(n, spacing, p);
}

// The terrain manager tests' 8 m × 8 m at 0.1 m spacing, the surface near y = 1 m.
// kind "flat": y = 1 m; "hills": ±5 cm over a 4 m period around y = 1 m.
inline Heightfield terrain_8m(const std::string& kind) {
  return kind == "hills" ? hills_terrain(81, 0.1f, 1.0f, 0.05f, 4.0f) : flat_terrain(81, 0.1f, 1.0f);
}

// A small pool on the CPU: granules of r = 2.5 cm (d = 5 cm), k_n = 2e4 N/m, one slot of 6000
// granules, patches 0.25 m deep, the demotion's depth render 512 texels a side on the CPU (same
// contract as GL; the GL path is tested in depth_conversion_test). Tests change what they need.
inline TerrainManagerDef small_manager_def() {
  TerrainManagerDef d;
  d.material.radius = 0.025f;
  d.material.stiffness = 2.0e4f;
  d.slots = 1;
  d.granules_per_slot = 6000;
  d.patch_depth = 0.25;
  d.depth_resolution = 512;
  d.use_gl = false;
  return d;
}

// A sphere of `radius` (m) and `mass` (kg) at `position` (m, world), every other field default.
inline RigidBodyDef sphere_body(float radius, float mass, const Eigen::Vector3d& position) {
  RigidBodyDef b;
  b.shape.kind = RigidShapeKind::Sphere;
  b.shape.radius = radius;
  b.mass = mass;
  b.position = position;
  return b;
}

// How many of the manager's events so far are of kind k.
inline int count_events(const TerrainManager& m, PatchEventKind k) {
  int n = 0;
  for (const PatchEvent& e : m.events()) n += e.kind == k;
  return n;
}

// Simulated time (s) of the manager's last event of kind k so far; -1 if none.
inline double last_event_time(const TerrainManager& m, PatchEventKind k) {
  double t = -1;
  for (const PatchEvent& e : m.events())
    if (e.kind == k) t = e.time;
  return t;
}

// A heightfield, the Bullet world over it and a terrain manager over both. The world and the
// manager hold references to the heightfield (and the manager to the world), so the rig owns
// all three, declared in that order (destroyed manager first), and is neither copied nor moved.
//
//   test::Rig rig(test::terrain_8m("flat"));       // heightfield + world (gravity -9.81 m/s² in y)
//   ASSERT_TRUE(rig.ok()) << rig.error;
//   auto id = rig.add_sphere(0.1f, 5.0f, {4.0, 1.4, 4.0});
//   ASSERT_TRUE(rig.start(test::small_manager_def()).ok()) << rig.error;  // the manager
//   ASSERT_TRUE(rig.frames(60).ok()) << rig.error;                         // 1 s at 1/60 s a frame
class Rig {
 public:
  explicit Rig(Heightfield terrain, const Eigen::Vector3f& gravity = {0, -9.81f, 0}) : hf(std::move(terrain)) {
    auto w = BulletWorld::create(hf, gravity);
    if (w.ok())
      world = std::move(*w);
    else
      error = w.message();
  }
  Rig(const Rig&) = delete;
  Rig& operator=(const Rig&) = delete;

  bool ok() const { return world != nullptr; }

  Result<RigidBodyId> add_sphere(float radius, float mass, const Eigen::Vector3d& position) {
    return world->add_body(sphere_body(radius, mass, position));
  }

  // Makes the manager over the heightfield and the world (bodies may be added before or after).
  Status start(const TerrainManagerDef& def) {
    auto r = TerrainManager::create(def, hf, *world);
    if (!r.ok()) return failed(r.errors());
    manager = std::move(*r);
    return Ok{};
  }

  // One frame at time t, as manager/run.cpp: the manager before the bodies, Bullet one step of
  // dt (unless step_bodies is false: tests without bodies leave Bullet out), the manager after
  // the bodies; then t += dt.
  Status frame() {
    if (Status s = manager->before_bodies(t, dt, profile); !s) return failed(s.errors());
    if (step_bodies) world->step(float(dt));
    if (Status s = manager->after_bodies(t, dt, profile); !s) return failed(s.errors());
    t += dt;
    return Ok{};
  }

  // n frames; after each, `after_each` (if given) is called and may return true to stop early.
  // The first error stops them and is returned.
  Status frames(int n, const std::function<bool()>& after_each = {}) {
    for (int f = 0; f < n; ++f) {
      if (Status s = frame(); !s) return s;
      if (after_each && after_each()) break;
    }
    return Ok{};
  }

  Status demote_all() {
    if (Status s = manager->demote_all(t, profile); !s) return failed(s.errors());
    return Ok{};
  }

  Heightfield hf;                          // declared first: the world and the manager refer to it
  std::unique_ptr<BulletWorld> world;      // null if its creation failed (then `error` says why)
  std::unique_ptr<TerrainManager> manager; // made by start()
  std::string error;                       // message of the last failure (world, start, frame, demotion)
  Profile profile;
  double t = 0;                            // s, simulated: the time of the next frame
  double dt = 1.0 / 60.0;                  // s, one frame
  bool step_bodies = true;

 private:
  Status failed(const std::vector<Error>& errors) {
    error.clear();
    for (const Error& e : errors) error += e.message() + "\n";
    return errors;
  }
};

}  // namespace sandpatch::test
