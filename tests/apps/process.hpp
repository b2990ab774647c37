// Running the program as a user does, for the tests of apps/sandpatch: a shell command's exit
// code and its output (stdout and stderr together).
#pragma once

#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

namespace apps_test {

struct Outcome {
  int code = -1;       // the exit code; -1 if the command did not exit normally
  std::string output;  // stdout and stderr together
};

inline Outcome shell(const std::string& cmd) {
  Outcome o;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (!p) return o;
  std::array<char, 4096> buf;
  while (std::size_t n = std::fread(buf.data(), 1, buf.size(), p)) o.output.append(buf.data(), n);
  const int status = pclose(p);
  o.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return o;
}

// `sandpatch ARGS` (the binary this build made).
inline Outcome sandpatch(const std::string& args) { return shell(std::string(SANDPATCH_EXE) + " " + args); }

}  // namespace apps_test
