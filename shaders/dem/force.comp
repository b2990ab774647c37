// Contact stage: every sphere (sorted order) searches the 27 cells around its own, and
// sums its own contact forces and torques in a fixed order (cells z, y, x; inside a cell
// by particle id), so the result does not depend on scheduling and needs no atomics.
// Each pair is computed by both its spheres; the two computations see exactly negated
// inputs, so they give exactly opposite forces and springs (round-to-nearest is symmetric).
//
// The laws are particles/contact.hpp's contact_force, operation by operation:
//   n = unit normal from the partner to this sphere, delta = r_i + r_j - |x_i - x_j|,
//   v = (u_i + w_i x (-r_i n)) - (u_j + w_j x (r_j n)) = (u_i - u_j) + n x (r_i w_i + r_j w_j)
//   f_n = max(0, k_n delta - c_n v.n),  c_n = 2 zeta sqrt(k_n m_eff) = cn0 / sqrt(1/m_i + 1/m_j);
//     in a contact's first substep the dashpot is c_n (min(delta/dt, |v.n|) + |v.n|/2) with the
//     sign of v.n (contact.hpp). The sphere velocities are the bodies' predicted to this
//     substep's time, v + u_pred dt a_prev, translation only (bodies.comp), as on the CPU.
//   SpringHistory: xi rotated into the tangent plane (length kept), xi += v_t dt, slip
//     shortens xi to mu f_n / k_t, f_t = -k_t xi - beta c_t v_t, largest beta in [0, 1]
//     with |f_t| <= mu f_n.   Bell: f_t = -min(mu f_n, k_b |v_t|) v_t / |v_t|
// Springs live in SP_K slots per sphere (by particle id), keyed by the partner's id; a
// contact that ends forgets its spring. A touching partner without a slot from the last
// substep is a new contact (first substep); with Bell's law the slots carry only that (xi 0).
// Boundary planes (floor; side walls) use the same law with their own springs (W, slot per
// plane; a plane not in the last substep's mask is new) and c_n from the sphere's body mass.
layout(local_size_x = SP_WG) in;

uniform float u_kn, u_cn0, u_kt, u_ctr, u_mu, u_kb, u_dt;
uniform bool u_bell;
uniform bool u_first_law;  // the first-substep dashpot is on (Simulation::contact_timing_on)
uniform float u_floor_y;
uniform bool u_walls;
// terrain outside the filled rectangle (dem.hpp TerrainGrid): bilinear heights
uniform bool u_terrain;
uniform ivec2 u_tn;          // nx, nz
uniform vec2 u_t0;           // x0, z0 (m)
uniform float u_tspacing;    // m
uniform vec4 u_fill;         // fill_min_x, fill_min_z, fill_max_x, fill_max_z (m)

float terrain_h(int ix, int iz) { return S.terrain[iz * u_tn.x + ix]; }
// TerrainGrid::height: bilinear, clamped at the grid edge
float terrain_height(float x, float z) {
  const int nx = u_tn.x, nz = u_tn.y;
  float fx = clamp((x - u_t0.x) / u_tspacing, 0.0, float(nx - 1));
  float fz = clamp((z - u_t0.y) / u_tspacing, 0.0, float(nz - 1));
  int ix = min(int(fx), nx - 2 < 0 ? 0 : nx - 2), iz = min(int(fz), nz - 2 < 0 ? 0 : nz - 2);
  int ix1 = min(ix + 1, nx - 1), iz1 = min(iz + 1, nz - 1);
  float tx = fx - float(ix), tz = fz - float(iz);
  return (1.0 - tz) * ((1.0 - tx) * terrain_h(ix, iz) + tx * terrain_h(ix1, iz)) +
         tz * ((1.0 - tx) * terrain_h(ix, iz1) + tx * terrain_h(ix1, iz1));
}
// TerrainGrid::normal: central differences over half a spacing
vec3 terrain_normal(float x, float z) {
  float e = 0.5 * u_tspacing;
  float dhdx = (terrain_height(x + e, z) - terrain_height(x - e, z)) / (2.0 * e);
  float dhdz = (terrain_height(x, z + e) - terrain_height(x, z - e)) / (2.0 * e);
  vec3 n = vec3(-dhdx, 1.0, -dhdz);
  return n * (1.0 / sqrt(dot(n, n)));
}

struct ContactOut {
  vec3 f;      // total force on this sphere, N
  vec3 ft;     // tangential part, N
  float energy;
};

// first: the contact's first substep (contact.hpp ContactParams::new_contact)
ContactOut contact_force(float cn, vec3 n, float delta, vec3 v, bool first, inout vec3 xi) {
  ContactOut o;
  float vn = dot(v, n);
  float fd = cn * vn;
  if (first && u_first_law) {
    const float avn = abs(vn);
    const float dd = delta < avn * u_dt ? delta / u_dt : avn;
    fd = (vn < 0.0 ? -1.0 : 1.0) * (cn * (dd + 0.5 * avn));
  }
  float fn = u_kn * delta - fd;
  fn = fn > 0.0 ? fn : 0.0;
  vec3 vt = v - vn * n;
  vec3 ft = vec3(0.0);
  if (!u_bell) {
    float ct = u_ctr * cn;
    float xi2 = dot(xi, xi);
    if (xi2 > 0.0) {
      vec3 xr = xi - dot(xi, n) * n;  // rotate into the new tangent plane
      float xr2 = dot(xr, xr);
      float q = xr2 > 0.0 ? xi2 / xr2 : 0.0;
      float sc = q < 1.001 ? 0.5 * (1.0 + q) : sqrt(q);
      xi = xr2 > 0.0 ? xr * sc : vec3(0.0);
    }
    xi = xi + vt * u_dt;
    float cap = u_mu * fn;
    float xl2 = dot(xi, xi);
    if (u_kt * u_kt * xl2 > cap * cap) xi = xi * (cap / (u_kt * sqrt(xl2)));  // slip
    vec3 a = -u_kt * xi, b = -ct * vt;
    ft = a + b;
    float ft2 = dot(ft, ft);
    if (ft2 > cap * cap) {
      float bb = dot(b, b), ab = dot(a, b), aa = dot(a, a);
      float disc = ab * ab - bb * (aa - cap * cap);
      float beta = bb > 0.0 ? (-ab + sqrt(disc > 0.0 ? disc : 0.0)) / bb : 0.0;
      beta = clamp(beta, 0.0, 1.0);
      ft = a + beta * b;
    }
    o.energy = 0.5 * u_kn * delta * delta + 0.5 * u_kt * dot(xi, xi);
  } else {
    float vt2 = dot(vt, vt);
    if (vt2 > 0.0) {
      float s = sqrt(vt2);
      float m = min(u_mu * fn, u_kb * s);
      ft = vt * (-m / s);
    }
    o.energy = 0.5 * u_kn * delta * delta;
  }
  o.f = fn * n + ft;
  o.ft = ft;
  return o;
}

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
          if (d2 >= rs * rs || d2 <= 0.0 || P.body[j] == bi) continue;
          const float invm_j = P.vel[j].w;
          if (!dyn_i && invm_j == 0.0) continue;  // neither moves under forces
          const int jid = P.id[j];
          const float inv = 1.0 / sqrt(d2);
          const float dist = d2 * inv;
          const vec3 nrm = d * inv;
          const vec3 v = (ui - P.vel[j].xyz) + cross(nrm, rwi + pj.w * P.omega[j].xyz);
          const float cn = u_cn0 / sqrt(invm_i + invm_j);
          // this pair's spring from the last substep (zero for a new contact, and no slot)
          vec3 xi = vec3(0.0);
          bool first = true;
          for (uint k = 0u; k < old_count; ++k) {
            const uvec4 sl = SIn.slot[sbase + k];
            if (int(sl.w) == jid) {
              xi = uintBitsToFloat(sl.xyz);
              first = false;
              break;
            }
          }
          ContactOut cf = contact_force(cn, nrm, rs - dist, v, first, xi);
          if (found < uint(SP_K)) SOut.slot[sbase + found] = uvec4(floatBitsToUint(xi), uint(jid));
          ++found;
          if (id < jid || (B.flags[P.body[j]] & SP_BODY_STATIC) != 0u) ++owned;
          F += cf.f;
          T += (-ri) * cross(nrm, cf.ft);
        }
      }

    // boundary planes: slot 0 floor, 1..4 walls x0, x1, z0, z1, 5 terrain outside the fill
    if (invm_i > 0.0) {
      const float cnw = u_cn0 / sqrt(invm_i);
      const uint old_mask = W.mask[id];
      uint mask = 0u;
      for (int slot = 0; slot < 6; ++slot) {
        vec3 nrm;
        float dist;
        if (slot == 0) { nrm = vec3(0.0, 1.0, 0.0); dist = pi.y - u_floor_y; }
        else if (slot == 5) {
          if (!u_terrain || !(pi.x < u_fill.x || pi.x > u_fill.z || pi.z < u_fill.y || pi.z > u_fill.w)) continue;
          nrm = terrain_normal(pi.x, pi.z);
          dist = (pi.y - terrain_height(pi.x, pi.z)) * nrm.y;
        }
        else if (!u_walls) {
          // the sides of the filled rectangle (particles/dem.cpp): a wall below the outside
          // surface h, the outside solid's top edge above it
          if (!u_terrain || pi.x < u_fill.x || pi.x > u_fill.z || pi.z < u_fill.y || pi.z > u_fill.w) continue;
          vec3 inward;
          float gap, h;
          if (slot == 1) { inward = vec3(1.0, 0.0, 0.0); gap = pi.x - u_fill.x; h = terrain_height(u_fill.x - ri, pi.z); }
          else if (slot == 2) { inward = vec3(-1.0, 0.0, 0.0); gap = u_fill.z - pi.x; h = terrain_height(u_fill.z + ri, pi.z); }
          else if (slot == 3) { inward = vec3(0.0, 0.0, 1.0); gap = pi.z - u_fill.y; h = terrain_height(pi.x, u_fill.y - ri); }
          else { inward = vec3(0.0, 0.0, -1.0); gap = u_fill.w - pi.z; h = terrain_height(pi.x, u_fill.w + ri); }
          if (!(gap < ri)) continue;
          const float dy = pi.y - h;
          if (dy <= 0.0) { nrm = inward; dist = gap; }
          else {
            dist = sqrt(gap * gap + dy * dy);
            if (!(dist > 0.0)) continue;
            nrm = (inward * gap + vec3(0.0, dy, 0.0)) / dist;
          }
        }
        else if (slot == 1) { nrm = vec3(1.0, 0.0, 0.0); dist = pi.x - u_bmin.x; }
        else if (slot == 2) { nrm = vec3(-1.0, 0.0, 0.0); dist = u_bmax.x - pi.x; }
        else if (slot == 3) { nrm = vec3(0.0, 0.0, 1.0); dist = pi.z - u_bmin.z; }
        else { nrm = vec3(0.0, 0.0, -1.0); dist = u_bmax.z - pi.z; }
        if (!(dist < ri)) continue;
        ++planes;
        mask |= 1u << uint(slot);
        const uint wslot = uint(id) * 6u + uint(slot);
        const vec3 v = ui + cross(wi, nrm * (-ri));
        const bool first = (old_mask & (1u << uint(slot))) == 0u;
        vec3 xi = first ? vec3(0.0) : W.xi[wslot].xyz;
        ContactOut cf = contact_force(cnw, nrm, ri - dist, v, first, xi);
        W.xi[wslot] = vec4(xi, 0.0);
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
  if (found > 0u) atomicMax(G.status[2], found);
  if (owned > 0u) atomicAdd(G.status[3], owned);
  if (planes > 0u) atomicAdd(G.status[4], planes);
}
