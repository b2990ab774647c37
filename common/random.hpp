// A small, seedable, platform-independent random source for reproducible set-ups (beds,
// piles): splitmix64 (Steele, Lea & Flood 2014). Same seed, same sequence, on every machine.
#pragma once

#include <cstdint>

namespace sandpatch {

// Next 64 random bits; advances the state `s`.
inline std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9e3779b97f4a7c15ull);
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
  return z ^ (z >> 31);
}

// Uniform in [0, 1) with 53 random bits.
inline double uniform(std::uint64_t& s) { return double(splitmix(s) >> 11) * (1.0 / 9007199254740992.0); }

}  // namespace sandpatch
