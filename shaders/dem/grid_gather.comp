// Grid stage 4: the sphere at place p of the scatter's order (particle `id`, at slot s of P)
// takes sorted place i = its cell's start + the number of spheres of its cell with a smaller
// particle id, so each cell's spheres are in id order and the sorted order is a function of
// the state only, whatever order the scatter's atomics gave. It gets every field of P[s] in
// the scratch block Pn (grid_copyback.comp copies it back to P; SP_COPY_PARTICLE is generated
// from fields.hpp), and slot_of and the position at sort time are updated. Each invocation
// reads and writes only slot_of[its own id], so the update is safe in place.
layout(local_size_x = SP_WG) in;

void main() {
  uint p = gl_GlobalInvocationID.x;
  if (p >= u_np) return;
  const int id = S.order[p];
  const int s = S.slot_of[id];
  const uint c = S.cell_of[s];
  const uint a = cell_begin(c), b = cell_begin(c + 1u);
  uint rank = 0u;
  for (uint k = a; k < b; ++k) rank += S.order[k] < id ? 1u : 0u;
  const uint i = a + rank;
  SP_COPY_PARTICLE(Pn, i, P, s)
  S.slot_of[id] = int(i);
  S.pos_at_sort[i] = P.pos[s];
}
