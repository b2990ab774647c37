// The terrain manager's test rig, shared by tests/manager/terrain_manager*_test.cpp and the
// extremes suite (tests/extremes/): small procedural terrains, the small CPU manager
// definition, sphere bodies, and a Rig over a World (manager/world.hpp), stepped frame by
// frame by World::step as every other caller steps it.
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
#include "manager/world.hpp"

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

// small_manager_def() for one small sphere on the 8 m terrain: a 4000-granule slot, patches
// 0.2 m deep with a 0.2 m apron (a 0.1 m sphere's patch fits it).
inline TerrainManagerDef sphere_patch_def() {
  TerrainManagerDef d = small_manager_def();
  d.granules_per_slot = 4000;
  d.patch_depth = 0.2;
  d.lod.apron = 0.2;
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

// A World over a heightfield (its Bullet world, and its terrain manager once started), with
// short names for what tests use.
//
//   test::Rig rig(test::terrain_8m("flat"));       // heightfield + world (gravity -9.81 m/s² in y)
//   ASSERT_TRUE(rig.ok()) << rig.error;
//   auto id = rig.add_sphere(0.1f, 5.0f, {4.0, 1.4, 4.0});
//   ASSERT_TRUE(rig.start(test::small_manager_def()).ok()) << rig.error;  // the manager
//   ASSERT_TRUE(rig.frames(60).ok()) << rig.error;                         // 1 s at 1/60 s a frame
class Rig {
 public:
  explicit Rig(Heightfield terrain, const Eigen::Vector3f& gravity = {0, -9.81f, 0}) {
    auto w = World::create(std::move(terrain), gravity);
    if (!w.ok()) {
      error = w.message();
      return;
    }
    core = std::move(*w);
    world = &core->bullet();
  }
  Rig(const Rig&) = delete;
  Rig& operator=(const Rig&) = delete;

  bool ok() const { return core != nullptr; }

  Result<RigidBodyId> add_sphere(float radius, float mass, const Eigen::Vector3d& position) {
    return core->add_body(sphere_body(radius, mass, position));
  }

  // Makes the manager over the heightfield and the world (bodies may be added before or after).
  Status start(const TerrainManagerDef& def) {
    if (Status s = core->enable_patches(def); !s) return failed(s.errors());
    manager = core->manager();
    return Ok{};
  }

  // One frame of dt (World::step: the manager's stages, `substeps` Bullet steps, the checks).
  Status frame(int substeps = 1) {
    if (Status s = core->step(dt, substeps); !s) return failed(s.errors());
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
    if (Status s = core->demote_all(); !s) return failed(s.errors());
    return Ok{};
  }

  Heightfield& hf() { return core->heightfield(); }
  const Heightfield& hf() const { return core->heightfield(); }
  Profile& profile() { return core->profile(); }
  double t() const { return core->time(); }  // s, simulated: the time of the next frame

  std::unique_ptr<World> core;             // null if its creation failed (then `error` says why)
  BulletWorld* world = nullptr;            // core's Bullet world
  TerrainManager* manager = nullptr;       // core's terrain manager, set by start()
  std::string error;                       // message of the last failure (world, start, frame, demotion)
  double dt = 1.0 / 60.0;                  // s, one frame

 private:
  Status failed(const std::vector<Error>& errors) {
    error.clear();
    for (const Error& e : errors) error += e.message() + "\n";
    return errors;
  }
};

}  // namespace sandpatch::test
