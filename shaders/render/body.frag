#version 430 core
// Rigid bodies lit like the terrain (common.glsl sp_shade: the same sun, diffuse + ambient),
// two-sided (a mesh's winding is not trusted); or, for tests, one flat ID colour per body.

in vec3 v_position;
in vec3 v_normal;
in vec3 v_color;

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
  o_color = vec4(sp_shade(v_color, n), 1.0);
}
