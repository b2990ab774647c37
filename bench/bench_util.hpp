// Small helpers shared by the `sandpatch bench ...` programs and `sandpatch stress`
// (bench/*.cpp): the machine's load, the process's CPU time, and whole-file writes.
#pragma once

#include <time.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <system_error>

namespace sandpatch::bench {

// The 1-minute load average (/proc/loadavg); 0 where it cannot be read. Benchmarks record it
// before and after a run: on a shared machine a timing means little without it.
inline double load_average() {
  double l = 0;
  std::ifstream f("/proc/loadavg");
  f >> l;
  return l;
}

// CPU seconds used by the whole process (all threads) so far: with the wall time it tells a
// loaded machine (cpu < threads × wall) from a slow step.
inline double process_cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// Writes `text` to `p` whole or not at all (a temporary file renamed over it).
inline bool write_text(const std::filesystem::path& p, const std::string& text) {
  const std::filesystem::path tmp = p.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    if (!f.flush()) return false;
  }
  std::error_code ec;
  std::filesystem::rename(tmp, p, ec);
  return !ec;
}

}  // namespace sandpatch::bench
