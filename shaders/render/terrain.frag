#version 430 core
// Clipmap terrain shading: normal and material weights from the level's textures (blended with
// the coarser level's by the same alpha as the geometry, so nothing pops), the normalised
// material blend (common.glsl) and one light, with the bodies' shadows and the terrain's own.

in vec2 v_xz;
in float v_height;   // m, local (the drawn, morphed surface)
in float v_alpha;
flat in int v_level;

uniform int u_T;
uniform float u_base_spacing;       // m, s_0
uniform int u_levels;
uniform sampler2DArray u_normals;   // RGBA16F unit normal (x, y, z), linear, repeat
uniform sampler2DArray u_materials; // RGBA8 weights of materials 0..3, linear, repeat
uniform sampler2DArray u_elevation; // R32F heights (m, local), one layer per level (terrain.vert)
uniform int u_n;                    // vertices per ring side
uniform float u_w;                  // transition width (samples)
uniform vec2 u_viewer;              // viewer (x, z), local m: the rings' centre
uniform int u_terrain_shadow_steps; // the march toward the sun (0 = no terrain shadow)
uniform float u_max_height;         // m, local: the heightfield's highest sample
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

// Height (m, local) of level l at local (x, z) m: bilinear between its four samples.
float level_height(vec2 xz, int l) {
  vec2 g = xz / (u_base_spacing * float(1 << l));
  ivec2 g0 = ivec2(floor(g));
  vec2 f = g - vec2(g0);
  ivec2 m = ivec2(u_T - 1);
  float h00 = texelFetch(u_elevation, ivec3(g0 & m, l), 0).r;
  float h10 = texelFetch(u_elevation, ivec3((g0 + ivec2(1, 0)) & m, l), 0).r;
  float h01 = texelFetch(u_elevation, ivec3((g0 + ivec2(0, 1)) & m, l), 0).r;
  float h11 = texelFetch(u_elevation, ivec3((g0 + ivec2(1, 1)) & m, l), 0).r;
  return mix(mix(h00, h10, f.x), mix(h01, h11, f.x), f.y);
}

// The drawn surface's height (m, local) at local (x, z) m, as terrain.vert builds it: the finest
// level whose ring holds the point, morphed toward the next coarser level by the same weight
// alpha over the ring's outer w samples, so it moves with the viewer without popping. false
// beyond the coarsest ring.
bool surface_height(vec2 xz, out float h) {
  for (int l = 0; l < u_levels; ++l) {
    vec2 d = abs(xz - u_viewer) / (u_base_spacing * float(1 << l));
    float half_n = float(u_n - 1) * 0.5;
    if (max(d.x, d.y) >= half_n - 1.0) continue;
    h = level_height(xz, l);
    if (l + 1 < u_levels) {
      vec2 a = clamp((d - (half_n - u_w - 1.0)) / u_w, 0.0, 1.0);
      float alpha = max(a.x, a.y);
      if (alpha > 0.0) h = mix(h, level_height(xz, l + 1), alpha);
    }
    return true;
  }
  return false;
}

// The sun's visibility over the terrain (1 lit, 0 in the terrain's shadow): march from p toward
// the sun from two base spacings, each step the larger of a base spacing and a fifth of the
// distance so far (steps independent of the levels, so the shadow does not pop when they move).
// Soft edge, a penumbra that widens with distance: the least of k (ray height - surface height
// + 0.02 t) / t over the march, k = 8 (the 0.02 t, about 1 degree, keeps the surface between a
// coarse level's samples from shadowing itself).
// The march ends as soon as no point further on can lower it: once (ray height - the highest
// sample + 0.02 t) / t >= 1/8, that only grows along the ray (toward sin(elevation) + 0.02 >
// 1/8 for a sun above 6 degrees), so the result is the full march's, in a few steps on gentle
// ground.
float terrain_sun_visibility(vec3 p) {
  if (u_terrain_shadow_steps <= 0 || u_sun_dir.y <= 0.0) return 1.0;
  const bool can_stop = u_sun_dir.y + 0.02 > 0.125;
  float t = 2.0 * u_base_spacing;
  float vis = 1.0;
  for (int k = 0; k < u_terrain_shadow_steps; ++k) {
    vec3 q = p + u_sun_dir * t;
    if (can_stop && 8.0 * (q.y - u_max_height + 0.02 * t) >= t) break;
    float h;
    if (!surface_height(q.xz, h)) break;
    vis = min(vis, 8.0 * (q.y - h + 0.02 * t) / t);
    if (vis <= 0.0) return 0.0;
    t += max(u_base_spacing, 0.2 * t);
  }
  return vis;
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
