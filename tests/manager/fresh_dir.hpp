// A fresh output directory for a test run (the run tests of tests/manager and tests/extremes):
// <temp>/sandpatch_<suite>_<name>, removed first so that nothing of an earlier run is read
// back. `suite` keeps test binaries that ctest runs at once out of each other's directories.
#pragma once

#include <filesystem>
#include <string>

namespace sandpatch::test {

inline std::filesystem::path fresh_dir(const std::string& suite, const std::string& name) {
  std::filesystem::path p = std::filesystem::temp_directory_path() / ("sandpatch_" + suite + "_" + name);
  std::filesystem::remove_all(p);
  return p;
}

}  // namespace sandpatch::test
