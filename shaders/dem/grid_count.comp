// Grid stage 1 of 5: the cell of every sphere (current order) and the count per cell.
// Integer atomics only; the counts do not depend on the order the invocations run in.
layout(local_size_x = SP_WG) in;

void main() {
  uint s = gl_GlobalInvocationID.x;
  if (s >= u_np) return;
  uint c = cell_index(cell3(P.pos[s].xyz));
  S.cell_of[s] = c;
  atomicAdd(G.cell_count[c], 1u);
}
