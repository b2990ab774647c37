#version 430 core
// Rigid bodies lit like the terrain (common.glsl sp_shade: the same sun, diffuse + ambient,
// the bodies' shadows and the terrain's), two-sided (a mesh's winding is not trusted); or, for tests, one flat ID colour per body.

in vec3 v_position;
in vec3 v_normal;
in vec3 v_color;

#include "terrain_shadow.glsl"

uniform vec3 u_eye;        // local m
uniform bool u_flat;       // true: the ID colour as it is, no light

out vec4 o_color;

void main() {
  if (u_flat) {
    o_color = vec4(v_color, 1.0);
    return;
  }
  vec3 n = normalize(v_normal);
  if (dot(n, u_eye - v_position) < 0.0) n = -n;
  // The bodies' shadows, this body's own included: looked up 3 shadow-map texels off the
  // surface along its normal (the 3 x 3 taps reach one texel each way), so a lit face does not
  // shadow itself; faces turned from the sun get no sun either way.
  // The terrain's shadow too: the march of terrain.frag from this point (a hill or a wall
  // between the body and the sun leaves it the ambient only).
  float vis = min(sp_sun_visibility(v_position + 3.0 * u_shadow_texel * n), terrain_sun_visibility(v_position));
  o_color = vec4(sp_shade_visible(v_color, n, vis), 1.0);
}
