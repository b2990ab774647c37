// Standalone runner of the GL DEM benchmark until the CLI wires `sandpatch bench dem
// --backend gl`: sandpatch_bench_dem_gl [granules] [steps] [--json]
#include <cstdlib>
#include <cstring>

#include "particles/gpu/bench_gl.hpp"

int main(int argc, char** argv) {
  int granules = 1000, steps = 200;
  bool json = false;
  int pos = 0;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--json") == 0) json = true;
    else if (pos++ == 0) granules = std::atoi(argv[i]);
    else steps = std::atoi(argv[i]);
  }
  return sandpatch::gpu::run_bench_dem_gl(granules, steps, json);
}
