// The granule DEM's state, each field declared once (after MuJoCo's mjxmacro.h).
//
// Every per-particle and per-body array of the simulation is generated from the two lists
// below: the CPU structure-of-arrays (particles/dem.cpp), the state hash
// (Simulation::state_hash), and later the GPU backend's std430 structs and the I/O.
//
// One entry: X(type, name, components, hashed, unit)
//   type        float (32 bit) or std::int32_t / std::uint32_t; 4 bytes each, so a std430
//               field of 4 components is a vec4/ivec4 and of 1 component a scalar
//   name        the array name (particles.name / bodies.name)
//   components  1 or 4 (vec3 quantities are padded to 4 so the GPU layout is std430-clean;
//               the 4th component is documented when it is used)
//   hashed      1 if the field is part of the determinism hash (the state that evolves)
//   unit        unit and meaning, in simulation units (patch-relative, unit particle scale)
//
// Array shape: a field of n components is a flat array of (count x n) values.
//
// Particle arrays are kept in cell-sorted order (they are permuted when the grid is
// rebuilt); `id` is the stable particle id (creation order) and the key of the contact
// history. Body arrays are in creation order (the body id is the index).
#pragma once

#include <cstdint>

// clang-format off
#define SANDPATCH_PARTICLE_FIELDS(X)                                                               \
  X(float,         pos,    4, 0, "m; xyz = sphere centre (rebuilt from the body each substep), w = radius (m)") \
  X(float,         vel,    4, 0, "m/s; xyz = velocity of the sphere centre, w = inverse mass of the body (1/kg), 0 if not dynamic") \
  X(float,         omega,  4, 0, "rad/s; xyz = angular velocity of the body (world frame), w unused")          \
  X(float,         offset, 4, 0, "m; xyz = centre offset from the body's centre of mass, body frame, w unused") \
  X(float,         force,  4, 0, "N; xyz = sum of contact forces on the sphere, w = elastic energy share (J); GL backend only (the CPU body stage sums straight into the body)") \
  X(float,         torque, 4, 0, "N m; xyz = torque of the contact forces about the sphere centre, w unused; GL backend only") \
  X(std::int32_t,  body,   1, 0, "index of the body the sphere belongs to")                                   \
  X(std::int32_t,  id,     1, 1, "stable particle id (creation order); key of the contact history")

#define SANDPATCH_BODY_FIELDS(X)                                                                    \
  X(float,         pos,         4, 1, "m; xyz = centre of mass, w unused")                                    \
  X(float,         quat,        4, 1, "unit quaternion (x, y, z, w), body frame -> world frame")             \
  X(float,         vel,         4, 1, "m/s; xyz = linear velocity of the centre of mass, w unused")            \
  X(float,         omega,       4, 1, "rad/s; xyz = angular velocity, world frame, w unused")                 \
  X(float,         force,       4, 0, "N; xyz = contact force summed over the body's spheres (no gravity)")   \
  X(float,         torque,      4, 0, "N m; xyz = contact torque about the centre of mass, world frame")     \
  X(float,         mass,        4, 0, "x = mass (kg), y = inverse mass (1/kg; 0 if not dynamic), zw unused") \
  X(float,         inv_inertia, 4, 0, "1/(kg m^2); xyz = inverse principal inertia, body frame; 0 if not dynamic") \
  X(std::uint32_t, flags,       1, 1, "BodyFlags: kind (granule/shell) | motion (static/kinematic/dynamic)") \
  X(std::int32_t,  first,       1, 0, "id of the body's first sphere (its spheres have consecutive ids)")     \
  X(std::int32_t,  count,       1, 0, "number of spheres of the body")
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
