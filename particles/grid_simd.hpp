// The neighbour search's distance test, 8 candidate spheres at a time (AVX2), by
// particles/grid_avx2.cpp. Used by the CPU backend's list rebuild (dem_grid.cpp for_forward)
// when the pair pass uses its AVX2 kernel (contact_simd.hpp: the same cpuid check and the same
// SANDPATCH_DEM_KERNEL switch); the scalar loop in for_forward is the reference and the
// fallback, and tests/particles/grid_avx2_test.cpp checks the two against each other.
//
// Same results, bit for bit: every lane computes the scalar test's float operations in the
// same order (d = p_i - p_j; d2 = (dx dx + dy dy) + dz dz; reach = (r_i + r_j) + skin; near
// unless d2 >= reach reach, so a NaN is near as in the scalar loop), and the near candidates
// come out in the runs' order, ascending within a run: the neighbour list is the same.
//
// Data only here (see contact_simd.hpp: an inline function shared with the AVX2 file could be
// emitted in its AVX2 form for everyone).
#pragma once

#include <cstdint>

namespace sandpatch::simd {

// Sphere i as the test reads it (sim units, m): its centre and radius, and the list's skin.
struct SearchSphere {
  float x, y, z;
  float r;
  float skin;
};

// Writes to `out`, in order, the indices j of the runs [runs[k][0], runs[k][1]) whose sphere
// (P: x, y, z, r per sphere) is near sphere s, and returns how many. `out` holds at least the
// runs' total length. `P` must be readable up to sphere `readable` - 1 (a run's last group of
// 8 reads past its end when that stays below `readable`; otherwise it is tested one by one).
// Only callable when avx2_available().
int near_spheres_avx2(const float* P, int readable, const SearchSphere& s, const std::int32_t (*runs)[2], int nruns,
                      std::int32_t* out);

}  // namespace sandpatch::simd
