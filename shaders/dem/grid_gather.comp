// Grid stage 5: the particle at sorted place i gets every field of particle order[i] in the
// scratch block Pn (grid_copyback.comp copies it back to P)
// (SP_COPY_PARTICLE is generated from fields.hpp), and slot_of is updated. Each invocation
// reads and writes only slot_of[its own id], so the update is safe in place.
layout(local_size_x = SP_WG) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= u_np) return;
  int id = S.order[i];
  int s = S.slot_of[id];
  SP_COPY_PARTICLE(Pn, i, P, s)
  S.slot_of[id] = int(i);
  S.pos_at_sort[i] = P.pos[s];
}
