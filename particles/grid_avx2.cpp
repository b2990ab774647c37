// The neighbour search's distance test for 8 candidates at once (AVX2), see grid_simd.hpp.
// Compiled with -mavx2 -ffp-contract=off (particles/CMakeLists.txt) and called only after a
// cpuid check, so the library still runs on baseline x86-64.
#include "particles/grid_simd.hpp"

#include <immintrin.h>

namespace sandpatch::simd {

int near_spheres_avx2(const float* P, int readable, const SearchSphere& s, const std::int32_t (*runs)[2], int nruns,
                      std::int32_t* out) {
  const __m256 px = _mm256_set1_ps(s.x), py = _mm256_set1_ps(s.y), pz = _mm256_set1_ps(s.z);
  const __m256 ri = _mm256_set1_ps(s.r), sk = _mm256_set1_ps(s.skin);
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  int n = 0;
  // (the scalar test of for_forward, for the candidates a group of 8 cannot read)
  auto one = [&](int j) {
    const float dx = s.x - P[4 * j], dy = s.y - P[4 * j + 1], dz = s.z - P[4 * j + 2];
    const float rs = s.r + P[4 * j + 3] + s.skin;
    if (!(dx * dx + dy * dy + dz * dz >= rs * rs)) out[n++] = j;
  };
  for (int k = 0; k < nruns; ++k) {
    int j = runs[k][0];
    const int j1 = runs[k][1];
    for (; j < j1; j += 8) {
      if (j + 8 > readable) {
        for (; j < j1; ++j) one(j);
        break;
      }
      // spheres j .. j+7, (x, y, z, r) each: lane l is sphere j + l after the transpose
      const float* q = P + 4 * std::size_t(j);
      const __m256 m0 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(q)), _mm_loadu_ps(q + 16), 1);
      const __m256 m1 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(q + 4)), _mm_loadu_ps(q + 20), 1);
      const __m256 m2 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(q + 8)), _mm_loadu_ps(q + 24), 1);
      const __m256 m3 = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(q + 12)), _mm_loadu_ps(q + 28), 1);
      const __m256 t0 = _mm256_unpacklo_ps(m0, m1), t1 = _mm256_unpackhi_ps(m0, m1);
      const __m256 t2 = _mm256_unpacklo_ps(m2, m3), t3 = _mm256_unpackhi_ps(m2, m3);
      const __m256 xj = _mm256_shuffle_ps(t0, t2, 0x44), yj = _mm256_shuffle_ps(t0, t2, 0xEE);
      const __m256 zj = _mm256_shuffle_ps(t1, t3, 0x44), rj = _mm256_shuffle_ps(t1, t3, 0xEE);
      // d = p_i - p_j; d2 = (dx dx + dy dy) + dz dz; reach rs = (r_i + r_j) + skin
      const __m256 dx = _mm256_sub_ps(px, xj), dy = _mm256_sub_ps(py, yj), dz = _mm256_sub_ps(pz, zj);
      const __m256 d2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
      const __m256 rs = _mm256_add_ps(_mm256_add_ps(ri, rj), sk);
      // near: not (d2 >= rs rs), true on NaN
      const __m256 near = _mm256_cmp_ps(d2, _mm256_mul_ps(rs, rs), _CMP_NGE_UQ);
      // lanes past the run's end are not candidates
      const __m256i live = _mm256_cmpgt_epi32(_mm256_set1_epi32(j1 - j), lane);
      unsigned bits = unsigned(_mm256_movemask_ps(_mm256_and_ps(near, _mm256_castsi256_ps(live))));
      while (bits) {
        out[n++] = j + __builtin_ctz(bits);
        bits &= bits - 1;
      }
    }
  }
  return n;
}

}  // namespace sandpatch::simd
