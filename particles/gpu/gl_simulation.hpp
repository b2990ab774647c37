// Granule DEM on the GPU: the CPU backend's physics (particles/dem.hpp, contact.hpp) as
// OpenGL 4.3 compute shaders (shaders/dem/), run in the headless EGL context (gl/context.hpp),
// so the same code runs on any GL driver and on Mesa's llvmpipe (docs/dem-gpu.md).
//
// The step, per substep (every stage a compute dispatch; no CPU round trip inside a frame):
//   1. grid      when a sphere has moved more than skin/2 since the last sort (decided on the
//                GPU; the grid kernels run by indirect dispatch): count spheres per cell
//                (integer atomics), exclusive prefix sum over the cells, scatter the particle
//                ids into their cells, sort each cell's ids, then gather every particle field
//                into cell order (generated from fields.hpp). No per-cell cap.
//   2. contacts  every sphere searches the 27 cells around it and sums its own forces in a
//                fixed order (cells z, y, x, then particle id): the same laws as contact.hpp,
//                including the tangential spring with history (one spring per sphere and
//                partner, kept in max_contacts_per_sphere slots keyed by partner id)
//   3. bodies    each body sums its spheres in id order, integrates (symplectic Euler,
//                normalised quaternion) and rebuilds its spheres (with the velocity
//                predicted half a substep ahead, translation only, as dem.cpp)
// After the frame one 32-byte status block is read back (max granule speed, NaN count,
// contact slots needed, contacts, grid rebuilds), which drives the sleep logic and the error
// reports. Asleep frames move only kinematic shells and wake on their contact, as dem.cpp.
//
// Needs a current GL 4.3+ context on the calling thread for its whole life (create, every
// call, destruction); the caller owns the gl::Context.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/error.hpp"
#include "particles/dem.hpp"

namespace sandpatch::gpu {

struct GlOptions {
  // Contact slots per sphere (partners touching at once): the tangential spring, and which
  // contacts are not new (the first-substep dashpot). 12 equal spheres can
  // touch one (kissing number); a granule's own 3 are not contacts. More simultaneous
  // contacts than this are reported by step() as an Error naming this field.
  int max_contacts_per_sphere = 16;
  int workgroup_size = 64;  // invocations per workgroup of the per-sphere/per-body kernels
  // Bytes of staged bodies step() uploads before simulating (whole bodies; at least one);
  // 0 = everything. Bodies not uploaded yet are not simulated (their queries return the
  // values they were added with).
  std::size_t upload_bytes_per_step = 0;
  bool upload_in_step = true;  // false: only upload() uploads (the caller budgets its frames)
  bool profile = false;        // time every dispatch on the GPU (GL_TIME_ELAPSED queries, read at the end of each step)
};

// GPU counterpart of Simulation, created from the same SimulationDef. Capacities
// (max_bodies, max_particles, the grid cells of bounds / (2 particle_radius + skin)) are
// fixed at creation; all GPU memory is allocated then.
class GlSimulation {
 public:
  static Result<GlSimulation> create(const SimulationDef& def, const GlOptions& options = {});
  GlSimulation(GlSimulation&&) noexcept;
  GlSimulation& operator=(GlSimulation&&) noexcept;
  ~GlSimulation();  // deletes every GL object it created

  // Bodies, as Simulation (same errors). Uploaded in one batch before the next step/query.
  Result<BodyId> add_granule(Vec3 position, Quat orientation = {}, Vec3 velocity = {},
                             Vec3 angular_velocity = {});
  Result<BodyId> add_shell(const ShellDef& shell);
  Status set_kinematic_velocity(BodyId b, Vec3 velocity, Vec3 angular_velocity);
  // As Simulation (same errors, same flags): sets a body's state (sim units), or parks /
  // restores it (disabled: static | parked with its motion bits << 8, at (centre x,
  // bounds_max.y + 1000, centre z), zero velocities, its spheres' plane masks cleared; enabled:
  // motion bits restored, then set its state). Both wake the simulation. A staged body's queued copy is changed; an uploaded
  // body's few words are written at its index and its spheres rebuilt at once (re-sort
  // flagged), so the next substep's contacts already see the new pose.
  Status set_body_state(BodyId b, Vec3 position, Quat orientation, Vec3 velocity, Vec3 angular_velocity);
  Status set_body_enabled(BodyId b, bool enabled);
  // As Simulation: a shell's collision group (ShellDef::group), written at its index.
  Status set_body_group(BodyId b, std::int32_t group);
  std::int32_t body_group(BodyId b) const;

  // Staged bodies: bytes still to upload; upload whole bodies in order within max_bytes
  // (with at_least_one, the first body goes however large); returns the bytes written.
  // step() uploads by itself (GlOptions::upload_bytes_per_step).
  std::size_t pending_upload_bytes() const;
  std::size_t upload(std::size_t max_bytes, bool at_least_one = true);
  int uploaded_body_count() const;

  // Empties the simulation and takes a new definition that must fit the capacities it was
  // created with (max_bodies, max_particles, grid cells); errors name the capacity to raise
  // as capacity_prefix + field (default "SimulationDef."). GPU memory is kept.
  Status reset(const SimulationDef& def, const char* capacity_prefix = "SimulationDef.");

  // Advances dt_frame in substeps_for(dt_frame) equal substeps (the CPU backend's guard).
  // Errors: the guard's refusal (state untouched); a non-finite body state; more touching
  // partners than GlOptions::max_contacts_per_sphere (names the option; the frame has run).
  Status step(double dt_frame);
  Result<int> substeps_for(double dt_frame) const;
  // As Simulation::set_steps_per_contact (the guard's and this definition's N).
  Status set_steps_per_contact(int n);
  double contact_time() const;
  double max_substep_dt() const;

  bool asleep() const;
  void wake();

  // Contact springs, as Simulation::contact_springs / set_contact_springs (dem.hpp
  // ContactSpring; same errors, gl_springs.cpp). contact_springs(): every granule-granule and
  // granule-plane contact that touched at the last substep, read back from the contact history
  // (each pair once, from its lower particle id's side unless only the higher one holds it), in
  // particle id order, pairs first; shells' and parked bodies' contacts are not included, nor
  // springs set and not yet taken by a step. set_contact_springs(): checked whole, then kept on
  // the host; the next step whose uploads hold both spheres of an entry writes it into the
  // history its first substep reads (staged writes), as a contact that touched (no
  // first-substep dashpot); a pair not touching then is dropped. Beyond the CPU's errors: more
  // springs on one sphere than GlOptions::max_contacts_per_sphere (names the option).
  std::vector<ContactSpring> contact_springs() const;
  Status set_contact_springs(const std::vector<ContactSpring>& springs);

  // Queries (sim units). Each reads back only what it returns.
  int body_count() const;
  int particle_count() const;
  int body_particle_count(BodyId b) const;       // spheres of body b; 0 for an id it does not hold
  Vec3 body_position(BodyId b) const;
  Quat body_orientation(BodyId b) const;
  Vec3 body_velocity(BodyId b) const;
  Vec3 body_angular_velocity(BodyId b) const;
  Vec3 body_force(BodyId b) const;   // contact force of the last substep, N (no gravity)
  Vec3 body_torque(BodyId b) const;  // contact torque about the COM, N m
  std::vector<Vec3> particle_positions() const;  // by stable particle id
  std::vector<Vec3> particle_forces() const;     // by stable particle id, last substep, N
  double max_granule_speed() const;              // m/s, max |v| + |w| (d + r) over granules
  const StepStats& last_step() const;            // substeps, dt, contacts, wall contacts
  std::uint64_t state_hash() const;              // hashed body fields + particle ids in id order
  const SimulationDef& def() const;
  const GranuleShape& granule_shape() const;
  double time() const;

  // GL names this simulation created (buffers and programs), for leak checks.
  std::vector<unsigned> gl_buffers() const;
  // The shader storage buffer holding the current particle state; its first member is
  // `vec4 pos[capacity]` (xyz = sphere centre, w = radius; sim units), so a renderer can draw
  // the particle_count() spheres straight from it (stride 16, radius at offset 12).
  unsigned particle_buffer() const;
  // Byte offset in particle_buffer() of `int id[capacity]`, each sphere's stable id in the
  // same (cell-sorted) order as pos: granules' spheres come first (ids 0 .. 4 granules - 1)
  // when they were added before any shell, so a renderer can leave the shells out.
  std::size_t particle_id_offset() const;
  std::vector<unsigned> gl_programs() const;
  std::size_t gpu_bytes() const;  // bytes of GPU buffer storage held
  // With GlOptions::profile: GPU seconds spent in each kernel so far, in stage order.
  std::vector<std::pair<std::string, double>> kernel_seconds() const;

  struct Impl;

 private:
  explicit GlSimulation(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandpatch::gpu
