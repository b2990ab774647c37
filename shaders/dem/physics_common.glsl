// The granule DEM's physics, one source for both backends (the way Jolt shares its shader
// structs between C++ and HLSL): the contact law, the terrain sampling, the boundary planes
// and the GL status block. Compiled
//   as C++:  particles/dem_physics.hpp includes it inside namespace sandpatch::physics after
//            a prelude; the CPU backend (particles/dem_contacts.cpp, dem_boundaries.cpp) calls them;
//   as GLSL: particles/gpu/gl_programs.cpp prepends it (before common.glsl) to every kernel of
//            shaders/dem/; force.comp calls these functions.
// So it is written in the common subset of C++20 and GLSL 4.30:
//   - types vec3, uint and the built-ins dot, cross, sqrt, abs, min, clamp: GLSL's own; the
//     C++ prelude maps them to math.hpp's Vec3 and <cmath>/<algorithm> (the float operations
//     the CPU backend has always done, so its results are unchanged bit for bit)
//   - SP_INLINE (C++ inline), SP_INOUT(T) / SP_OUT(T) (C++ T&; GLSL inout T / out T)
//   - structs built as T(a, b, ...) (C++20 parenthesised aggregate initialisation)
//   - float literals with a point and an f suffix (1.0f), no implicit int -> float
//   - SP_TERRAIN_GRID / SP_TERRAIN_AT(t, ix, iz): the terrain grid argument and one height
//     sample (C++: TerrainGrid::heights; GLSL: the Sort block's terrain[] of common.glsl)
// contact_avx2.cpp keeps an 8-lane AVX2 copy of contact_force for the CPU pair pass; it is
// checked against this one by tests/particles/contact_avx2_test.cpp.
//
// Units: simulation units (patch-relative, unit particle scale): m, s, kg, N.

#ifndef __cplusplus
// GLSL prelude (the C++ one is in particles/dem_physics.hpp).
#define SP_INLINE
#define SP_INOUT(T) inout T
#define SP_OUT(T) out T
// The terrain grid's description (dem.hpp TerrainGrid without its heights: m, sim units);
// force.comp builds it from its uniforms.
struct TerrainGrid {
  int nx;
  int nz;
  float x0;
  float z0;
  float spacing;
  float fill_min_x;
  float fill_min_z;
  float fill_max_x;
  float fill_max_z;
};
#define SP_TERRAIN_GRID TerrainGrid
float terrain_sample(int k);  // heights[k], m (common.glsl: the Sort block's terrain[])
#define SP_TERRAIN_AT(t, ix, iz) terrain_sample((iz) * (t).nx + (ix))
#endif

// ---- GL status block (buffer binding 3, first member; std430) -------------------------------
// Written by the kernels, read back once per frame by GlSimulation::step
// (particles/gpu/gl_simulation.cpp).
// C++ checks its size and offsets with static_asserts (particles/dem_physics.hpp).
#define SP_GRID_KERNELS 6  // grid kernels run by indirect dispatch (particles/gpu/gl_impl.hpp: kGridCount..)
struct DemStatus {
  uint max_granule_speed;  // float bits of max |v| + |w| (d + r) over granules (m/s; >= 0 orders like its bits)
  uint nonfinite_bodies;   // bodies whose state became non-finite
  uint max_partners;       // most touching partners of one sphere (spring slots needed)
  uint contacts;           // sphere-sphere contacts (pairs, owner side as the CPU counts)
  uint plane_contacts;     // sphere-plane contacts (floor, walls, terrain)
  uint resort;             // 1: re-sort needed (a sphere moved > skin/2 since the sort, or an upload)
  uint grid_rebuilds;      // grid rebuilds this frame
  uint kinematic_touch;    // asleep frame: 1 if a moving kinematic sphere reaches a dynamic one
};

// ---- Which spheres touch ----
// Two spheres interact unless they belong to the same body, or to two bodies of the same
// collision group > 0 (ShellDef::group, Simulation::set_body_group: the terrain manager puts bodies joined
// by joints in one group, as Bullet stops colliding jointed bodies, so a vehicle's wheel and
// chassis shells do not push each other apart). Granules are in no group (0): they touch
// every shell. Both backends' pair searches ask this (dem_grid.cpp, force.comp).
SP_INLINE bool spheres_interact(int body_i, int group_i, int body_j, int group_j) {
  return body_i != body_j && (group_i == 0 || group_i != group_j);
}

// ---- Contact law (Bell et al. 2005 normal spring-dashpot; Cundall & Strack 1979 spring) ----
// For one sphere of a pair or a sphere against a plane. Notation: n = unit normal from the
// partner to this sphere; delta = overlap (m); v = velocity of this sphere's contact point
// relative to the partner's (m/s).
//   normal      f_n = max(0, f_el - d), f_el = k_n delta (or hysteretic: contact_force_h),
//               d = c_n v.n; in the first substep of a contact
//               (new_contact) |d| = c_n (min(delta/dt, |v.n|) + |v.n|/2) instead, with the
//               sign of v.n                                              (N, never attractive)
//   tangential  v_t = v - (v.n) n; xi <- xi - (xi.n) n, rescaled to its old length;
//               xi <- xi + v_t dt; slip: if k_t |xi| > mu f_n, xi is shortened to
//               |xi| = mu f_n / k_t; then f_t = -k_t xi - beta c_t v_t with the largest beta
//               in [0, 1] that keeps |f_t| <= mu f_n.
// Why not LAMMPS' xi <- -(f_t + c_t v_t)/k_t: that stores the damper's force in the spring and
// releases it later as work, so energy can rise (measured: +0.3 % of the total in one step in a
// damped granule gas). Here the spring is only ever shortened by slip and the damper only ever
// removes energy.
struct ContactParams {
  float kn;          // N/m
  float cn;          // N s/m for this pair (2 zeta sqrt(k_n m_eff))
  float kt;          // N/m
  float ct;          // N s/m (tangential damping)
  float mu;          // Coulomb friction coefficient
  float dt;          // s, substep
  bool new_contact;  // first substep of the contact (it did not touch at the previous substep)
};

struct ContactForce {
  vec3 f;        // total force on this sphere, N
  vec3 ft;       // tangential part, N
  float energy;  // elastic energy of the contact's springs, J
};

// xi is the tangential spring (m) of this contact from the previous substep (zero for a new
// contact); it is updated in place.
//
// Dashpot c_n vn: the caller passes v at the substep's time t_n (the body stage predicts the
// bodies' translation as v + (dt/2) a_prev, symplectic Euler's v being half a step old; less at
// large damping per substep, Simulation::velocity_predictor_gain). The kick at t_n stands for
// [t_n - dt/2, t_n + dt/2]; in the first substep of a contact the touch was delta/|vn| before
// t_n (delta < |vn| dt for an approach from outside), so the dashpot's impulse from the touch
// to t_n + dt/2 is c_n (delta + |vn| dt/2): |fd| = c_n (delta/dt + |vn|/2), with delta/dt
// capped at |vn| (a contact that did not start by approach, e.g. a body placed overlapping,
// gets at most 1.5 c_n |vn|). With the full c_n |vn| whatever the phase of the touch, e = 0.1
// at dt = t_contact/50 came out -17 % ... +2 % with the phase; with this and the predictor,
// -1.2 ... -1.0 % (docs/dem.md "Step size"). Only the first substep: a cap on every contact
// with delta < |vn| dt also strips the damping from lightly loaded resting contacts (overlap
// ~ m g / k_n) and beds stopped settling (measured, ibid.). fd has the sign of vn, so the
// dashpot still opposes the normal motion.
//
// Hysteretic normal spring (Walton & Braun 1986, J. Rheol. 30:949), used when kn2 > k_n:
// loading (delta at its largest of the contact, dmax) along k_n, unloading and reloading along
// the stiffer kn2 from delta0 = dmax (1 - k_n/kn2): f_el = min(k_n delta, kn2 (delta - delta0)),
// at least 0. A load-unload cycle gives back k_n/kn2 of the energy the loading stored, however
// slowly it runs (the dashpot takes only a part ~ zeta omega of a slow cycle: the collective
// modes of a bed, far slower than one contact, were left nearly undamped). dmax (m) is the
// contact's history beside xi (0 for a new contact); kn2 <= k_n: the linear spring, dmax untouched.
SP_INLINE ContactForce contact_force_h(ContactParams p, float kn2, vec3 n, float delta, vec3 v, SP_INOUT(vec3) xi,
                                       SP_INOUT(float) dmax) {
  ContactForce o;
  float vn = dot(v, n);
  float fd = p.cn * vn;
  if (p.new_contact) {
    const float avn = abs(vn);
    const float dd = delta < avn * p.dt ? delta / p.dt : avn;
    fd = (vn < 0.0f ? -1.0f : 1.0f) * (p.cn * (dd + 0.5f * avn));
  }
  float fel = p.kn * delta;
  float uel = 0.5f * p.kn * delta * delta;  // J, the normal spring's energy (recoverable)
  if (kn2 > p.kn) {
    dmax = delta > dmax ? delta : dmax;
    const float d0 = dmax * (1.0f - p.kn / kn2);
    const float fu = kn2 * (delta - d0);
    fel = fu < fel ? fu : fel;
    fel = fel > 0.0f ? fel : 0.0f;
    uel = fel * fel / (2.0f * kn2);
  }
  float fn = fel - fd;
  fn = fn > 0.0f ? fn : 0.0f;
  vec3 vt = v - vn * n;
  float xi2 = dot(xi, xi);
  if (xi2 > 0.0f) {
    vec3 xr = xi - dot(xi, n) * n;  // rotate into the new tangent plane
    float xr2 = dot(xr, xr);
    // rescale to the old length: sqrt(q), q = xi2/xr2 >= 1. The normal turns by O(v dt / r)
    // per substep, so q - 1 is tiny and (1 + q)/2 matches sqrt(q) to (q-1)^2/8; fall back to
    // the sqrt for larger turns.
    float q = xr2 > 0.0f ? xi2 / xr2 : 0.0f;
    float sc = q < 1.001f ? 0.5f * (1.0f + q) : sqrt(q);
    xi = xr2 > 0.0f ? xr * sc : vec3(0.0f, 0.0f, 0.0f);
  }
  xi = xi + vt * p.dt;
  const float cap = p.mu * fn;
  float xl2 = dot(xi, xi);
  if (p.kt * p.kt * xl2 > cap * cap) xi = xi * (cap / (p.kt * sqrt(xl2)));  // slip
  vec3 a = -p.kt * xi;
  vec3 b = -p.ct * vt;
  vec3 ft = a + b;
  float ft2 = dot(ft, ft);
  if (ft2 > cap * cap) {
    // largest beta with |a + beta b| <= cap; |a| <= cap so beta = 0 is always feasible
    float bb = dot(b, b);
    float ab = dot(a, b);
    float aa = dot(a, a);
    float disc = ab * ab - bb * (aa - cap * cap);
    float beta = bb > 0.0f ? (-ab + sqrt(disc > 0.0f ? disc : 0.0f)) / bb : 0.0f;
    beta = beta < 0.0f ? 0.0f : (beta > 1.0f ? 1.0f : beta);
    ft = a + beta * b;
  }
  o.energy = uel + 0.5f * p.kt * dot(xi, xi);
  o.f = fn * n + ft;
  o.ft = ft;
  return o;
}

// The linear spring (no hysteresis): contact_force_h with kn2 = k_n.
SP_INLINE ContactForce contact_force(ContactParams p, vec3 n, float delta, vec3 v, SP_INOUT(vec3) xi) {
  float dm = 0.0f;
  return contact_force_h(p, p.kn, n, delta, v, xi, dm);
}

// Velocity (m/s) of sphere i's contact point relative to sphere j's, n the unit normal from j
// to i: (u_i + w_i x (-r_i n)) - (u_j + w_j x (r_j n)) = (u_i - u_j) + n x (r_i w_i + r_j w_j),
// rw = r_i w_i + r_j w_j.
SP_INLINE vec3 pair_contact_velocity(vec3 ui, vec3 uj, vec3 n, vec3 rw) { return (ui - uj) + cross(n, rw); }

// Velocity (m/s) of a sphere's contact point on a plane with unit normal n (into the domain).
SP_INLINE vec3 plane_contact_velocity(vec3 u, vec3 w, vec3 n, float r) { return u + cross(w, n * (-r)); }

// ---- Terrain outside the filled region (dem.hpp TerrainGrid) --------------------------------
// h(x, z) bilinear between samples heights[iz * nx + ix] at (x0 + ix spacing, z0 + iz spacing),
// clamped at the grid edge (m).
SP_INLINE float terrain_height(SP_TERRAIN_GRID t, float x, float z) {
  float fx = clamp((x - t.x0) / t.spacing, 0.0f, float(t.nx - 1));
  float fz = clamp((z - t.z0) / t.spacing, 0.0f, float(t.nz - 1));
  int ix = min(int(fx), t.nx - 2 < 0 ? 0 : t.nx - 2);
  int iz = min(int(fz), t.nz - 2 < 0 ? 0 : t.nz - 2);
  int ix1 = min(ix + 1, t.nx - 1);
  int iz1 = min(iz + 1, t.nz - 1);
  float tx = fx - float(ix);
  float tz = fz - float(iz);
  return (1.0f - tz) * ((1.0f - tx) * SP_TERRAIN_AT(t, ix, iz) + tx * SP_TERRAIN_AT(t, ix1, iz)) +
         tz * ((1.0f - tx) * SP_TERRAIN_AT(t, ix, iz1) + tx * SP_TERRAIN_AT(t, ix1, iz1));
}

// Unit surface normal: central differences over half a spacing.
SP_INLINE vec3 terrain_normal(SP_TERRAIN_GRID t, float x, float z) {
  float e = 0.5f * t.spacing;
  float dhdx = (terrain_height(t, x + e, z) - terrain_height(t, x - e, z)) / (2.0f * e);
  float dhdz = (terrain_height(t, x, z + e) - terrain_height(t, x, z - e)) / (2.0f * e);
  vec3 n = vec3(-dhdx, 1.0f, -dhdz);
  return n * (1.0f / sqrt(dot(n, n)));
}

// ---- Boundary planes --------------------------------------------------------------------------
// Per sphere, 6 plane slots, each with its own tangential spring: 0 bedrock floor y = floor_y,
// 1..4 side walls x = bmin.x, x = bmax.x, z = bmin.z, z = bmax.z (or, without side walls, the
// sides of the terrain's filled rectangle), 5 the terrain surface outside the filled rectangle.
#define SP_PLANE_SLOTS 6
struct Boundaries {
  float floor_y;  // m
  bool walls;     // side walls on (SimulationDef::side_walls)
  bool terrain;   // a terrain grid is set
  vec3 bmin;      // m, SimulationDef::bounds_min
  vec3 bmax;      // m, SimulationDef::bounds_max
};

// Plane `slot` for a sphere at p of radius r (m): true when it touches, with n the unit normal
// into the domain and dist the distance (m) of the centre from the plane (< r; the overlap is
// r - dist). Called for slots 0..5 in order, so the forces add in slot order.
// The terrain outside the filled rectangle is solid up to its surface h(x, z): outside, a
// sphere rests on the surface (slot 5); inside, the rectangle's sides are walls up to the
// outside surface, so the granules of a patch are held by the soil around them and can still
// spill over the top onto the terrain. Above h the closest point of the outside solid is its
// top edge, so the contact turns continuously from the wall to the edge as a sphere rises past
// h. (A wall that simply ended at h started contacts at full overlap when a sphere sank past
// h, and kept surface granules along the sides rattling at 0.02-0.05 m/s: a patch never fell
// asleep.)
SP_INLINE bool boundary_plane(Boundaries b, SP_TERRAIN_GRID t, int slot, vec3 p, float r, SP_OUT(vec3) n,
                              SP_OUT(float) dist) {
  if (slot == 0) {
    n = vec3(0.0f, 1.0f, 0.0f);
    dist = p.y - b.floor_y;
    return dist < r;
  }
  const bool outside = p.x < t.fill_min_x || p.x > t.fill_max_x || p.z < t.fill_min_z || p.z > t.fill_max_z;
  if (slot == 5) {
    if (!b.terrain || !outside) return false;
    const float hh = terrain_height(t, p.x, p.z);
    n = terrain_normal(t, p.x, p.z);
    dist = (p.y - hh) * n.y;
    // Below the surface, past the rectangle's side by less than it is deep: the side's face
    // (slots 1-4 from inside) pushes it back into the rectangle, the overlap growing from r as
    // the centre crosses it. (Pushed up instead, a granule a wheel shoved across a side 0.3 m
    // under the surface took 7 r of overlap at once and was fired out of the sand, and the
    // car's shells with it: a run ended in NaN; docs/dem.md "Contact model", boundaries.)
    if (dist < 0.0f) {
      const float ox = p.x < t.fill_min_x ? t.fill_min_x - p.x : (p.x > t.fill_max_x ? t.fill_max_x - p.x : 0.0f);
      const float oz = p.z < t.fill_min_z ? t.fill_min_z - p.z : (p.z > t.fill_max_z ? t.fill_max_z - p.z : 0.0f);
      const float back = sqrt(ox * ox + oz * oz);  // m, to the rectangle (the way back in)
      if (back < -dist) {
        n = vec3(ox, 0.0f, oz) * (1.0f / back);
        dist = -back;
      }
    }
    return dist < r;
  }
  if (b.walls) {
    if (slot == 1) { n = vec3(1.0f, 0.0f, 0.0f); dist = p.x - b.bmin.x; }
    else if (slot == 2) { n = vec3(-1.0f, 0.0f, 0.0f); dist = b.bmax.x - p.x; }
    else if (slot == 3) { n = vec3(0.0f, 0.0f, 1.0f); dist = p.z - b.bmin.z; }
    else { n = vec3(0.0f, 0.0f, -1.0f); dist = b.bmax.z - p.z; }
    return dist < r;
  }
  if (!b.terrain || outside) return false;
  // a side of the filled rectangle: inward normal, gap to the side, outside surface height
  // (the gap first: the outside height is sampled only for a sphere within r of the side)
  vec3 inward;
  float gap;
  if (slot == 1) { inward = vec3(1.0f, 0.0f, 0.0f); gap = p.x - t.fill_min_x; }
  else if (slot == 2) { inward = vec3(-1.0f, 0.0f, 0.0f); gap = t.fill_max_x - p.x; }
  else if (slot == 3) { inward = vec3(0.0f, 0.0f, 1.0f); gap = p.z - t.fill_min_z; }
  else { inward = vec3(0.0f, 0.0f, -1.0f); gap = t.fill_max_z - p.z; }
  if (!(gap < r)) return false;
  float top;
  if (slot == 1) top = terrain_height(t, t.fill_min_x - r, p.z);
  else if (slot == 2) top = terrain_height(t, t.fill_max_x + r, p.z);
  else if (slot == 3) top = terrain_height(t, p.x, t.fill_min_z - r);
  else top = terrain_height(t, p.x, t.fill_max_z + r);
  const float dy = p.y - top;
  if (dy <= 0.0f) {
    n = inward;
    dist = gap;
    return true;
  }
  dist = sqrt(gap * gap + dy * dy);
  if (!(dist < r && dist > 0.0f)) return false;
  n = (inward * gap + vec3(0.0f, dy, 0.0f)) * (1.0f / dist);
  return true;
}
