// A pool of GPU granule simulations (issue 4; Leach & Marais §3-4): N slots allocated at
// start-up, each a GlSimulation with the same fixed capacity (bodies, particles, grid
// cells), so GPU memory does not grow with the live particles. A slot is acquired with its
// own SimulationDef (own particle scale, material, bounds within the capacity), filled by
// adding bodies (staged on the CPU, uploaded at most upload_bytes_per_frame per frame over
// all slots, so a fill never stalls a frame), stepped, and released for the next patch.
// Asking for more than the pool holds is an Error naming the capacity to raise.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "particles/gpu/gl_simulation.hpp"

namespace sandpatch::gpu {

struct GlPoolDef {
  int slots = 4;
  // Capacity of every slot: max_bodies, max_particles, and the grid cells of its bounds at
  // its particle_radius (a slot's def may use smaller bounds or larger particles).
  SimulationDef capacity;
  GlOptions options;
  std::size_t upload_bytes_per_frame = 1u << 20;  // over all slots, per step()
};

class GlPool {
 public:
  static Result<GlPool> create(const GlPoolDef& def);

  // A free slot set up for `def` (which must fit the capacity). Errors: every slot in use
  // (names GlPoolDef.slots) or a capacity exceeded (names GlPoolDef.capacity.<field>).
  Result<int> acquire(const SimulationDef& def);
  // Empties the slot and makes it free. Its GPU memory stays with the pool.
  Status release(int slot);
  // The slot's simulation (add bodies, query); the slot must be in use.
  GlSimulation& sim(int slot);
  const GlSimulation& sim(int slot) const;

  // One frame: uploads staged bodies within upload_bytes_per_frame (slots in order, whole
  // bodies), then steps every slot in use by dt_frame. Returns the first error, naming the slot.
  Status step(double dt_frame);

  int slots() const;
  int in_use() const;
  bool in_use(int slot) const;
  std::size_t gpu_bytes() const;            // what the pool holds, bytes
  std::size_t last_frame_upload_bytes() const;
  std::string report() const;               // one line: slots, capacity, memory, use

 private:
  GlPoolDef def_;
  std::vector<GlSimulation> sims_;
  std::vector<bool> used_;
  std::size_t last_upload_ = 0;
};

}  // namespace sandpatch::gpu
