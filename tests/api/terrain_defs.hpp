// Terrain definitions shared by the public API's tests (tests/api/*_test.cpp), through the
// public header only (include/sandpatch/sandpatch.hpp): no internals.
#pragma once

#include <limits>
#include <sandpatch/sandpatch.hpp>

namespace sandpatch::api::test {

// A small flat terrain without granular patches: 41 × 41 samples at 0.25 m (10 m × 10 m) at
// y = 1 m; creation is instant (no granule tile).
inline TerrainDef flat_def() {
  TerrainDef d;
  d.procedural = "flat";
  d.samples_x = d.samples_z = 41;
  d.spacing = 0.25;
  d.base_height = 1.0f;
  d.granular_patches = false;
  return d;
}

// Granular patches with coarse granules (granule_radius 5 cm, d = 10 cm, so a patch holds a
// few hundred granules and a test takes seconds), stiff enough for a 20 kg sphere landing at
// 2.4 m/s (k_n = 1e5 N/m, the scene files' default): 41 × 41 samples at 0.1 m (4 m × 4 m) at
// y = 1 m, one slot of 6000 granules, patches 0.3 m deep.
inline TerrainDef sand_def() {
  TerrainDef d = flat_def();
  d.spacing = 0.1;
  d.granular_patches = true;
  d.material.granule_radius = 0.05;
  d.material.stiffness = 1.0e5;
  d.slots = 1;
  d.granules_per_slot = 6000;
  d.patch_depth = 0.3;
  // No frame budget: its choices follow the machine's clock, and these tests compare states.
  d.frame_budget_ms = std::numeric_limits<double>::infinity();
  return d;
}

}  // namespace sandpatch::api::test
