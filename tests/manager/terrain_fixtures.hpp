// Terrains shared by the terrain manager's tests (tests/manager/terrain_manager*_test.cpp):
// 8 m × 8 m at 0.1 m spacing, the surface near y = 1 m.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "heightfield/heightfield.hpp"
#include "heightfield/procedural.hpp"

namespace sandpatch::test {

// kind "flat": y = 1 m; "hills": ±5 cm over a 4 m period around y = 1 m.
inline Heightfield terrain_8m(const std::string& kind) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = 81;
  g.spacing = 0.1f;
  ProceduralHeightsDef p;
  p.kind = kind;
  p.height = 1.0f;
  if (kind == "hills") {
    p.amplitude = 0.05f;
    p.wavelength = 4.0f;
  }
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << (hf.ok() ? "" : hf.message());
  return std::move(*hf);
}

}  // namespace sandpatch::test
