// Grid stage 4: sort each cell's particle ids (insertion sort; cells hold a few spheres),
// so the sorted order is a function of the state only. Resets the fill counter.
layout(local_size_x = SP_WG) in;

void main() {
  uint c = gl_GlobalInvocationID.x;
  if (c >= u_cells) return;
  uint a = cell_begin(c), b = cell_begin(c + 1u);
  for (uint i = a + 1u; i < b; ++i) {
    int v = S.order[i];
    uint j = i;
    while (j > a && S.order[j - 1u] > v) {
      S.order[j] = S.order[j - 1u];
      --j;
    }
    S.order[j] = v;
  }
  G.cell_count[c] = 0u;
}
