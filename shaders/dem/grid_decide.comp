// Grid stage 0 (one invocation, once per frame before its first substep): re-sort only when
// needed. The body stage raises status.resort when a sphere has moved more than skin/2 since
// the last sort (as dem.cpp), and the host raises it after an upload or a body's move; until
// then the sorted order and cell ranges stay valid for the 27-cell search (cell = 2 r_max +
// skin: a touching partner is still in a neighbouring cell). Writes the dispatch-indirect
// arguments of the grid kernels from the flag (their workgroup counts, or 0), with this
// frame's sphere and cell counts; within the frame request_resort and grid_copyback.comp keep
// them in step with the flag (common.glsl).
layout(local_size_x = 1) in;

void main() { write_grid_dispatch(G.status.resort != 0u); }
