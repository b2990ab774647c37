// The terrain manager's planning geometry (internal to manager/, used by planning.cpp,
// budget.cpp and filling.cpp; tests/manager/planning_test.cpp): where a patch goes on the
// heightfield, how deep, and the soil volume its ledger counts. Pure functions of the
// heightfield, no manager state.
#pragma once

#include <vector>

#include "common/error.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/lod.hpp"

namespace sandpatch {

// The terrain's world rectangle (m).
PatchRequest terrain_rect(const Heightfield& hf);

// Clips a request's rectangle to the terrain's.
void clip_to_terrain(const Heightfield& hf, PatchRequest& r);

// Region of heightfield samples for a request: the samples bracketing its rectangle, rounded
// out to whole tile periods of `tile_cells` cells (the patch's sides then fall on the walls
// the tile was settled against), centred, and kept on the terrain; where the terrain is
// narrower than the rounded patch, the cut sides stay. Error "off the terrain" when fewer
// than 3 samples remain on an axis.
Result<GridRegion> patch_region(const Heightfield& hf, const PatchRequest& r, int tile_cells);

// Floor of a patch over `region` (m, heightfield-local): patch_depth below the lowest
// surface sample, and never below the bedrock under any sample of the region (the DEM's
// floor is one plane, so it sits at the highest bedrock point: no granule below the
// bedrock anywhere; where the surface dips below that plane the patch has no granules and
// its floor holds bodies up to that much above the surface, docs/extremes.md). The bedrock
// under a sample is the higher of surface - soil_depth and min(surface, bedrock_height).
// `lo`, `hi`: the lowest and highest surface samples. A floor at or above `hi`: no soil.
double patch_floor(const Heightfield& hf, const GridRegion& region, double patch_depth, double soil_depth,
                   double bedrock_height, float* lo, float* hi);

// m³: the soil between the floor (m, local) and the bilinear surface over `region` (trapezoid
// weights: ½ on edges, ¼ at corners). The ledger's volume before promotion.
double soil_volume(const Heightfield& hf, const GridRegion& region, double floor_local);


}  // namespace sandpatch
