// sandpatch_bench_render: standalone runner of run_bench_render until `sandpatch bench render`
// is wired. Usage: sandpatch_bench_render [--terrain N]... [--frames F] [--width W] [--height H] [--json]
#include <cstdio>
#include <cstdlib>
#include <string>

#include "render/render.hpp"

int main(int argc, char** argv) {
  sandpatch::render::BenchRenderArgs a;
  for (int i = 1; i < argc; ++i) {
    std::string s = argv[i];
    auto next = [&]() -> const char* {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", s.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (s == "--terrain") a.terrains.push_back(std::atoi(next()));
    else if (s == "--frames") a.frames = std::atoi(next());
    else if (s == "--width") a.width = std::atoi(next());
    else if (s == "--height") a.height = std::atoi(next());
    else if (s == "--json") a.json = true;
    else {
      std::fprintf(stderr, "unknown option %s\n", s.c_str());
      return 2;
    }
  }
  return sandpatch::render::run_bench_render(a);
}
