// Grid stage 2c: add each block's offset to its cells' starts; reset the counts, which the
// scatter then uses as fill counters.
layout(local_size_x = SP_WG) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= u_cells) return;
  G.cell_start[i] += G.block_sum[i / 1024u];
  G.cell_count[i] = 0u;
}
