// Grid stage 0 (one invocation): re-sort only when needed. The body stage raises status.resort
// when a sphere has moved more than skin/2 since the last sort (as dem.cpp), and an upload
// raises it; until then the sorted order and cell ranges stay valid for the 27-cell search
// (cell = 2 r_max + skin: a touching partner is still in a neighbouring cell). Writes the
// dispatch-indirect arguments of the grid kernels: their workgroup counts, or 0.
layout(local_size_x = 1) in;

void main() {
  const bool resort = G.status.resort != 0u;
  const uint per_sphere = (u_np + uint(SP_WG) - 1u) / uint(SP_WG);
  const uint per_cell = (u_cells + uint(SP_WG) - 1u) / uint(SP_WG);
  // order of SP_GRID_* in particles/gpu/gl_simulation.cpp
  uint groups[8] = uint[8](per_sphere, (u_cells + 1023u) / 1024u, 1u, per_cell, per_sphere, per_cell,
                                 per_sphere, per_sphere);
  for (int k = 0; k < SP_GRID_KERNELS; ++k) {
    G.status.grid_dispatch[3 * k] = resort ? groups[k] : 0u;
    G.status.grid_dispatch[3 * k + 1] = 1u;
    G.status.grid_dispatch[3 * k + 2] = 1u;
  }
  if (resort) {
    G.status.resort = 0u;
    G.status.grid_rebuilds += 1u;
  }
}
