// Host-side rules both DEM backends apply identically (particles/dem.cpp, the CPU reference;
// particles/gpu/gl_simulation.cpp, the GL backend): parking a disabled body and the sleep
// timer. The physics they share with the GL kernels is shaders/dem/physics_common.glsl
// (particles/dem_physics.hpp).
//
// Not shared, and why:
//   push_body   the CPU writes the body and its spheres in place into its sorted arrays (with
//               the overlap guard's per-body values); the GL stages them for a later upload.
//               Both write the same record: the fields of particles/fields.hpp.
//   integration the body stage is written twice: dem_bodies.cpp (SSE registers for granules,
//               Vec3/Quat for shells) and shaders/dem/bodies.comp (vec3/vec4 quaternions), with
//               the same formulas in the same order; the quaternion types differ between the
//               two (Quat vs vec4), so it is outside physics_common.glsl's common subset.
#pragma once

#include <cstdint>
#include <string>

#include "particles/dem.hpp"
#include "particles/fields.hpp"

namespace sandpatch {

// Flags of a body being disabled: static | parked, its motion bits kept << 8.
inline std::uint32_t parked_flags(std::uint32_t f) {
  const std::uint32_t motion = kBodyStatic | kBodyKinematic | kBodyDynamic;
  return (f & ~motion) | kBodyStatic | kBodyParked | ((f & motion) << 8);
}
// Flags of a parked body being enabled again: its motion bits restored.
inline std::uint32_t unparked_flags(std::uint32_t f) {
  const std::uint32_t motion = kBodyStatic | kBodyKinematic | kBodyDynamic;
  return (f & ~(motion | kBodyParked | (motion << 8))) | ((f >> 8) & motion);
}
// Where a parked body waits (m, sim units): above the domain's centre, in contact with nothing.
inline Vec3 parking_position(const SimulationDef& d) {
  return {0.5f * (d.bounds_min.x + d.bounds_max.x), d.bounds_max.y + 1000.0f, 0.5f * (d.bounds_min.z + d.bounds_max.z)};
}

// The sleep timer after an awake frame of dt_frame seconds whose last substep's largest
// granule speed was vmax (m/s): asleep once every granule has stayed below sleep_speed for
// sleep_time seconds (sleep_time 0: never).
inline void update_sleep(const SimulationDef& d, float vmax, double dt_frame, double& below_time, bool& asleep) {
  if (vmax < d.sleep_speed) {
    below_time += dt_frame;
    if (below_time >= d.sleep_time && d.sleep_time > 0) asleep = true;
  } else {
    below_time = 0;
  }
}

// Whether body `index` (of `bodies`, with `flags`) may take collision group `group`
// (set_body_group): a shell of this simulation, a group >= 0 (0: none).
inline Status check_body_group(int index, int bodies, std::uint32_t flags, std::int32_t group) {
  if (index < 0 || index >= bodies)
    return Error{"", "set_body_group.body", std::to_string(index), "must be a body of this simulation", ""};
  if (group < 0)
    return Error{"", "set_body_group.group", std::to_string(group), "must be >= 0 (0: no collision group)", ""};
  if (flags & kBodyGranule)
    return Error{"", "set_body_group.body", std::to_string(index), "is a granule: only shells have a group", ""};
  return Ok{};
}

}  // namespace sandpatch
