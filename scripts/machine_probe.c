/* What the machine's two cores share, for reading DEM timings (docs/BENCHMARKS.md, session 7).
 *
 *   gcc -O2 -mavx2 -fopenmp scripts/machine_probe.c -o /tmp/machine_probe && /tmp/machine_probe
 *
 * 1. triad c = a + 1.5 b over 3 x 160 MB, 1 and 2 threads: memory bandwidth (GB/s, best of 5)
 * 2. dependent loads over a random cycle of 128 MB: latency of one load that misses (ns)
 * 3. 8 independent chains of AVX multiply-adds (no memory), 1 and 2 threads: seconds per
 *    thread's loop; the same on 2 threads as on 1 means the two vCPUs are separate cores
 *    (SMT siblings would share the FP units and take ~2x).
 */
#include <immintrin.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>

int main(void) {
  const long n = 40L * 1000 * 1000;
  float *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b), *c = malloc(n * sizeof *c);
  if (!a || !b || !c) return 1;
#pragma omp parallel for
  for (long i = 0; i < n; ++i) a[i] = 1.0f, b[i] = 2.0f, c[i] = 0.0f;
  for (int t = 1; t <= 2; ++t) {
    double best = 1e30;
    for (int r = 0; r < 5; ++r) {
      const double t0 = omp_get_wtime();
#pragma omp parallel for num_threads(t)
      for (long i = 0; i < n; ++i) c[i] = a[i] + 1.5f * b[i];
      const double dt = omp_get_wtime() - t0;
      if (dt < best) best = dt;
    }
    printf("triad, %d thread(s): %.1f GB/s\n", t, 3.0 * n * sizeof(float) / best / 1e9);
  }

  const long m = 16L * 1024 * 1024;  /* 128 MB of indices: one random cycle (Sattolo) */
  long* next = malloc(m * sizeof *next);
  if (!next) return 1;
  for (long i = 0; i < m; ++i) next[i] = i;
  unsigned long long s = 88172645463325252ull;
  for (long i = m - 1; i > 0; --i) {
    s ^= s << 13, s ^= s >> 7, s ^= s << 17;
    const long j = (long)(s % (unsigned long long)i);
    const long tmp = next[i];
    next[i] = next[j], next[j] = tmp;
  }
  const long hops = 20L * 1000 * 1000;
  long x = 0;
  const double t0 = omp_get_wtime();
  for (long i = 0; i < hops; ++i) x = next[x];
  printf("dependent load over 128 MB: %.0f ns (end %ld)\n", (omp_get_wtime() - t0) / hops * 1e9, x);

  for (int t = 1; t <= 2; ++t) {
    const double t1 = omp_get_wtime();
    float sum = 0.0f;
#pragma omp parallel num_threads(t) reduction(+ : sum)
    {
      __m256 v[8];
      for (int k = 0; k < 8; ++k) v[k] = _mm256_set1_ps(1.0f + k);
      const __m256 mul = _mm256_set1_ps(0.9999999f), add = _mm256_set1_ps(1e-7f);
      for (long i = 0; i < 200L * 1000 * 1000; ++i) {
        for (int k = 0; k < 8; ++k) v[k] = _mm256_add_ps(_mm256_mul_ps(v[k], mul), add);
        __asm__ volatile("" : "+x"(v[0]), "+x"(v[1]), "+x"(v[2]), "+x"(v[3]), "+x"(v[4]), "+x"(v[5]), "+x"(v[6]),
                         "+x"(v[7]));
      }
      float out[8];
      _mm256_storeu_ps(out, v[0]);
      sum += out[0];
    }
    printf("AVX multiply-add chains, %d thread(s): %.2f s (sum %g)\n", t, omp_get_wtime() - t1, sum);
  }
  free(a), free(b), free(c), free(next);
  return 0;
}
