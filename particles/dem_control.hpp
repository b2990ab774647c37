// Host-side rules both DEM backends apply identically (particles/dem.cpp, the CPU reference;
// particles/gpu/gl_simulation.cpp, the GL backend): adding a granule or a shell (the checks
// and the record pushed), parking a disabled body, the checks of contact springs set from outside, the sleep timer and an asleep frame. The physics they share with the GL kernels is shaders/dem/physics_common.glsl
// (particles/dem_physics.hpp).
//
// Not shared, and why:
//   push_body   the CPU writes the body and its spheres in place into its sorted arrays (with
//               the overlap guard's per-body values); the GL stages them for a later upload.
//               The body's record (the fields of particles/fields.hpp) is one function here,
//               write_body_record; the spheres' placement is each backend's.
//   integration the body stage is written twice: dem_bodies.cpp (SSE registers for granules,
//               Vec3/Quat for shells) and shaders/dem/bodies.comp (vec3/vec4 quaternions), with
//               the same formulas in the same order; the quaternion types differ between the
//               two (Quat vs vec4), so it is outside physics_common.glsl's common subset.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "particles/dem.hpp"
#include "particles/dem_physics.hpp"
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

// The body record (particles/fields.hpp, SANDPATCH_BODY_FIELDS) of slot i of either backend's
// body arrays (`B`: the CPU's BodyArrays, the GL's BodyStage), as push_body writes it: state
// x (m), q (normalised here), v (m/s), w (rad/s); mass (kg) and invm (1/kg), inv_inertia
// (1/(kg m^2), body frame); flags (BodyFlags); the ids of its spheres first .. first + count - 1;
// group 0 (add_shell sets a shell's). The w of the vec4 fields and the forces are left as they are.
template <class B>
void write_body_record(B& b, std::size_t i, std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm,
                       Vec3 inv_inertia, int first, int count) {
  auto put = [i](std::vector<float>& a, Vec3 u) {
    a[4 * i] = u.x;
    a[4 * i + 1] = u.y;
    a[4 * i + 2] = u.z;
  };
  put(b.pos, x);
  const Quat qn = normalized(q);
  b.quat[4 * i] = qn.x;
  b.quat[4 * i + 1] = qn.y;
  b.quat[4 * i + 2] = qn.z;
  b.quat[4 * i + 3] = qn.w;
  put(b.vel, v);
  put(b.omega, w);
  b.mass[4 * i] = mass;
  b.mass[4 * i + 1] = invm;
  put(b.inv_inertia, inv_inertia);
  b.flags[i] = flags;
  b.first[i] = first;
  b.count[i] = count;
  b.group[i] = 0;
}

// wake() of either backend (`Impl`: its state): awake, with its sleep timer reset.
template <class Impl>
void wake_up(Impl& s) {
  s.asleep = false;
  s.below_time = 0;
}

// A frame that finds the simulation asleep. Untouched by a moving kinematic shell (the
// caller has moved the kinematic shells), only the clock advances and the step reports slept
// with no substeps: returns true, the frame is done. Touched, it wakes with its sleep timer
// reset and returns false: the frame is stepped. `Impl` is either backend's state.
template <class Impl>
bool asleep_frame(Impl& s, double dt_frame, bool touched) {
  if (!touched) {
    s.time += dt_frame;
    s.stats.slept = true;
    s.stats.substeps = 0;
    return true;
  }
  wake_up(s);
  return false;
}

// add_granule of either backend (`Impl`: its nb bodies and np spheres of def's capacities,
// its GranuleShape and push_body): a dynamic body of the shape's 4 spheres at position x,
// orientation q, velocity v (m/s) and angular velocity w (rad/s). Errors name the capacity
// to raise, or the non-finite input.
template <class Impl>
Result<BodyId> push_granule(Impl& s, Vec3 x, Quat q, Vec3 v, Vec3 w) {
  if (s.nb + 1 > s.def.max_bodies)
    return Error{"", "SimulationDef.max_bodies", format_number(s.def.max_bodies), "is full: raise max_bodies",
                 "add_granule needs 1 more body"};
  if (s.np + 4 > s.def.max_particles)
    return Error{"", "SimulationDef.max_particles", format_number(s.def.max_particles), "is full: raise max_particles",
                 "add_granule needs 4 more particles"};
  if (!std::isfinite(x.x + x.y + x.z + q.x + q.y + q.z + q.w + v.x + v.y + v.z + w.x + w.y + w.z))
    return Error{"", "add_granule", "non-finite", "position, orientation and velocities must be finite", ""};
  const GranuleShape& g = s.shape;
  float r = g.radius;
  float inv_i = 1.0f / g.inertia;
  return BodyId{s.push_body(kBodyGranule | kBodyDynamic, x, q, v, w, g.mass, 1.0f / g.mass, {inv_i, inv_i, inv_i},
                            g.offsets.data(), &r, 4, true)};
}

// The body of shell `sh` as planned by plan_shell (checked, capacity included), pushed by
// either backend's push_body; returns its index.
template <class Impl>
int push_shell(Impl& s, const ShellDef& sh, const ShellPlan& p) {
  return s.push_body(p.flags, sh.position, sh.orientation, sh.velocity, sh.angular_velocity,
                     sh.motion == MotionType::Dynamic ? sh.mass : 0.0f, p.inv_mass, p.inv_inertia, sh.offsets.data(),
                     sh.radii.data(), p.count, p.one_radius);
}

// Whether `index` names one of the simulation's `bodies` bodies; the error names `call`.body.
// set_contact_springs' entries (dem.hpp ContactSpring), checked whole before either backend
// sets anything: `flags(b)` and `count(b)` give body b's BodyFlags and sphere count (b in
// [0, bodies)). Errors name the entry and field.
template <class Flags, class Count>
Status check_contact_springs(const std::vector<ContactSpring>& springs, int bodies, Flags flags, Count count) {
  for (std::size_t n = 0; n < springs.size(); ++n) {
    const ContactSpring& c = springs[n];
    const std::string at = "set_contact_springs[" + std::to_string(n) + "].";
    auto check_sphere = [&](BodyId b, int k, const char* body, const char* sphere) -> Status {
      if (b.index < 0 || b.index >= bodies || !(flags(b.index) & kBodyGranule))
        return Error{"", at + body, std::to_string(b.index), "must be a granule of this simulation", ""};
      if (k < 0 || k >= count(b.index)) return Error{"", at + sphere, std::to_string(k), "must be 0..3 (the granule's spheres)", ""};
      return Ok{};
    };
    if (Status st = check_sphere(c.a, c.sphere_a, "a", "sphere_a"); !st) return st;
    if (c.plane >= physics::kPlaneSlots || c.plane < -1)
      return Error{"", at + "plane", std::to_string(c.plane), "must be -1 (a pair) or 0..5 (a boundary plane)", ""};
    if (c.plane < 0) {
      if (Status st = check_sphere(c.b, c.sphere_b, "b", "sphere_b"); !st) return st;
      if (c.b.index == c.a.index) return Error{"", at + "b", std::to_string(c.b.index), "must be another granule than a", ""};
    }
    if (!std::isfinite(c.xi.x) || !std::isfinite(c.xi.y) || !std::isfinite(c.xi.z))
      return Error{"", at + "xi", "not finite", "must be a finite spring (m)", ""};
    if (!std::isfinite(c.dmax) || c.dmax < 0) return Error{"", at + "dmax", std::to_string(c.dmax), "must be a finite overlap >= 0 (m)", ""};
  }
  return Ok{};
}

inline Status check_body_index(int index, int bodies, const std::string& call) {
  if (index < 0 || index >= bodies)
    return Error{"", call + ".body", std::to_string(index), "must be a body of this simulation", ""};
  return Ok{};
}

// Whether body `index` (of `bodies`, with `flags`) may take collision group `group`
// (set_body_group): a shell of this simulation, a group >= 0 (0: none).
inline Status check_body_group(int index, int bodies, std::uint32_t flags, std::int32_t group) {
  if (Status st = check_body_index(index, bodies, "set_body_group"); !st) return st;
  if (group < 0)
    return Error{"", "set_body_group.group", std::to_string(group), "must be >= 0 (0: no collision group)", ""};
  if (flags & kBodyGranule)
    return Error{"", "set_body_group.body", std::to_string(index), "is a granule: only shells have a group", ""};
  return Ok{};
}

}  // namespace sandpatch
