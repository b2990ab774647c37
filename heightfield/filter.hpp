// Smoothing of heightfield regions (Leach & Marais §5.2): the height map rendered from a
// demoted particle patch is smoothed with a 3x3 Gaussian, written into the heightfield,
// and a 3x3 Gaussian is applied again along the border of the written region so the patch
// joins its surroundings without a step.
//
// Kernel: the 3x3 binomial [1 2 1]^T [1 2 1] / 16, applied as two passes of [1 2 1]/4
// (exactly the same weights). All outputs are computed from the values before the call.
//
// Neighbours outside the region are read from the grid where they exist. Beyond the grid
// edge the missing neighbour is extrapolated linearly, h[-1] = 2 h[0] - h[1] (an odd
// reflection), instead of replicated: replication would bend a sloping plane at the edge,
// extrapolation keeps constants and planes exactly. Consequence: along the axis normal to
// a grid edge, the edge samples are unchanged ((2h0-h1) + 2h0 + h1)/4 = h0; they are still
// smoothed along the edge.
#pragma once

#include "heightfield/heightfield.hpp"

namespace sandpatch {

// 3x3 Gaussian over the samples of r (r inside the grid, asserted); samples outside r are
// read but not changed.
void gaussian3x3(Heightfield& hf, GridRegion r, Layer l = Layer::Elevation);

// 3x3 Gaussian applied only to the band of `width` samples (>= 1) on each side of r's
// boundary: the outermost `width` rows/columns of r and the `width` rows/columns just
// outside it (clipped to the grid). Samples deeper inside r and farther outside are left
// exactly unchanged. For stitching a written patch into its surroundings.
void smooth_border_band(Heightfield& hf, GridRegion r, int width = 1, Layer l = Layer::Elevation);

// The smoothed values of r without writing them: ni*nj floats, row-major, x fastest.
std::vector<float> gaussian3x3_values(const Heightfield& hf, GridRegion r, Layer l = Layer::Elevation);

}  // namespace sandpatch
