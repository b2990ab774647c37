// OBJ reader: any file → load_obj_mesh, then the checks a solid body's mesh goes through and
// the mass properties computed from it.
#include <cmath>
#include <cstdint>

#include "fuzz/fuzz_util.hpp"
#include "scene/mesh.hpp"

using namespace sandpatch;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string path = fuzz::scratch_file(data, size, ".obj");
  auto mesh = load_obj_mesh(path, 1.0);
  if (!mesh) {
    if (mesh.errors().empty()) __builtin_trap();
    return 0;
  }
  for (const auto& v : mesh->vertices)
    if (!v.allFinite()) __builtin_trap();  // a loaded mesh never holds NaN or infinity
  if (check_solid_mesh(*mesh, path, "shape").empty()) {
    (void)mesh->centroid();
    (void)mesh->inertia(1.0);
  }
  return 0;
}
