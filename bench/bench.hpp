// `sandpatch bench ...` programs (docs/BENCHMARKS.md).
#pragma once

#include <string>

namespace sandpatch {

// bench dem: settles a bed of `granules` tetrahedral granules (spheres d = 0.01 m,
// rho = 2500 kg/m^3, the peer's contact parameters k_n = 3292 N/m, e = 0.3, mu = 0.5,
// dt = 5e-5 s) in a walled box whose footprint gives the peer's ~11-diameter depth, then
// times `steps` steps. Prints sphere-steps/s, contacts per sphere, dt and threads; with
// json, one JSON object on the last line.
struct BenchDemArgs {
  int granules = 16000;
  int steps = 1000;
  std::string backend = "cpu";
  int threads = 0;  // 0 = OpenMP default
  bool json = false;
};

// Exit code: 0 ok, 1 runtime failure, 2 bad input. Prints to stdout (errors to stderr).
int run_bench_dem(const BenchDemArgs& args);

}  // namespace sandpatch
