#version 430 core
// Screen-space ambient occlusion over the finished frame (terrain, granules, bodies): the
// colour is multiplied by 1 - strength * (mean over N samples of max(0, cos(theta) - bias) *
// falloff), theta being the angle between the surface normal at the pixel and the direction to
// a surface point sampled within `u_radius` metres (world) around it, read back from the depth
// buffer. A crater's floor sees its walls above its tangent plane and darkens; gaps between
// granules darken; a body darkens the ground next to it. Flat open ground is left as it is
// (every sample lies in the tangent plane). The background (depth 1) is copied unchanged.

in vec2 v_uv;

uniform sampler2D u_color;
uniform sampler2D u_depth;
uniform mat4 u_inv_proj;     // clip -> eye
uniform float u_proj_scale;  // P[1][1] * viewport height / 2: pixels per metre at eye distance 1
uniform vec2 u_size;         // viewport (pixels)
uniform float u_radius;      // m, world
uniform float u_strength;    // 0 = no occlusion
uniform int u_samples;

out vec4 o_color;

vec3 eye_pos(vec2 uv) {
  float d = texture(u_depth, uv).r;
  vec4 p = u_inv_proj * vec4(uv * 2.0 - 1.0, d * 2.0 - 1.0, 1.0);
  return p.xyz / p.w;
}

void main() {
  vec4 c = texture(u_color, v_uv);
  float d = texture(u_depth, v_uv).r;
  if (d >= 1.0 || u_strength <= 0.0) {
    o_color = c;
    return;
  }
  vec3 P = eye_pos(v_uv);
  // Normal from the depth buffer: on each axis the neighbour closer in depth (no silhouettes).
  vec2 px = 1.0 / u_size;
  vec3 l = eye_pos(v_uv - vec2(px.x, 0)), r = eye_pos(v_uv + vec2(px.x, 0));
  vec3 b = eye_pos(v_uv - vec2(0, px.y)), t = eye_pos(v_uv + vec2(0, px.y));
  vec3 dx = abs(r.z - P.z) < abs(P.z - l.z) ? r - P : P - l;
  vec3 dy = abs(t.z - P.z) < abs(P.z - b.z) ? t - P : P - b;
  vec3 n = normalize(cross(dx, dy));
  if (dot(n, -P) < 0.0) n = -n;
  float r_px = u_radius * u_proj_scale / max(-P.z, 1e-4);  // the radius on screen, pixels
  if (r_px < 1.0) {
    o_color = c;
    return;
  }
  r_px = min(r_px, 0.25 * u_size.y);
  // A per-pixel rotation of the sample spiral (integer hash of the pixel): noise instead of bands.
  float rot = 6.2831853 * sp_hash01(ivec2(gl_FragCoord.xy));
  float occ = 0.0;
  for (int i = 0; i < u_samples; ++i) {
    float f = (float(i) + 0.5) / float(u_samples);
    float a = rot + 2.3999632 * float(i);  // golden angle
    vec2 uv = v_uv + vec2(cos(a), sin(a)) * sqrt(f) * r_px * px;
    if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) continue;
    if (texture(u_depth, uv).r >= 1.0) continue;
    vec3 v = eye_pos(uv) - P;
    float len = length(v);
    if (len < 1e-5) continue;
    float fall = 1.0 - clamp(len / u_radius, 0.0, 1.0);
    occ += max(0.0, dot(v, n) / len - 0.02) * fall;
  }
  occ /= float(u_samples);
  o_color = vec4(c.rgb * clamp(1.0 - u_strength * occ, 0.0, 1.0), c.a);
}
