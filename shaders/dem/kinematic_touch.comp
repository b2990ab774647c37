// Asleep simulations (dem_grid.cpp kinematic_touch): would a moving kinematic sphere, moved by
// the frame's dt, come within contact range + skin/2 of a dynamic sphere? Then status.kinematic_touch = 1
// and the simulation wakes. The grid is still valid: the dynamic spheres have not moved
// since it was built (less than skin/2), so the 27 cells around the moved sphere hold them.
layout(local_size_x = SP_WG) in;

uniform float u_dt;         // s, the whole frame
uniform float u_half_skin;  // m

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= u_np) return;
  const int b = P.body[i];
  if ((B.flags[b] & SP_BODY_KINEMATIC) == 0u) return;
  const vec3 v = B.vel[b].xyz, w = B.omega[b].xyz;
  if (dot(v, v) == 0.0 && dot(w, w) == 0.0) return;
  const vec3 x = B.pos[b].xyz + u_dt * v;
  vec4 q = B.quat[b];
  q = quat_normalized(q + (0.5 * u_dt) * quat_mul(vec4(w, 0.0), q));
  const vec3 xs = x + quat_rotate(q, P.offset[i].xyz);
  const float r = P.pos[i].w;
  const ivec3 c = cell3(xs);
  for (int zz = max(c.z - 1, 0); zz <= min(c.z + 1, u_grid.z - 1); ++zz)
    for (int yy = max(c.y - 1, 0); yy <= min(c.y + 1, u_grid.y - 1); ++yy) {
      const int row = (zz * u_grid.y + yy) * u_grid.x;
      const uint j1 = G.cell_start[row + min(c.x + 1, u_grid.x - 1) + 1];
      for (uint j = G.cell_start[row + max(c.x - 1, 0)]; j < j1; ++j) {
        if (P.vel[j].w == 0.0) continue;  // not dynamic
        const int bj = P.body[j];
        if (!spheres_interact(b, B.group[b], bj, B.group[bj])) continue;  // jointed to it
        const vec3 d = xs - P.pos[j].xyz;
        const float rs = r + P.pos[j].w + u_half_skin;
        if (dot(d, d) < rs * rs) atomicOr(G.status.kinematic_touch, 1u);
      }
    }
}
