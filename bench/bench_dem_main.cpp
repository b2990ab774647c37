// sandpatch_bench_dem: standalone runner of run_bench_dem until `sandpatch bench dem` is wired.
// Usage: sandpatch_bench_dem [--granules N] [--steps S] [--threads T] [--backend cpu] [--json]
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "bench/bench.hpp"

int main(int argc, char** argv) {
  sandpatch::BenchDemArgs a;
  for (int i = 1; i < argc; ++i) {
    std::string s = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", s.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (s == "--granules") a.granules = std::atoi(next());
    else if (s == "--steps") a.steps = std::atoi(next());
    else if (s == "--threads") a.threads = std::atoi(next());
    else if (s == "--backend") a.backend = next();
    else if (s == "--json") a.json = true;
    else {
      std::fprintf(stderr, "unknown option %s\n", s.c_str());
      return 2;
    }
  }
  return sandpatch::run_bench_dem(a);
}
