#version 430 core
// Geometry-clipmap vertex shader (Asirvatham & Hoppe 2005): one piece of one level.
// The vertex's level coordinates g = u_piece_origin + a_cell give its (x, z) = g * u_spacing;
// its height is fetched from the level's toroidal texture (texel g mod T) and, in the
// transition region, morphed toward the coarser level's surface with weight alpha.

layout(location = 0) in ivec2 a_cell;   // vertex coordinates inside the piece

uniform mat4 u_view_proj;               // local -> clip
uniform ivec2 u_piece_origin;           // level coordinates of the piece's corner
uniform int u_level;                    // this level (layer of the texture arrays)
uniform float u_spacing;                // m, s_l
uniform bool u_has_coarser;             // level l+1 exists
uniform int u_T;                        // texture side (power of two)
uniform int u_n;                        // vertices per ring side
uniform float u_w;                      // transition width (vertices)
uniform vec2 u_viewer;                  // viewer (x, z), local m
uniform vec2 u_extent;                  // terrain extent (x, z), local m: the grid covers [0, extent]
uniform sampler2DArray u_elevation;     // R32F heights (m, local), one layer per level

out float gl_ClipDistance[4];
out vec2 v_xz;       // local (x, z), m
out float v_height;  // m, local
out float v_alpha;   // morph weight toward level l+1
flat out int v_level;

float fetch_height(ivec2 g, int level) {
  return texelFetch(u_elevation, ivec3(g & ivec2(u_T - 1), level), 0).r;
}

void main() {
  ivec2 g = u_piece_origin + a_cell;
  vec2 xz = vec2(g) * u_spacing;
  float zf = fetch_height(g, u_level);
  float alpha = 0.0;
  float zc = zf;
  if (u_has_coarser) {
    // alpha = max over axes of clamp((|x - v| - ((n-1)/2 - w - 1)) / w, 0, 1), in level units.
    vec2 d = abs(vec2(g) - u_viewer / u_spacing);
    vec2 a = clamp((d - (float(u_n - 1) * 0.5 - u_w - 1.0)) / u_w, 0.0, 1.0);
    alpha = max(a.x, a.y);
    // The coarser surface at g: on a coarse vertex, its height; on a coarse edge or cell
    // centre, the mean of the two ends of that edge / of the cell's (0,0)-(1,1) diagonal,
    // which is exactly the coarse triangle mesh there.
    ivec2 gc = g >> 1;
    ivec2 odd = g & ivec2(1);
    zc = 0.5 * (fetch_height(gc, u_level + 1) + fetch_height(gc + odd, u_level + 1));
  }
  float h = mix(zf, zc, alpha);
  // Pieces straddling the terrain's edge are clipped at it (four user clip planes), so the
  // terrain ends in a clean cut instead of a skirt that would come and go as levels move.
  gl_ClipDistance[0] = xz.x;
  gl_ClipDistance[1] = u_extent.x - xz.x;
  gl_ClipDistance[2] = xz.y;
  gl_ClipDistance[3] = u_extent.y - xz.y;
  v_xz = xz;
  v_height = h;
  v_alpha = alpha;
  v_level = u_level;
  gl_Position = u_view_proj * vec4(xz.x, h, xz.y, 1.0);
}
