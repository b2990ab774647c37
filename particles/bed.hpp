// Granule beds for tests and benchmarks: granules on a loose cubic lattice with random
// orientations, to be settled by stepping the simulation.
#pragma once

#include <cstdint>

#include "common/error.hpp"
#include "particles/dem.hpp"

namespace sandpatch {

struct LatticeBedDef {
  Vec3 min{};                 // lowest corner of the lattice region (granule centres), m
  int nx = 1, nz = 1;         // columns along x and z
  int layers = 1;             // layers along y
  float spacing = 0;          // centre spacing, m; 0 -> 2 (d + r) * 1.02 (bounding spheres apart)
  float jitter = 0.05f;       // random horizontal offset, fraction of the spacing
  std::uint64_t seed = 1;     // orientations and jitter (splitmix64; same seed, same bed)
  int count = -1;             // granules to place (-1: nx * nz * layers)
};

// Adds the granules layer by layer (x fastest); fails with the simulation's capacity error.
Status add_lattice_bed(Simulation& sim, const LatticeBedDef& bed);

// Footprint side (m) of a square box holding `granules` with the settled depth of the
// peer's bed (docs/BENCHMARKS.md "Running the LAMMPS peer": 0.4 m holds 20,000 spheres of d = 0.01 m),
// scaled to the sphere diameter 2 r.
double peer_footprint(int granules, double radius);

}  // namespace sandpatch
