// Contact stage: every sphere (sorted order) searches the 27 cells around its own, and
// sums its own contact forces and torques in a fixed order (cells z, y, x; inside a cell
// by particle id), so the result does not depend on scheduling and needs no atomics.
// Each pair is computed by both its spheres; the two computations see exactly negated
// inputs, so they give exactly opposite forces and springs (round-to-nearest is symmetric).
//
// The law, the terrain and the boundary planes are physics_common.glsl's (the CPU backend's
// own source: contact_force, terrain_height/terrain_normal, boundary_plane):
//   n = unit normal from the partner to this sphere, delta = r_i + r_j - |x_i - x_j|,
//   v = (u_i - u_j) + n x (r_i w_i + r_j w_j) (pair_contact_velocity),
//   c_n = 2 zeta sqrt(k_n m_eff) = cn0 / sqrt(1/m_i + 1/m_j). The sphere velocities are the
//   bodies' predicted to this substep's time, v + u_pred dt a_prev, translation only
//   (bodies.comp), as on the CPU.
// Springs live in SP_K slots per sphere (by particle id), keyed by the partner's id, with the
// contact's largest overlap beside them (dmax, the hysteretic normal spring's history; both
// spheres of a pair see the same overlap, so they keep the same dmax); a contact that ends
// forgets its spring. A touching partner without a slot from the last
// substep is a new contact (first substep).
// Spheres of one body, or of two bodies of one collision group, do not touch
// (physics_common.glsl spheres_interact).
// Boundary planes (floor; side walls; terrain) use the same law with their own springs (W,
// slot per plane; a plane not in the last substep's mask is new) and c_n from the sphere's
// body mass.
layout(local_size_x = SP_WG) in;

uniform float u_kn, u_cn0, u_kt, u_ctr, u_mu, u_dt;
uniform float u_kn2;       // unloading stiffness (N/m): k_n x Material::unloading_stiffness_ratio (k_n: linear)
uniform bool u_first_law;  // the first-substep dashpot is on (Simulation::contact_timing_on)
uniform float u_floor_y;
uniform bool u_walls;
// terrain outside the filled rectangle (dem.hpp TerrainGrid): bilinear heights
uniform bool u_terrain;
uniform ivec2 u_tn;          // nx, nz
uniform vec2 u_t0;           // x0, z0 (m)
uniform float u_tspacing;    // m
uniform vec4 u_fill;         // fill_min_x, fill_min_z, fill_max_x, fill_max_z (m)

void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i >= u_np) return;
  const int id = P.id[i];
  vec3 F = vec3(0.0), T = vec3(0.0);
  float E = 0.0;
  uint found = 0u;   // touching partners (springs needed)
  uint owned = 0u;   // pairs this sphere owns in the CPU's count (lower id, or static partner)
  uint planes = 0u;
  const int bi = P.body[i];
  const int gi = B.group[bi];
  if ((B.flags[bi] & SP_BODY_STATIC) == 0u) {
    const vec3 pi = P.pos[i].xyz;
    const float ri = P.pos[i].w;
    const vec3 ui = P.vel[i].xyz;
    const float invm_i = P.vel[i].w;
    const vec3 wi = P.omega[i].xyz;
    const vec3 rwi = ri * wi;
    const bool dyn_i = invm_i > 0.0;
    const uint old_count = SIn.count[id];
    const uint sbase = uint(id) * uint(SP_K);

    // sphere-sphere: 27 cells, z then y then x rows (a row of 3 cells is one range)
    const ivec3 c = cell3(pi);
    const int x0 = max(c.x - 1, 0), x1 = min(c.x + 1, u_grid.x - 1);
    for (int zz = max(c.z - 1, 0); zz <= min(c.z + 1, u_grid.z - 1); ++zz)
      for (int yy = max(c.y - 1, 0); yy <= min(c.y + 1, u_grid.y - 1); ++yy) {
        const int row = (zz * u_grid.y + yy) * u_grid.x;
        const uint j1 = G.cell_start[row + x1 + 1];
        for (uint j = G.cell_start[row + x0]; j < j1; ++j) {
          const vec4 pj = P.pos[j];
          const vec3 d = pi - pj.xyz;
          const float rs = ri + pj.w;
          const float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
          if (d2 >= rs * rs || d2 <= 0.0) continue;
          const int bj = P.body[j];
          if (!spheres_interact(bi, gi, bj, B.group[bj])) continue;  // same body or collision group
          const float invm_j = P.vel[j].w;
          if (!dyn_i && invm_j == 0.0) continue;  // neither moves under forces
          const int jid = P.id[j];
          const float inv = 1.0 / sqrt(d2);
          const float dist = d2 * inv;
          const vec3 nrm = d * inv;
          const vec3 v = pair_contact_velocity(ui, P.vel[j].xyz, nrm, rwi + pj.w * P.omega[j].xyz);
          const float cn = u_cn0 / sqrt(invm_i + invm_j);
          // this pair's spring from the last substep (zero for a new contact, and no slot)
          vec3 xi = vec3(0.0);
          float dm = 0.0;
          bool first = true;
          for (uint k = 0u; k < old_count; ++k) {
            const uvec4 sl = SIn.slot[sbase + k];
            if (int(sl.w) == jid) {
              xi = uintBitsToFloat(sl.xyz);
              dm = SIn.dmax[sbase + k];
              first = false;
              break;
            }
          }
          const ContactForce cf = contact_force_h(ContactParams(u_kn, cn, u_kt, u_ctr * cn, u_mu, u_dt, first && u_first_law),
                                                  u_kn2, nrm, rs - dist, v, xi, dm);
          if (found < uint(SP_K)) {
            SOut.slot[sbase + found] = uvec4(floatBitsToUint(xi), uint(jid));
            SOut.dmax[sbase + found] = dm;
          }
          ++found;
          if (id < jid || (B.flags[P.body[j]] & SP_BODY_STATIC) != 0u) ++owned;
          F += cf.f;
          T += (-ri) * cross(nrm, cf.ft);
        }
      }

    // boundary planes (physics_common.glsl boundary_plane), in slot order as the CPU
    if (invm_i > 0.0) {
      const float cnw = u_cn0 / sqrt(invm_i);
      const uint old_mask = W.mask[id];
      uint mask = 0u;
      const Boundaries bnd = Boundaries(u_floor_y, u_walls, u_terrain, u_bmin, u_bmax);
      const TerrainGrid tg = TerrainGrid(u_tn.x, u_tn.y, u_t0.x, u_t0.y, u_tspacing, u_fill.x, u_fill.y, u_fill.z, u_fill.w);
      for (int slot = 0; slot < SP_PLANE_SLOTS; ++slot) {
        vec3 nrm;
        float dist;
        if (!boundary_plane(bnd, tg, slot, pi, ri, nrm, dist)) continue;
        ++planes;
        mask |= 1u << uint(slot);
        const uint wslot = uint(id) * uint(SP_PLANE_SLOTS) + uint(slot);
        const vec3 v = plane_contact_velocity(ui, wi, nrm, ri);
        const bool first = (old_mask & (1u << uint(slot))) == 0u;
        const vec4 wx = first ? vec4(0.0) : W.xi[wslot];
        vec3 xi = wx.xyz;
        float dm = wx.w;
        const ContactForce cf = contact_force_h(ContactParams(u_kn, cnw, u_kt, u_ctr * cnw, u_mu, u_dt, first && u_first_law),
                                                u_kn2, nrm, ri - dist, v, xi, dm);
        W.xi[wslot] = vec4(xi, dm);
        F += cf.f;
        T += cross(nrm * (-ri), cf.ft);
        E += cf.energy;
      }
      W.mask[id] = mask;
    }
  }
  SOut.count[id] = min(found, uint(SP_K));
  P.force[i] = vec4(F, E);
  P.torque[i] = vec4(T, 0.0);
  if (found > 0u) atomicMax(G.status.max_partners, found);
  if (owned > 0u) atomicAdd(G.status.contacts, owned);
  if (planes > 0u) atomicAdd(G.status.plane_contacts, planes);
}
