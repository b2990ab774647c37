// Grid stage 2a: exclusive prefix sum of the cell counts within blocks of 1024 cells
// (256 invocations x 4 cells); each block's total goes to block_sum. The counts are reset as
// they are read: the scatter uses them as fill counters. cell_start holds the start within
// the block until grid_copyback.comp adds the block's offset (common.glsl cell_begin).
layout(local_size_x = 256) in;
shared uint partial[256];

void main() {
  uint t = gl_LocalInvocationID.x;
  uint base = gl_WorkGroupID.x * 1024u + t * 4u;
  uint v[4];
  uint sum = 0u;
  for (uint k = 0u; k < 4u; ++k) {
    v[k] = base + k < u_cells ? G.cell_count[base + k] : 0u;
    if (base + k < u_cells) G.cell_count[base + k] = 0u;
    sum += v[k];
  }
  partial[t] = sum;
  memoryBarrierShared();
  barrier();
  SP_SCAN256(partial, t)
  uint run = partial[t] - sum;  // exclusive prefix of this invocation's first cell
  for (uint k = 0u; k < 4u; ++k) {
    if (base + k < u_cells) G.cell_start[base + k] = run;
    run += v[k];
  }
  if (t == 255u) G.block_sum[gl_WorkGroupID.x] = partial[255];
}
