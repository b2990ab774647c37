// Helpers shared by the harnesses: a per-process scratch file (the loaders take paths) and a
// little reader that turns the fuzzer's bytes into typed values.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>

namespace sandpatch::fuzz {

// Writes the bytes to /tmp/sandpatch-fuzz-<pid><suffix> and returns the path.
inline std::string scratch_file(const std::uint8_t* data, std::size_t size, const char* suffix) {
  const std::string path = "/tmp/sandpatch-fuzz-" + std::to_string(::getpid()) + suffix;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) __builtin_trap();  // the harness itself cannot work
  if (size) std::fwrite(data, 1, size, f);
  std::fclose(f);
  return path;
}

// Reads typed values from the input; past its end every value is 0.
struct Bytes {
  const std::uint8_t* p;
  std::size_t n;
  bool empty() const { return n == 0; }
  template <class T>
  T take() {
    T v{};
    const std::size_t k = n < sizeof(T) ? n : sizeof(T);
    std::memcpy(&v, p, k);
    p += k;
    n -= k;
    return v;
  }
  std::uint8_t byte() { return take<std::uint8_t>(); }
};

}  // namespace sandpatch::fuzz
