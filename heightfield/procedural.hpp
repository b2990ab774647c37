// Procedural terrains for tests, benchmarks and scenes. Every kind uses only +, -, *, /,
// floor and integer hashing (no libm transcendental functions), in double, rounded to
// float once per sample: the same definition gives the same bytes on every IEEE-754 machine.
// (Named ProceduralHeightsDef, not ProceduralDef: scene/scene.hpp has the scene-file ProceduralDef.)
#pragma once

#include <cstdint>
#include <string>

#include "heightfield/heightfield.hpp"

namespace sandpatch {

struct ProceduralHeightsDef {
  std::string kind = "flat";  // flat | plane | hills | noise
  float height = 0;           // m, local: base height of every kind
  float slope_x = 0, slope_z = 0;  // plane: dh/dx, dh/dz (dimensionless)
  float amplitude = 1;        // m: hills peak height above `height` / noise peak deviation (>= 0)
  float wavelength = 32;      // m: hills period / noise coarsest feature size (> 0)
  std::uint32_t seed = 1;     // noise: lattice seed
  int octaves = 4;            // noise: fBm octaves in [1, 16], each half the wavelength and amplitude
};

// Heights (local m, x = i*spacing, z = j*spacing):
//   flat:  height
//   plane: height + slope_x x + slope_z z
//   hills: height + amplitude c(x) c(z), c(s) = 2 S(|2 frac(s/wavelength) - 1|) - 1 with
//          S(t) = t^2 (3 - 2t): a C1, cosine-like periodic wave in [-1, 1]
//   noise: height + amplitude * sum_k a_k n_k(x, z) / sum_k a_k, a_k = 2^-k; n_k is value
//          noise with lattice period wavelength / 2^k, lattice values in [-1, 1] from an
//          integer hash of (seed, k, cell), quintic-faded bilinear interpolation.
// Errors name the ProceduralHeightsDef field (grid errors as Heightfield::create).
Result<Heightfield> make_procedural(const HeightfieldDef& grid, const ProceduralHeightsDef& p);

}  // namespace sandpatch
