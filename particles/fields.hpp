// The granule DEM's state, each field declared once (after MuJoCo's mjxmacro.h).
//
// Every per-particle and per-body array of the simulation is generated from the lists below:
// the CPU structure-of-arrays and its sort permutation (particles/dem_impl.hpp,
// dem_grid.cpp), the state hash (Simulation::state_hash), the GPU backend's std430 blocks
// (particles/gpu/layout.hpp) and the manager's memory estimate.
//
// One entry: X(type, name, components, hashed, backend, unit)
//   type        float (32 bit) or std::int32_t / std::uint32_t (std::uint8_t: CPU-only
//               contact flags); a GL field is 4 bytes per component, so a std430 field of 4
//               components is a vec4/ivec4 and of 1 component a scalar
//   name        the array name (particles.name / bodies.name / contacts.name)
//   components  values per element (GL fields: 1 or 4; vec3 quantities are padded to 4 so the
//               GPU layout is std430-clean; the 4th component is documented when it is used)
//   hashed      1 if the field is part of the determinism hash (the state that evolves)
//   backend     which backend keeps the array: BOTH, CPU or GL (SANDPATCH_FIELD_ON(CPU, backend,
//               ...) keeps its arguments only for the CPU's fields, likewise GL): the CPU
//               backend neither allocates nor sorts the GL's per-sphere force sums, the GL
//               backend has no CPU-only contact arrays in its blocks
//   unit        unit and meaning, in simulation units (patch-relative, unit particle scale)
//
// Array shape: a field of n components is a flat array of (count x n) values.
//
// Particle arrays are kept in cell-sorted order (they are permuted when the grid is
// rebuilt); `id` is the stable particle id (creation order) and the key of the contact
// history. Body arrays are in creation order (the body id is the index).
//
// Contact history (the tangential springs, Cundall & Strack 1979, and which contacts touched
// at the last substep, for the first-substep dashpot): state that evolves, so hashed.
//   SANDPATCH_SPHERE_CONTACT_FIELDS  per sphere (CPU: sorted order, permuted with the particles)
//   SANDPATCH_PAIR_CONTACT_FIELDS    per neighbour-list entry (CPU: the CSR list of dem.hpp,
//                                    one entry per pair within r_i + r_j + skin, owner side)
// The GL backend keeps its contact history by particle id in buffers of its own layout
// (shaders/dem/common.glsl: SpringsIn/SpringsOut, K slots of (xi, partner id) per sphere and
// their dmax, and Walls, a mask and 6 springs per sphere with their dmax in w), hashed by
// GlSimulation::state_hash (the pairs' dmax only with the hysteretic spring).
#pragma once

#include <cstdint>

// SANDPATCH_FIELD_ON(CPU, backend, ...) / SANDPATCH_FIELD_ON(GL, backend, ...): the arguments
// after `backend` if that backend keeps the field, else nothing.
#define SANDPATCH_FIELD_ON(which, backend, ...) SANDPATCH_FIELD_ON_##which##_##backend(__VA_ARGS__)
#define SANDPATCH_FIELD_ON_CPU_BOTH(...) __VA_ARGS__
#define SANDPATCH_FIELD_ON_CPU_CPU(...) __VA_ARGS__
#define SANDPATCH_FIELD_ON_CPU_GL(...)
#define SANDPATCH_FIELD_ON_GL_BOTH(...) __VA_ARGS__
#define SANDPATCH_FIELD_ON_GL_GL(...) __VA_ARGS__
#define SANDPATCH_FIELD_ON_GL_CPU(...)

// clang-format off
#define SANDPATCH_PARTICLE_FIELDS(X)                                                               \
  X(float,         pos,    4, 0, BOTH, "m; xyz = sphere centre (rebuilt from the body each substep), w = radius (m)") \
  X(float,         vel,    4, 0, BOTH, "m/s; xyz = velocity of the sphere centre, w = inverse mass of the body (1/kg), 0 if not dynamic") \
  X(float,         omega,  4, 0, BOTH, "rad/s; xyz = angular velocity of the body (world frame), w unused")          \
  X(float,         offset, 4, 0, BOTH, "m; xyz = centre offset from the body's centre of mass, body frame, w unused") \
  X(float,         force,  4, 0, GL,   "N; xyz = sum of contact forces on the sphere, w = elastic energy share (J); the CPU body stage sums straight into the body") \
  X(float,         torque, 4, 0, GL,   "N m; xyz = torque of the contact forces about the sphere centre, w unused") \
  X(std::int32_t,  body,   1, 0, BOTH, "index of the body the sphere belongs to")                                   \
  X(std::int32_t,  id,     1, 1, BOTH, "stable particle id (creation order); key of the contact history")

#define SANDPATCH_BODY_FIELDS(X)                                                                    \
  X(float,         pos,         4, 1, BOTH, "m; xyz = centre of mass, w unused")                                    \
  X(float,         quat,        4, 1, BOTH, "unit quaternion (x, y, z, w), body frame -> world frame")             \
  X(float,         vel,         4, 1, BOTH, "m/s; xyz = linear velocity of the centre of mass, w unused")            \
  X(float,         omega,       4, 1, BOTH, "rad/s; xyz = angular velocity, world frame, w unused")                 \
  X(float,         force,       4, 0, BOTH, "N; xyz = contact force summed over the body's spheres (no gravity)")   \
  X(float,         torque,      4, 0, BOTH, "N m; xyz = contact torque about the centre of mass, world frame")     \
  X(float,         mass,        4, 0, BOTH, "x = mass (kg), y = inverse mass (1/kg; 0 if not dynamic), zw unused") \
  X(float,         inv_inertia, 4, 0, BOTH, "1/(kg m^2); xyz = inverse principal inertia, body frame; 0 if not dynamic") \
  X(std::uint32_t, flags,       1, 1, BOTH, "BodyFlags: kind (granule/shell) | motion (static/kinematic/dynamic)") \
  X(std::int32_t,  first,       1, 0, BOTH, "id of the body's first sphere (its spheres have consecutive ids)")     \
  X(std::int32_t,  count,       1, 0, BOTH, "number of spheres of the body")                  \
  X(std::int32_t,  group,       1, 0, BOTH, "collision group: the spheres of two bodies of the same group > 0 never touch (bodies joined by joints); 0 = none")

#define SANDPATCH_SPHERE_CONTACT_FIELDS(X)                                                        \
  X(float,         wall_xi,   18, 1, CPU,  "m; tangential springs against the 6 boundary planes (physics_common.glsl slots: floor, walls x0, x1, z0, z1, terrain), xyz each; read only where wall_mask has the plane's bit") \
  X(std::uint32_t, wall_mask,  1, 1, CPU,  "bit k: boundary plane k touched the sphere at the last substep") \
  X(float,         wall_dmax,  6, 0, CPU,  "m; largest overlap of each plane contact (hysteretic normal spring, contact_force_h; 0 with the linear spring; not hashed: it shows in the positions)")

#define SANDPATCH_PAIR_CONTACT_FIELDS(X)                                                          \
  X(float,         xi,         3, 1, CPU,  "m; the pair's tangential spring (zero while the pair does not touch)") \
  X(std::uint8_t,  touch,      1, 1, CPU,  "1: the pair touched at the last substep (else a touch is in its first substep)") \
  X(float,         dmax,       1, 0, CPU,  "m; the pair's largest overlap while it touches (hysteretic normal spring, contact_force_h; 0 with the linear spring; not hashed: it shows in the positions)")
// clang-format on

namespace sandpatch {

// Bits of the body `flags` field.
enum BodyFlags : std::uint32_t {
  kBodyGranule = 1u << 0,    // a 4-sphere tetrahedral granule (else a shell)
  kBodyStatic = 1u << 1,     // never moves
  kBodyKinematic = 1u << 2,  // moves with an externally set velocity, ignores forces
  kBodyDynamic = 1u << 3,    // integrated from forces (granules are always dynamic)
  kBodyParked = 1u << 4,     // disabled by the manager: static, parked; its own motion bits << 8
};

}  // namespace sandpatch
