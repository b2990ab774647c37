#version 430 core
// Clipmap terrain shading: normal and material weights from the level's textures (blended with
// the coarser level's by the same alpha as the geometry, so nothing pops), the normalised
// material blend (common.glsl) and one light.

in vec2 v_xz;
in float v_alpha;
flat in int v_level;

uniform int u_T;
uniform float u_base_spacing;       // m, s_0
uniform int u_levels;
uniform sampler2DArray u_normals;   // RGBA16F unit normal (x, y, z), linear, repeat
uniform sampler2DArray u_materials; // RGBA8 weights of materials 0..3, linear, repeat

out vec4 o_color;

vec2 level_uv(int level) {
  float s = u_base_spacing * float(1 << level);
  return (v_xz / s + 0.5) / float(u_T);
}

void main() {
  int l = v_level;
  vec3 n = texture(u_normals, vec3(level_uv(l), float(l))).xyz;
  vec4 w = texture(u_materials, vec3(level_uv(l), float(l)));
  if (v_alpha > 0.0 && l + 1 < u_levels) {
    n = mix(n, texture(u_normals, vec3(level_uv(l + 1), float(l + 1))).xyz, v_alpha);
    w = mix(w, texture(u_materials, vec3(level_uv(l + 1), float(l + 1))), v_alpha);
  }
  n = normalize(n);
  o_color = vec4(sp_shade(sp_blend_materials(w, v_xz), n), 1.0);
}
