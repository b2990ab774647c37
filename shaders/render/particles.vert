#version 430 core
// Particle splats (Leach & Marais §4.2): one point per particle read straight from the
// simulation's buffer (position, optional radius), sized to the sphere's projected diameter.
// The particle's material weights come from the terrain's clipmap textures under it, so a
// patch looks like the heightfield it came from; the terrain's shadow is marched from its centre.

layout(location = 0) in vec3 a_position;  // m, patch frame, unit particle scale
layout(location = 1) in float a_radius;   // m, unit scale (constant attribute when not in the buffer)
layout(location = 2) in int a_id;         // the particle's id, when the source gives ids (u_has_id)

uniform mat4 u_view;              // local -> eye
uniform mat4 u_proj;              // eye -> clip
uniform float u_viewport_h;       // pixels
uniform vec3 u_patch_origin;      // local m
uniform float u_scale;            // particle scale (Leach §4.3)
#include "terrain_shadow.glsl"
uniform int u_first_level;        // finest active clipmap level
uniform ivec2 u_level_origin[24]; // O_l per level
uniform sampler2DArray u_materials;
uniform sampler2DArray u_normals;  // terrain normals (RGBA16F)
uniform float u_color_variation;  // albedo factor 1 + v u per granule, u in [-1, 1]
uniform int u_first_index;        // index of this draw's first particle in its buffer
uniform bool u_has_id;            // a_id holds the particle's id
uniform int u_id_limit;           // >= 0: only particles of id below it are drawn (the others are shells)

out vec3 v_center_eye;
out float v_radius;
out vec4 v_weights;
out vec3 v_ground_normal;   // terrain normal under the particle
out float v_tint;           // albedo factor of this granule
out float v_terrain_vis;    // the sun's visibility over the terrain at the granule's centre (1 lit)

void main() {
  if (u_id_limit >= 0 && a_id >= u_id_limit) {  // not a granule's sphere: outside the clip volume
    gl_Position = vec4(2.0, 2.0, 2.0, 1.0);
    gl_PointSize = 1.0;
    return;
  }
  vec3 c = u_patch_origin + u_scale * a_position;
  float r = u_scale * a_radius;
  vec4 e = u_view * vec4(c, 1.0);
  v_center_eye = e.xyz;
  v_radius = r;
  gl_Position = u_proj * e;
  // Projected radius of a sphere at eye distance d: f * r / sqrt(d^2 - r^2) (f = u_proj[1][1]).
  float d = max(-e.z, 1e-6);
  float rp = u_proj[1][1] * r / sqrt(max(d * d - r * r, 1e-12)) * 0.5 * u_viewport_h;
  gl_PointSize = max(2.0 * rp, 1.0);
  // The terrain's shadow, marched once per sphere from its centre (a granule is a few
  // pixels to a few tens across: one value for it, not one per fragment).
  v_terrain_vis = terrain_sun_visibility(c);
  // One factor per granule (its four spheres are consecutive), from an integer hash.
  int granule = (u_has_id ? a_id : u_first_index + gl_VertexID) >> 2;
  v_tint = 1.0 + u_color_variation * (2.0 * sp_hash01(ivec2(granule, 7919)) - 1.0);
  // Material weights and terrain normal: the finest level whose window holds the particle.
  v_weights = vec4(1.0, 0.0, 0.0, 0.0);
  v_ground_normal = vec3(0.0, 1.0, 0.0);
  for (int l = u_first_level; l < u_levels; ++l) {
    float s = u_base_spacing * float(1 << l);
    ivec2 g = ivec2(floor(c.xz / s + 0.5));
    ivec2 rel = g - u_level_origin[l];
    if (all(greaterThanEqual(rel, ivec2(0))) && all(lessThan(rel, ivec2(u_n)))) {
      v_weights = texelFetch(u_materials, ivec3(g & ivec2(u_T - 1), l), 0);
      v_ground_normal = texelFetch(u_normals, ivec3(g & ivec2(u_T - 1), l), 0).xyz;
      break;
    }
  }
}
