// One granular simulation as the terrain manager drives it, whichever backend runs it: the
// CPU reference (particles/dem.hpp) or the GL compute shaders (particles/gpu/). The methods
// are the CPU Simulation's, with its semantics and units (sim units, patch-relative).
#pragma once

#include <cstdint>
#include <memory>
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
  virtual Status step(double dt_frame) = 0;
  virtual bool asleep() const = 0;
  virtual void wake() = 0;

  virtual Vec3 body_velocity(BodyId b) const = 0;
  virtual Vec3 body_angular_velocity(BodyId b) const = 0;
  // Sphere centres by stable particle id (granules' spheres first when they were added first).
  virtual std::vector<Vec3> particle_positions() const = 0;
  virtual const SimulationDef& def() const = 0;
  virtual const GranuleShape& granule_shape() const = 0;
  virtual std::uint64_t state_hash() const = 0;
};

// The CPU reference backend around a created Simulation.
std::unique_ptr<DemBackend> make_cpu_backend(Simulation sim);

}  // namespace sandpatch
