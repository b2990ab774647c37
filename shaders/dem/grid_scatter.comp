// Grid stage 3: every sphere takes a place in its cell's range (integer atomic on the
// cell's fill counter) and writes its particle id there. The order inside a cell depends
// on scheduling; stage 4 makes it deterministic.
layout(local_size_x = SP_WG) in;

void main() {
  uint s = gl_GlobalInvocationID.x;
  if (s >= u_np) return;
  uint c = S.cell_of[s];
  uint k = atomicAdd(G.cell_count[c], 1u);
  S.order[cell_begin(c) + k] = P.id[s];
}
