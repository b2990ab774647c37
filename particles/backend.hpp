// One granular simulation as the terrain manager drives it, whichever backend runs it: the
// CPU reference (particles/dem.hpp) or the GL compute shaders (particles/gpu/). The methods
// are the CPU Simulation's, with its semantics and units (sim units, patch-relative).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "common/error.hpp"
#include "particles/dem.hpp"

namespace sandpatch {

class DemBackend {
 public:
  virtual ~DemBackend() = default;
  virtual const char* name() const = 0;  // "cpu" or "gl"

  virtual Status reset(const SimulationDef& def) = 0;
  virtual Result<BodyId> add_granule(Vec3 position, Quat orientation) = 0;
  virtual Result<BodyId> add_shell(const ShellDef& shell) = 0;
  virtual Status set_body_state(BodyId b, Vec3 position, Quat orientation, Vec3 velocity, Vec3 angular_velocity) = 0;
  virtual Status set_body_enabled(BodyId b, bool enabled) = 0;
  // A shell's collision group (ShellDef::group): shells of one group > 0 do not touch.
  virtual Status set_body_group(BodyId b, std::int32_t group) = 0;
  // The substep bound N of the following steps (Simulation::set_steps_per_contact).
  virtual Status set_steps_per_contact(int n) = 0;
  // OpenMP threads of the following steps (0 = OpenMP's default); the results do not depend
  // on it. Backends that do not run on the CPU's threads ignore it.
  virtual Status set_threads(int) { return Ok{}; }
  // The lists the next step would begin by building, built now (Simulation::build_lists_now);
  // backends that build them elsewhere ignore it.
  virtual void build_lists_now() {}
  virtual std::int32_t body_group(BodyId b) const = 0;
  virtual Status step(double dt_frame) = 0;
  // DEM substeps a frame of dt_frame seconds takes (dt_sub <= t_c / N), or the error step() gives.
  virtual Result<int> substeps_for(double dt_frame) const = 0;
  virtual bool asleep() const = 0;
  virtual void wake() = 0;

  virtual Vec3 body_position(BodyId b) const = 0;     // m (sim units): its centre of mass
  virtual Quat body_orientation(BodyId b) const = 0;
  virtual Vec3 body_velocity(BodyId b) const = 0;
  virtual Vec3 body_angular_velocity(BodyId b) const = 0;
  // Contact force (N) and torque about the centre of mass (N m) on body b in the last substep.
  virtual Vec3 body_force(BodyId b) const = 0;
  virtual Vec3 body_torque(BodyId b) const = 0;
  // Sphere centres by stable particle id (granules' spheres first when they were added first).
  virtual std::vector<Vec3> particle_positions() const = 0;
  virtual const SimulationDef& def() const = 0;
  virtual const GranuleShape& granule_shape() const = 0;
  virtual std::uint64_t state_hash() const = 0;
  virtual int particle_count() const = 0;
  // Spheres of body b (a granule's 4, a shell's count); 0 for an id it does not hold.
  virtual int body_particle_count(BodyId b) const = 0;
  // The last step's substeps, substep dt (s), sphere-sphere contacts and grid rebuilds
  // (StepStats; substeps = 0 when the step found the simulation asleep).
  virtual const StepStats& last_step() const = 0;
  // A granule's still time for sleeping regions (Simulation::still_time, set_still_time):
  // {0, its position} and nothing to set on a backend without them (GL).
  virtual Simulation::StillTime still_time(BodyId b) const { return {0.0f, body_position(b)}; }
  virtual Status set_still_time(BodyId, Simulation::StillTime) { return Ok{}; }
  // Contact springs (Simulation::contact_springs, set_contact_springs).
  virtual std::vector<ContactSpring> contact_springs() const = 0;
  virtual Status set_contact_springs(const std::vector<ContactSpring>& springs) = 0;
  // GL backend: the buffer whose first member is vec4 pos[] (xyz, radius) of every sphere, for
  // drawing without a copy to the CPU; 0 on the CPU backend.
  virtual unsigned gpu_particle_buffer() const { return 0; }
  // GL backend: the byte offset of the spheres' int32 ids (stride 4, the same order) in that
  // buffer; -1 on the CPU backend.
  virtual long long gpu_particle_id_offset() const { return -1; }
  // GL backend with GlOptions::profile: GPU seconds per kernel since creation (empty otherwise).
  virtual std::vector<std::pair<std::string, double>> kernel_seconds() const { return {}; }
};

// A DemBackend around any simulation type with the CPU Simulation's methods (the CPU
// Simulation and gpu::GlSimulation): one adapter, so both backends expose the same calls.
template <class Sim>
class DemBackendOf final : public DemBackend {
 public:
  DemBackendOf(Sim sim, const char* name) : sim_(std::move(sim)), name_(name) {}
  const char* name() const override { return name_; }
  Status reset(const SimulationDef& def) override { return sim_.reset(def); }
  Result<BodyId> add_granule(Vec3 p, Quat q) override { return sim_.add_granule(p, q); }
  Result<BodyId> add_shell(const ShellDef& s) override { return sim_.add_shell(s); }
  Status set_body_state(BodyId b, Vec3 p, Quat q, Vec3 v, Vec3 w) override { return sim_.set_body_state(b, p, q, v, w); }
  Status set_body_enabled(BodyId b, bool e) override { return sim_.set_body_enabled(b, e); }
  Status set_body_group(BodyId b, std::int32_t g) override { return sim_.set_body_group(b, g); }
  Status set_steps_per_contact(int n) override { return sim_.set_steps_per_contact(n); }
  Status set_threads(int n) override {
    if constexpr (requires(Sim& s) { s.set_threads(n); }) return sim_.set_threads(n);
    return Ok{};
  }
  void build_lists_now() override {
    if constexpr (requires(Sim& s) { s.build_lists_now(); }) sim_.build_lists_now();
  }
  std::int32_t body_group(BodyId b) const override { return sim_.body_group(b); }
  Status step(double dt) override { return sim_.step(dt); }
  Result<int> substeps_for(double dt) const override { return sim_.substeps_for(dt); }
  bool asleep() const override { return sim_.asleep(); }
  void wake() override { sim_.wake(); }
  Vec3 body_position(BodyId b) const override { return sim_.body_position(b); }
  Quat body_orientation(BodyId b) const override { return sim_.body_orientation(b); }
  Vec3 body_velocity(BodyId b) const override { return sim_.body_velocity(b); }
  Vec3 body_angular_velocity(BodyId b) const override { return sim_.body_angular_velocity(b); }
  Vec3 body_force(BodyId b) const override { return sim_.body_force(b); }
  Vec3 body_torque(BodyId b) const override { return sim_.body_torque(b); }
  std::vector<Vec3> particle_positions() const override { return sim_.particle_positions(); }
  const SimulationDef& def() const override { return sim_.def(); }
  const GranuleShape& granule_shape() const override { return sim_.granule_shape(); }
  std::uint64_t state_hash() const override { return sim_.state_hash(); }
  int particle_count() const override { return sim_.particle_count(); }
  int body_particle_count(BodyId b) const override { return sim_.body_particle_count(b); }
  const StepStats& last_step() const override { return sim_.last_step(); }
  Simulation::StillTime still_time(BodyId b) const override {
    if constexpr (requires(const Sim& s) { s.still_time(b); }) return sim_.still_time(b);
    return DemBackend::still_time(b);
  }
  Status set_still_time(BodyId b, Simulation::StillTime t) override {
    if constexpr (requires(Sim& s) { s.set_still_time(b, t); }) return sim_.set_still_time(b, t);
    return Ok{};
  }
  std::vector<ContactSpring> contact_springs() const override {
    if constexpr (requires(const Sim& s) { s.contact_springs(); }) return sim_.contact_springs();
    return {};
  }
  Status set_contact_springs(const std::vector<ContactSpring>& c) override {
    if constexpr (requires(Sim& s) { s.set_contact_springs(c); }) return sim_.set_contact_springs(c);
    return Ok{};
  }
  unsigned gpu_particle_buffer() const override {
    if constexpr (requires(const Sim& s) { s.particle_buffer(); }) return sim_.particle_buffer();
    return 0;
  }
  std::vector<std::pair<std::string, double>> kernel_seconds() const override {
    if constexpr (requires(const Sim& s) { s.kernel_seconds(); }) return sim_.kernel_seconds();
    return {};
  }
  long long gpu_particle_id_offset() const override {
    if constexpr (requires(const Sim& s) { s.particle_id_offset(); }) return (long long)sim_.particle_id_offset();
    return -1;
  }

 private:
  Sim sim_;
  const char* name_;
};

// The CPU reference backend around a created Simulation.
inline std::unique_ptr<DemBackend> make_cpu_backend(Simulation sim) {
  return std::make_unique<DemBackendOf<Simulation>>(std::move(sim), "cpu");
}

}  // namespace sandpatch
