// Grid stage 6: the sorted particles go back from the scratch block to P (every field,
// generated from fields.hpp), so P is the current order without the CPU tracking a swap
// (the grid stages run only when a re-sort is needed, decided on the GPU).
layout(local_size_x = SP_WG) in;

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= u_np) return;
  SP_COPY_PARTICLE(P, i, Pn, i)
}
