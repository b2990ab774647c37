// Grid stage 5: the sorted particles go back from the scratch block to P (every field,
// generated from fields.hpp), so P is the current order without the CPU tracking a swap
// (the grid stages run only when a re-sort is needed, decided on the GPU); the cells' starts
// become final (each block's offset added: common.glsl cell_begin), for the contact stage, and
// the cells' counts are reset.
// Its first invocation ends the re-sort: lowers status.resort and zeroes the grid kernels'
// arguments. Invocations: max(spheres, cells).
layout(local_size_x = SP_WG) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i == 0u) {  // the re-sort is done: lower the flag and zero the arguments (common.glsl)
    G.status.resort = 0u;
    G.status.grid_rebuilds += 1u;
    for (int k = 0; k < SP_GRID_KERNELS; ++k) A.grid_dispatch[3 * k] = 0u;  // read at this dispatch's launch
  }
  if (i < u_cells) {
    G.cell_start[i] += G.block_sum[i / 1024u];
    G.cell_count[i] = 0u;  // for the next re-sort's count (the scatter filled it)
  }
  if (i >= u_np) return;
  SP_COPY_PARTICLE(P, i, Pn, i)
}
