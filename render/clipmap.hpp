// Geometry-clipmap level-of-detail selection, pure (no GL): Asirvatham & Hoppe, "Terrain
// rendering using GPU-based geometry clipmaps", GPU Gems 2 ch. 2 (2005); Losasso & Hoppe 2004.
// Like fstrugar/CDLOD, selection is a function that fills a caller's buffer; drawing lives in
// terrain_renderer.hpp. docs/rendering.md has the pictures and the formulas.
//
// Grid units. Level l has vertex spacing s_l = base_spacing * 2^l (m). Its vertices sit at
// integer "level coordinates" g = (gx, gz): local position (x, z) = (gx * s_l, gz * s_l),
// relative to the heightfield's origin (the same local frame as Heightfield::sample).
//
// Placement. n = 2^k - 1 vertices per ring side, m = (n + 1) / 4 vertices per block side.
// For a viewer at local (vx, vz), C_l = floor(vx / (2 s_l)) and the level covers vertices
//   [O_l, O_l + n - 1]  with  O_l = 2 C_l - 2m + 2           (per axis)
// so O_l is even (its border lies on level l+1's vertices) and level l sits inside level
// l+1's hole, leaving exactly one coarse cell on the low side (C_l odd) or the high side
// (C_l even): that cell is level l+1's interior trim.
//
// Footprint of a level, in cells (n - 1 = 4m - 2 per side), per axis: block [0, m-1],
// block [m-1, 2m-2], fix-up [2m-2, 2m], block [2m, 3m-1], block [3m-1, 4m-2].
//   finest drawn level: all 16 blocks + the fix-up cross (complete grid);
//   other levels: the 12 ring blocks, 4 ring fix-ups (m x 3 vertices), the L-shaped interior
//   trim (two strips one cell wide), all around a hole of 2m cells holding level l-1.
// Every level also draws its outer degenerate triangles (zero-area in exact arithmetic), one
// piece per side, that close the T-junctions against the coarser level, so no pixel falls through.
//
// Culling. A piece is skipped when its box (x, z range; y = the terrain's height range) lies
// outside one plane of the view frustum or all eight frustum corners lie beyond one of its
// faces, or when it lies outside the terrain's extent [0, extent_x] x [0, extent_z].
// Triangles per frame therefore depend on n, the levels and the view, not on terrain size.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdint>
#include <vector>

#include "common/error.hpp"

namespace sandpatch::render {

struct ClipmapDef {
  int n = 255;               // vertices per ring side, 2^k - 1 with k in [3, 12]
  int levels = 10;           // nested levels (>= 1, <= 24)
  float base_spacing = 1.0f; // m: vertex spacing of level 0 (> 0, finite)
  // Transition width w (vertices) over which level l morphs into level l+1 (Asirvatham: n/10).
  // 0 = n / 10. Must be in [1, (n-1)/2 - 2].
  int transition = 0;
  // Skip fine levels whose half-extent (n-1)/2 * s_l is below height_factor * (viewer height
  // above the terrain): Asirvatham's "active levels". 0 = never skip.
  float height_factor = 2.5f;
};

// Checks a ClipmapDef; errors name the field ("clipmap.n = 100: must be 2^k - 1 ...").
Status validate(const ClipmapDef& def);

inline int block_size(const ClipmapDef& d) { return (d.n + 1) / 4; }  // m (vertices)
inline int transition_width(const ClipmapDef& d) { return d.transition > 0 ? d.transition : std::max(1, d.n / 10); }
inline float level_spacing(const ClipmapDef& d, int level) { return d.base_spacing * float(1u << level); }

// An axis-aligned rectangle of vertices in one level's coordinates: [x0, x0+nx) x [z0, z0+nz).
struct LevelRect {
  int x0 = 0, z0 = 0, nx = 0, nz = 0;
  bool empty() const { return nx <= 0 || nz <= 0; }
  friend bool operator==(const LevelRect&, const LevelRect&) = default;
};

// Block: m x m vertices. FixupX / FixupZ: 3 vertices (2 cells) across x / z. TrimX / TrimZ: one
// cell across x / z. DegenerateX / DegenerateZ: one side of the level's outer border, a line of
// n vertices along x / z carrying (n-1)/2 zero-area triangles.
enum class PieceKind : std::uint8_t { Block, FixupX, FixupZ, TrimX, TrimZ, DegenerateX, DegenerateZ };

// One draw: a grid of cells_x x cells_z cells whose corner vertex is at level coordinates
// (gx, gz). A degenerate side has cells_x = n - 1, cells_z = 0 (along x) or the reverse.
struct ClipmapPiece {
  int level = 0;
  PieceKind kind = PieceKind::Block;
  int gx = 0, gz = 0;            // level coordinates of the piece's (min x, min z) vertex
  int cells_x = 0, cells_z = 0;  // cells along x and z
  // Triangles this piece draws: 2 cells_x cells_z, or (n - 1) / 2 for a degenerate side.
  std::int64_t triangles() const;
};

struct ClipmapLevel {
  int level = 0;
  float spacing = 0;      // m
  int origin_x = 0;       // O_l (level coordinates of the level's min corner vertex)
  int origin_z = 0;
  bool active = false;    // drawn this frame (false: skipped as too fine for the viewer height)
  bool finest = false;    // the finest active level: drawn as a complete grid
  LevelRect vertices() const;  // [O_l, O_l + n) on both axes (needs n: filled by select)
  int n = 0;
};

struct ClipmapView {
  Eigen::Vector3f viewer{0, 0, 0};   // local position (m) relative to the heightfield origin
  Eigen::Matrix4f view_proj = Eigen::Matrix4f::Identity();  // local -> clip (OpenGL convention)
  bool cull = true;                  // frustum culling on
  // Terrain extent (local m) and height range used for culling and active levels.
  float extent_x = 0, extent_z = 0;  // the terrain covers [0, extent_x] x [0, extent_z]
  float min_height = 0, max_height = 0;
  float ground_height = 0;           // terrain height under the viewer (m, local)
};

struct ClipmapSelection {
  std::vector<ClipmapLevel> levels;  // def.levels entries, finest first
  std::vector<ClipmapPiece> pieces;  // pieces to draw, grouped by level, finest first
  std::int64_t triangles = 0;        // sum over pieces
  int culled_pieces = 0;             // pieces skipped by the frustum or the terrain extent
};

// Level origin O_l along one axis for viewer coordinate v (m) (formula above).
int level_origin(const ClipmapDef& def, int level, double v);

// Fills `out` (cleared first; its capacity is reused frame to frame). def must be valid.
void select_clipmap(const ClipmapDef& def, const ClipmapView& view, ClipmapSelection& out);

// The six planes (a, b, c, d), a x + b y + c z + d >= 0 inside, of a view-projection matrix
// (Gribb & Hartmann), normalised.
std::array<Eigen::Vector4f, 6> frustum_planes(const Eigen::Matrix4f& view_proj);
// true when the box [lo, hi] is entirely outside one of the planes.
bool box_outside(const std::array<Eigen::Vector4f, 6>& planes, const Eigen::Vector3f& lo,
                 const Eigen::Vector3f& hi);
// The frustum's eight corners (local m) of a view-projection matrix.
std::array<Eigen::Vector3f, 8> frustum_corners(const Eigen::Matrix4f& view_proj);
// Plane test plus the box's own face axes (all frustum corners beyond one face): exact for the
// large boxes of coarse levels, where the plane test alone keeps boxes beside the frustum.
bool box_outside(const std::array<Eigen::Vector4f, 6>& planes, const std::array<Eigen::Vector3f, 8>& corners,
                 const Eigen::Vector3f& lo, const Eigen::Vector3f& hi);

// ---- toroidal texture bookkeeping ----
//
// Each level's data lives in a T x T texture (T = n + 1, a power of two); vertex g is stored at
// texel (g mod T) on each axis, so when the level moves only the vertices that entered it are
// written. These functions say which.

// Vertices of `now` not in `before` (before empty = everything), in level coordinates,
// covering each new vertex exactly once: at most two rectangles (an L shape) when the two
// have the same size, as when a level moves; at most four in general.
std::vector<LevelRect> toroidal_updates(const LevelRect& before, const LevelRect& now);

// A rectangle of texels in a T x T toroidal texture: the rectangle of level coordinates r
// (nx, nz <= T) splits at the wrap into up to four texel rectangles; `src` is the offset of
// each piece inside r (so the upload reads r's row-major data from there).
struct TexelRect {
  int tx = 0, tz = 0, nx = 0, nz = 0;  // texel rectangle inside [0, T)^2
  int src_x = 0, src_z = 0;            // offset inside the level rectangle
  friend bool operator==(const TexelRect&, const TexelRect&) = default;
};
std::vector<TexelRect> wrap_rect(const LevelRect& r, int T);

// The level vertices whose texel data (elevation, normal, material weights) depends on the
// heightfield samples [i0, i0+ni) x [j0, j0+nj) of spacing `hf_spacing` (m): every vertex
// whose bilinear sample or normal reads one of them (one sample of margin), clipped to
// `level_rect`. Empty when they do not meet.
// Samples on the grid's edge also stand for everything beyond it (the surface is clamped), so a
// region touching an edge dirties the level vertices outside the grid on that side.
LevelRect dirty_level_rect(const ClipmapDef& def, int level, const LevelRect& level_rect, int i0,
                           int j0, int ni, int nj, float hf_spacing, int samples_x, int samples_z);

}  // namespace sandpatch::render
