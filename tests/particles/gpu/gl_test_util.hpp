// Helpers shared by the GL DEM tests (random numbers as the CPU tests, a GL context, the
// test box).
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <memory>

#include "gl/context.hpp"
#include "particles/dem.hpp"

namespace sandpatch::gpu::testutil {

inline std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}
inline float urand(std::uint64_t& s) { return float(double(splitmix(s) >> 11) / 9007199254740992.0); }
inline float srand1(std::uint64_t& s) { return 2.0f * urand(s) - 1.0f; }
inline Quat random_quat(std::uint64_t& s) {
  return normalized(Quat{srand1(s), srand1(s), srand1(s), srand1(s)});
}

inline std::unique_ptr<gl::Context> context() {
  auto ctx = gl::Context::create();
  if (!ctx) {
    ADD_FAILURE() << ctx.message();
    return nullptr;
  }
  return std::move(*ctx);
}

inline float norm(Vec3 a) { return std::sqrt(dot(a, a)); }

inline SimulationDef box_def(ShearLaw law) {
  SimulationDef d;
  d.bounds_min = {0, 0, 0};
  d.bounds_max = {0.08f, 0.08f, 0.08f};
  d.side_walls = true;
  d.sleep_time = 0;
  d.max_bodies = 2000;
  d.max_particles = 4000;
  d.material.shear = law;
  // The GL backend has no overlap guard (docs/dem.md "Stability guard"); the CPU reference
  // runs without it too, so both integrate the same scenes (drop_bed's jittered granules
  // reach 12 m/s, above the guard's limit at the peer stiffness).
  d.max_overlap_fraction = 0;
  return d;
}

}  // namespace sandpatch::gpu::testutil
