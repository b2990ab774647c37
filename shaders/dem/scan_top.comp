// Grid stage 2b (one workgroup of 256): exclusive prefix sum of the block totals, in place
// (each block's offset: common.glsl cell_begin).
// Invocation t owns a contiguous run of ceil(blocks / 256) blocks: it sums them, the 256
// sums are scanned in shared memory, then it writes its blocks' offsets. cell_start[cells]
// = total.
layout(local_size_x = 256) in;
shared uint partial[256];
uniform uint u_blocks;

void main() {
  uint t = gl_LocalInvocationID.x;
  uint per = (u_blocks + 255u) / 256u;
  uint b0 = min(t * per, u_blocks), b1 = min(b0 + per, u_blocks);
  uint sum = 0u;
  for (uint b = b0; b < b1; ++b) sum += G.block_sum[b];
  partial[t] = sum;
  memoryBarrierShared();
  barrier();
  SP_SCAN256(partial, t)
  uint run = partial[t] - sum;
  for (uint b = b0; b < b1; ++b) {
    uint v = G.block_sum[b];
    G.block_sum[b] = run;
    run += v;
  }
  if (t == 255u) G.cell_start[u_cells] = partial[255];
}
