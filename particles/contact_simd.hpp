// A batch of 8 touching sphere-sphere pairs for the contact law, evaluated 8
// lanes at a time (AVX2) by particles/contact_avx2.cpp. Used by the pair pass of
// particles/dem_contacts.cpp when the CPU has AVX2; the scalar contact_force (shaders/dem/
// physics_common.glsl, shared with the GL kernels, through contact.hpp) is the reference and
// the fallback; tests/particles/contact_avx2_test.cpp checks the kernel against it.
//
// Same results, bit for bit: every lane performs the float operations of contact_force (and of
// the pair pass around it) in the same order, with the same roundings (mul and add kept
// separate: the kernel's file is compiled with -ffp-contract=off, sqrt and div are IEEE in both
// paths); branches become per-lane selects of the same values. So a bed's state hash does not
// depend on the path (checked by comparing the two paths' hashes; tests run on both through
// SANDPATCH_DEM_KERNEL, see dem_contacts.cpp).
//
// This header holds data only (no inline functions): the kernel's file is compiled for AVX2,
// and an inline function it shared with the baseline code could be emitted in its AVX2 form
// and picked by the linker for everyone.
#pragma once

#include <cstdint>

namespace sandpatch::simd {

constexpr int kPairLanes = 8;

// Structure of arrays, one lane per touching pair (sim units). Inputs are what the pair pass
// computes before the law; outputs are what it stores.
struct alignas(32) PairBatch {
  // in
  float dx[kPairLanes], dy[kPairLanes], dz[kPairLanes];  // x_i - x_j, m
  float d2[kPairLanes];                                   // |x_i - x_j|^2, m^2 (> 0)
  float rs[kPairLanes];                                   // r_i + r_j, m
  float dux[kPairLanes], duy[kPairLanes], duz[kPairLanes];  // u_i - u_j, m/s
  float rwx[kPairLanes], rwy[kPairLanes], rwz[kPairLanes];  // r_i w_i + r_j w_j, m/s
  float invm[kPairLanes];                                 // 1/m_i + 1/m_j, 1/kg
  float newc[kPairLanes];                                 // 1: first substep of the contact, else 0
  // in and out: the tangential spring of the pair, m
  float xix[kPairLanes], xiy[kPairLanes], xiz[kPairLanes];
  // in and out: the pair's largest overlap while it touches (the hysteretic normal spring's
  // history, physics_common.glsl contact_force_h), m; untouched when PairLaw::kn2 <= kn
  float dmax[kPairLanes];
  // out: force on sphere i (N) and n x f_t (N)
  float fx[kPairLanes], fy[kPairLanes], fz[kPairLanes];
  float cx[kPairLanes], cy[kPairLanes], cz[kPairLanes];
  std::int32_t entry[kPairLanes];                         // neighbour-list entry of each lane
  int count = 0;                                          // lanes in use
};

// The material constants of the pair pass (see dem_contacts.cpp `contacts`).
struct PairLaw {
  float kn;   // N/m
  float cn0;  // c_n = cn0 / sqrt(1/m_i + 1/m_j), N s/m
  float kt;   // N/m
  float ctr;  // c_t = ctr c_n
  float mu;
  float dt;   // s
  float kn2;  // unloading stiffness, N/m (Material::unloading_stiffness_ratio x k_n; <= kn: the linear spring)
};

// Evaluates all 8 lanes (lanes >= count must hold finite inputs; their outputs are ignored).
// Only callable when avx2_available().
void spring_pairs_avx2(const PairLaw& law, PairBatch& b);

// True if this CPU runs the AVX2 kernel (checked once, cpuid).
bool avx2_available();

// The choice Simulation::create makes (particles/dem_contacts.cpp): the AVX2 kernel if this build has
// it, the CPU has AVX2 and the environment variable SANDPATCH_DEM_KERNEL is not "scalar".
bool use_avx2_pair_kernel();

}  // namespace sandpatch::simd
