// Shared helpers of the granule DEM kernels (shaders/dem/*.comp). Prepended after the
// generated preamble (particles/gpu/gl_programs.cpp: #version, capacities, the std430
// blocks generated from particles/fields.hpp, BodyFlags) and physics_common.glsl (the
// physics shared with the CPU backend, and the status block), before each kernel.
//
// Buffer bindings (all std430; every kernel declares all of them, uses a few):
//   0 P    particles, current (cell-sorted) order        generated from fields.hpp
//   1 Pn   particles, scratch copy                       (the grid's gather writes it)
//   2 B    bodies, creation order                        generated from fields.hpp
//   3 G    status counters, cells, prefix-sum block sums, the list of wide bodies
//   4 SIn  contact springs read this substep (by particle id, K slots each): per slot the
//          tangential spring xi and the partner id (slot), and the largest overlap of the
//          contact (dmax, m: the hysteretic normal spring, physics_common.glsl contact_force_h;
//          0 with the linear spring)
//   5 SOut contact springs written this substep
//   6 W    boundary-plane springs (by particle id, 6 planes each): xi in xyz, the plane
//          contact's largest overlap (m, as dmax) in w
//   7 S    sort bookkeeping: slot_of (id -> sorted index), cell_of, order; terrain heights
//   8 A    the grid kernels' dispatch-indirect arguments (also the GL_DISPATCH_INDIRECT_BUFFER)
//   9, 10  copy_words.comp's source and destination (the host's writes into any block)
// Math follows particles/math.hpp operation by operation; the contact law, terrain and
// boundary planes are physics_common.glsl's, the CPU backend's own source.

layout(std430, binding = 3) buffer Grid {
  DemStatus status;  // physics_common.glsl; read back by the host after each frame
  uint cell_start[SP_CELLS + 1];
  uint cell_count[SP_CELLS];
  uint block_sum[SP_SCAN_BLOCKS];
  int wide_body[SP_BODIES];  // the bodies of more than SP_WIDE spheres (bodies.comp SP_WIDE_PASS)
} G;

layout(std430, binding = 4) buffer SpringsIn {
  uint count[SP_PARTICLES];
  uvec4 slot[SP_PARTICLES * SP_K];
  float dmax[SP_PARTICLES * SP_K];
} SIn;
layout(std430, binding = 5) buffer SpringsOut {
  uint count[SP_PARTICLES];
  uvec4 slot[SP_PARTICLES * SP_K];
  float dmax[SP_PARTICLES * SP_K];
} SOut;
layout(std430, binding = 6) buffer Walls { uint mask[SP_PARTICLES]; vec4 xi[SP_PARTICLES * 6]; } W;
// (terrain: the optional TerrainGrid heights, heights[iz * nx + ix], m)
layout(std430, binding = 7) buffer Sort {
  int slot_of[SP_PARTICLES];
  uint cell_of[SP_PARTICLES];
  int order[SP_PARTICLES];
  vec4 pos_at_sort[SP_PARTICLES];  // sphere centre at the last sort (sorted order), m
  float terrain[];
} S;

float terrain_sample(int k) { return S.terrain[k]; }  // physics_common.glsl's SP_TERRAIN_AT

// (x, y, z) workgroups of each grid kernel, kGridCount.. of particles/gpu/gl_impl.hpp. Its own
// small buffer: NVIDIA's driver made every glCopyBufferSubData out of the large grid block cost
// 50-450 us of host time, and indirect dispatches read from that block cost GPU time
// (docs/BENCHMARKS.md "GL backend on a GPU").
layout(std430, binding = 8) buffer Args { uint grid_dispatch[SP_GRID_KERNELS * 3]; } A;

uniform uint u_np;          // live particles
uniform uint u_nb;          // live bodies
uniform uint u_cells;       // gx * gy * gz (<= SP_CELLS)
uniform ivec3 u_grid;       // gx, gy, gz
uniform vec3 u_bmin;        // bounds_min (m)
uniform vec3 u_bmax;        // bounds_max (m)
uniform float u_inv_h;      // 1 / cell size (1/m)

// Cell coordinate of one axis, clamped to the grid (dem_impl.hpp cell_coord).
int cell_coord(float v, float lo, int n) {
  int c = int(floor((v - lo) * u_inv_h));
  return c < 0 ? 0 : (c >= n ? n - 1 : c);
}
ivec3 cell3(vec3 x) {
  return ivec3(cell_coord(x.x, u_bmin.x, u_grid.x), cell_coord(x.y, u_bmin.y, u_grid.y),
               cell_coord(x.z, u_bmin.z, u_grid.z));
}
uint cell_index(ivec3 c) { return uint((c.z * u_grid.y + c.y) * u_grid.x + c.x); }

// ---- re-sort requests and the grid kernels' dispatch-indirect arguments ----
// Invariant inside a frame's substeps: status.resort != 0 exactly when A.grid_dispatch holds
// the grid kernels' workgroup counts (else their x counts are 0). grid_decide.comp establishes
// it once per frame (the host may have raised the flag: an upload, a body moved);
// request_resort keeps it when a kernel raises the flag; grid_copyback.comp, the last grid
// kernel, lowers both. The grid kernels of the next substep read the arguments after a
// command barrier (particles/gpu/gl_simulation.cpp substep()).
void write_grid_dispatch(bool resort) {
  const uint per_sphere = (u_np + uint(SP_WG) - 1u) / uint(SP_WG);
  const uint per_cell = (u_cells + uint(SP_WG) - 1u) / uint(SP_WG);
  // order of kGridCount.. in particles/gpu/gl_impl.hpp
  uint groups[SP_GRID_KERNELS] = uint[SP_GRID_KERNELS](per_sphere, (u_cells + 1023u) / 1024u, 1u, per_sphere,
                                                       per_sphere, max(per_sphere, per_cell));
  for (int k = 0; k < SP_GRID_KERNELS; ++k) {
    A.grid_dispatch[3 * k] = resort ? groups[k] : 0u;
    A.grid_dispatch[3 * k + 1] = 1u;
    A.grid_dispatch[3 * k + 2] = 1u;
  }
}
// Raises the re-sort flag; the one invocation that raises it first writes the arguments.
void request_resort() {
  if (atomicOr(G.status.resort, 1u) == 0u) write_grid_dispatch(true);
}

// Start of cell c's range in the sorted order (c <= u_cells; u_cells: the end) while a re-sort
// runs, between scan_top.comp and grid_copyback.comp: the start within its block of 1024
// cells plus the block's offset. Before and after, cell_start holds the final starts.
uint cell_begin(uint c) { return c < u_cells ? G.cell_start[c] + G.block_sum[c / 1024u] : G.cell_start[u_cells]; }

// v rotated by the unit quaternion q = (x, y, z, w): v + 2w (u x v) + 2 u x (u x v).
vec3 quat_rotate(vec4 q, vec3 v) {
  vec3 t = 2.0 * cross(q.xyz, v);
  return v + q.w * t + cross(q.xyz, t);
}
vec3 quat_rotate_inv(vec4 q, vec3 v) { return quat_rotate(vec4(-q.xyz, q.w), v); }
// Quaternion product a * b, (x, y, z, w).
vec4 quat_mul(vec4 a, vec4 b) {
  return vec4(a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
              a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w, a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z);
}
vec4 quat_normalized(vec4 q) {
  float n = sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  float s = n > 0.0 ? 1.0 / n : 0.0;
  return n > 0.0 ? q * s : vec4(0.0, 0.0, 0.0, 1.0);
}

// Inclusive scan of shared uint arr[256] by invocation t (Hillis-Steele), written out so
// that barrier() is never inside control flow (GLSL 4.30 rule).
#define SP_SCAN_STEP(arr, t, off)              \
  {                                            \
    uint a_ = t >= off ? arr[t - off] : 0u;    \
    memoryBarrierShared();                     \
    barrier();                                 \
    arr[t] += a_;                              \
    memoryBarrierShared();                     \
    barrier();                                 \
  }
#define SP_SCAN256(arr, t)                                                              \
  SP_SCAN_STEP(arr, t, 1u) SP_SCAN_STEP(arr, t, 2u) SP_SCAN_STEP(arr, t, 4u)            \
  SP_SCAN_STEP(arr, t, 8u) SP_SCAN_STEP(arr, t, 16u) SP_SCAN_STEP(arr, t, 32u)          \
  SP_SCAN_STEP(arr, t, 64u) SP_SCAN_STEP(arr, t, 128u)
