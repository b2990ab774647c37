// The C++ face of the DEM physics shared with the GL kernels: shaders/dem/physics_common.glsl
// (the contact law, terrain sampling, boundary planes and the GL status block), compiled here
// inside namespace sandpatch::physics after a small prelude that maps the GLSL subset it is
// written in to C++: vec3 -> Vec3 (math.hpp), uint -> std::uint32_t, the GLSL built-ins to
// the <cmath>/<algorithm> functions of the same float operations, inout/out -> references.
// The GL backend compiles the same text as GLSL (particles/gpu/gl_programs.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "particles/dem.hpp"  // TerrainGrid
#include "particles/math.hpp"

namespace sandpatch::physics {

// ---- prelude: the GLSL subset in C++ ----
using vec3 = Vec3;
using uint = std::uint32_t;
using sandpatch::cross;
using sandpatch::dot;
inline float sqrt(float x) { return std::sqrt(x); }
inline float abs(float x) { return std::fabs(x); }
inline int min(int a, int b) { return std::min(a, b); }
inline float clamp(float v, float lo, float hi) { return std::clamp(v, lo, hi); }

#define SP_INLINE inline
#define SP_INOUT(T) T&
#define SP_OUT(T) T&
#define SP_TERRAIN_GRID const TerrainGrid&
#define SP_TERRAIN_AT(t, ix, iz) (t).heights[std::size_t(iz) * std::size_t((t).nx) + std::size_t(ix)]

#include "shaders/dem/physics_common.glsl"

#undef SP_INLINE
#undef SP_INOUT
#undef SP_OUT
#undef SP_TERRAIN_GRID
#undef SP_TERRAIN_AT

// The std430 layout of the status block (all members 4-byte scalars: offsets 4 apart, no
// padding), as the GL backend reads it back.
static_assert(sizeof(DemStatus) == 8 * 4, "DemStatus: 8 status words (32 bytes)");
static_assert(offsetof(DemStatus, max_granule_speed) == 0 && offsetof(DemStatus, nonfinite_bodies) == 4 &&
              offsetof(DemStatus, max_partners) == 8 && offsetof(DemStatus, contacts) == 12 &&
              offsetof(DemStatus, plane_contacts) == 16 && offsetof(DemStatus, resort) == 20 &&
              offsetof(DemStatus, grid_rebuilds) == 24 && offsetof(DemStatus, kinematic_touch) == 28,
              "DemStatus: std430 offsets of shaders/dem/physics_common.glsl");
constexpr int kPlaneSlots = SP_PLANE_SLOTS;
constexpr int kGridKernels = SP_GRID_KERNELS;

}  // namespace sandpatch::physics
