// The GL compute-shader simulation as a DemBackend (particles/backend.hpp), for the terrain
// manager. The GL context must stay current on the calling thread for the backend's life.
#pragma once

#include <memory>

#include "particles/backend.hpp"
#include "particles/gpu/gl_simulation.hpp"

namespace sandpatch::gpu {

inline std::unique_ptr<DemBackend> make_gl_backend(GlSimulation sim) {
  return std::make_unique<DemBackendOf<GlSimulation>>(std::move(sim), "gl");
}

}  // namespace sandpatch::gpu
