#version 430 core
// Circular splat with sphere shading and the sphere's depth: the point sprite is cut to a disc,
// the disc point lifted onto the sphere facing the eye, lit like the terrain, and its depth
// written so splats intersect each other and the terrain correctly.
// The normal may be bent toward the terrain's (u_normal_bend).

in vec3 v_center_eye;
in float v_radius;
in vec4 v_weights;
in vec3 v_ground_normal;

uniform mat4 u_proj;
uniform mat4 u_view_inv;   // eye -> local
uniform float u_fade;      // fade-in factor in [0, 1]
uniform float u_normal_bend;  // 0 = pure sphere normal, 1 = the terrain's normal

out vec4 o_color;

void main() {
  vec2 q = gl_PointCoord * 2.0 - 1.0;
  q.y = -q.y;                        // point coordinates run top to bottom
  float r2 = dot(q, q);
  if (r2 > 1.0) discard;
  vec3 n_eye = vec3(q, sqrt(1.0 - r2));
  vec3 p_eye = v_center_eye + v_radius * n_eye;
  vec4 clip = u_proj * vec4(p_eye, 1.0);
  float ndc_z = clip.z / clip.w;
  gl_FragDepth = 0.5 * (gl_DepthRange.diff * ndc_z + gl_DepthRange.near + gl_DepthRange.far);
  // Sphere normal, bent toward the terrain's normal under the particle by u_normal_bend: a
  // packed bed's caps then light like the surface they make up (docs/rendering.md).
  vec3 n_sphere = normalize(mat3(u_view_inv) * n_eye);
  vec3 n = normalize(mix(n_sphere, normalize(v_ground_normal), u_normal_bend));
  vec3 p = (u_view_inv * vec4(p_eye, 1.0)).xyz;
  o_color = vec4(sp_shade(sp_blend_materials(v_weights, p.xz), n), u_fade);
}
