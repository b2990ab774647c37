// The terrain's shadow: a march from a point toward the sun through the clipmap's surface,
// shared by terrain.frag (the ground), particles.vert (each granule, at its centre) and body.frag
// (the bodies), included where a shader says #include "terrain_shadow.glsl" (render/shaders.cpp).
// TerrainRenderer::bind_terrain_shadow sets these uniforms; with u_terrain_shadow_steps = 0 (the
// default of an unset uniform) terrain_sun_visibility is 1 and nothing is read.

uniform sampler2DArray u_elevation; // R32F heights (m, local), one layer per level (terrain.vert)
uniform int u_T;                    // texture side (power of two)
uniform float u_base_spacing;       // m, s_0
uniform int u_levels;
uniform int u_n;                    // vertices per ring side
uniform float u_w;                  // transition width (samples)
uniform vec2 u_viewer;              // viewer (x, z), local m: the rings' centre
uniform int u_terrain_shadow_steps; // the march toward the sun (0 = no terrain shadow)
uniform float u_max_height;         // m, local: the heightfield's highest sample
// The live patches' footprints (local x0, z0, x1, z1, m; TerrainRenderer::set_live_footprints).
// Inside one the heightfield still holds the surface the patch was promoted from, which its
// granules have since dug into or heaped up, so the march takes no sample there: a granule
// at the bottom of a trough is not shadowed by the ground that was above it before. (The
// granules cast no shadow of their own on the march; the bodies' shadow map and the ambient
// occlusion darken them.)
const int kMaxLive = 32;
uniform int u_live_count;
uniform vec4 u_live[kMaxLive];

bool sp_in_live_footprint(vec2 xz) {
  for (int k = 0; k < u_live_count; ++k)
    if (all(greaterThan(xz, u_live[k].xy)) && all(lessThan(xz, u_live[k].zw))) return true;
  return false;
}

// Height (m, local) of level l at local (x, z) m: bilinear between its four samples.
float sp_level_height(vec2 xz, int l) {
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
bool sp_surface_height(vec2 xz, out float h) {
  for (int l = 0; l < u_levels; ++l) {
    vec2 d = abs(xz - u_viewer) / (u_base_spacing * float(1 << l));
    float half_n = float(u_n - 1) * 0.5;
    if (max(d.x, d.y) >= half_n - 1.0) continue;
    h = sp_level_height(xz, l);
    if (l + 1 < u_levels) {
      vec2 a = clamp((d - (half_n - u_w - 1.0)) / u_w, 0.0, 1.0);
      float alpha = max(a.x, a.y);
      if (alpha > 0.0) h = mix(h, sp_level_height(xz, l + 1), alpha);
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
    if (!sp_surface_height(q.xz, h)) break;
    if (!sp_in_live_footprint(q.xz)) vis = min(vis, 8.0 * (q.y - h + 0.02 * t) / t);
    if (vis <= 0.0) return 0.0;
    t += max(u_base_spacing, 0.2 * t);
  }
  return vis;
}
