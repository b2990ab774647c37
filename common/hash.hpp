// Stable 64-bit hashing for scene hashes and final-state hashes (FNV-1a, 64 bit).
// Byte-exact: the same floats in the same order give the same hash on every run,
// so a state hash is a determinism check.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>

namespace sandpatch {

class Hasher {
 public:
  void bytes(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) {
      h_ ^= p[i];
      h_ *= 0x100000001b3ull;
    }
  }
  template <class T>
  void pod(const T& v) { bytes(&v, sizeof(T)); }
  void str(std::string_view s) { bytes(s.data(), s.size()); }
  std::uint64_t value() const { return h_; }
  std::string hex() const { return to_hex(h_); }

  static std::string to_hex(std::uint64_t v) {
    char buf[17];
    std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
    return buf;
  }

 private:
  std::uint64_t h_ = 0xcbf29ce484222325ull;
};

}  // namespace sandpatch
