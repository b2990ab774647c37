#version 430 core
// Clipmap terrain shading: normal and material weights from the level's textures (blended with
// the coarser level's by the same alpha as the geometry, so nothing pops), the normalised
// material blend (common.glsl) and one light, with the bodies' shadows and the terrain's own.

in vec2 v_xz;
in float v_height;   // m, local (the drawn, morphed surface)
in float v_alpha;
flat in int v_level;

#include "terrain_shadow.glsl"

uniform sampler2DArray u_normals;   // RGBA16F unit normal (x, y, z), linear, repeat
uniform sampler2DArray u_materials; // RGBA8 weights of materials 0..3, linear, repeat
// Footprints left out of this pass (local x0, z0, x1, z1, m): the live patches' in the second
// terrain pass, where their granules are the surface (render.hpp).
// Inside a footprint the terrain gives way to the granules over a band of u_cut_band[k] m
// from its edge (six granule diameters): a ragged edge at granule scale, not a translucent
// layer. At depth fraction a (1 at the footprint's edge, 0 at the band's inner end) the
// terrain stays where a - fbm(x / one granule diameter) > 0, with a soft step of +-0.12 (a few
// pixels), so near the edge it is whole, in the middle it breaks into holes of one or two
// granules, and at the inner end only specks remain: sand running out into the patch.
const int kMaxCuts = 32;
uniform int u_cut_count;
uniform vec4 u_cuts[kMaxCuts];
uniform float u_cut_band[kMaxCuts];

out vec4 o_color;

vec2 level_uv(int level) {
  float s = u_base_spacing * float(1 << level);
  return (v_xz / s + 0.5) / float(u_T);
}

void main() {
  float alpha = 1.0;
  for (int k = 0; k < u_cut_count; ++k) {
    vec2 inside = min(v_xz - u_cuts[k].xy, u_cuts[k].zw - v_xz);  // m from the nearest edge, per axis
    float d = min(inside.x, inside.y);
    if (d > 0.0) {
      float band = max(u_cut_band[k], 1e-6);
      float a = 1.25 * (1.0 - clamp(d / band, 0.0, 1.0)) - 0.125;  // in [-0.125, 1.125]
      float g = sp_fbm(v_xz * (6.0 / band) + vec2(17.0 * float(k)));  // one cell per granule diameter
      alpha = min(alpha, smoothstep(g - 0.12, g + 0.12, a));
    }
  }
  if (alpha <= 0.0) discard;
  int l = v_level;
  vec3 n = texture(u_normals, vec3(level_uv(l), float(l))).xyz;
  vec4 w = texture(u_materials, vec3(level_uv(l), float(l)));
  if (v_alpha > 0.0 && l + 1 < u_levels) {
    n = mix(n, texture(u_normals, vec3(level_uv(l + 1), float(l + 1))).xyz, v_alpha);
    w = mix(w, texture(u_materials, vec3(level_uv(l + 1), float(l + 1))), v_alpha);
  }
  n = normalize(n);
  vec3 p = vec3(v_xz.x, v_height, v_xz.y);
  float vis = min(sp_sun_visibility(p), terrain_sun_visibility(p));
  o_color = vec4(sp_shade_visible(sp_blend_materials(w, v_xz), n, vis), alpha);
}
