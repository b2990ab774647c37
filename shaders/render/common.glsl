// Shared by every render/ shader (inserted after the #version line by render/shaders.cpp):
// procedural material colours, the normalised blend operator and the light.

// ---- procedural value noise (integer hash; no textures, no downloads) ----
uint sp_hash(uvec2 q) {
  uint h = q.x * 0x8da6b343u ^ q.y * 0xd8163841u;
  h ^= h >> 15; h *= 0x2c1b3c6du; h ^= h >> 12; h *= 0x297a2d39u; h ^= h >> 15;
  return h;
}
float sp_hash01(ivec2 c) { return float(sp_hash(uvec2(c)) & 0xffffu) / 65535.0; }
float sp_value_noise(vec2 p) {
  vec2 i = floor(p), f = fract(p);
  vec2 u = f * f * (3.0 - 2.0 * f);
  ivec2 c = ivec2(i);
  float a = sp_hash01(c), b = sp_hash01(c + ivec2(1, 0));
  float d = sp_hash01(c + ivec2(0, 1)), e = sp_hash01(c + ivec2(1, 1));
  return mix(mix(a, b, u.x), mix(d, e, u.x), u.y);
}
float sp_fbm(vec2 p) {
  return 0.5 * sp_value_noise(p) + 0.3 * sp_value_noise(2.03 * p) + 0.2 * sp_value_noise(4.01 * p);
}

// Colour of material k (0 sand, 1 gravel, 2 soil, 3 grass) at local position p = (x, z) (m).
vec3 sp_material_color(int k, vec2 p) {
  if (k == 0) {  // sand: warm yellow, fine ripples
    return vec3(0.80, 0.69, 0.48) * (0.93 + 0.14 * sp_fbm(p * 1.7));
  } else if (k == 1) {  // gravel: grey stones, one brightness per 0.25 m cell
    float cell = sp_hash01(ivec2(floor(p * 4.0)));
    return vec3(0.52, 0.51, 0.49) * (0.75 + 0.45 * cell);
  } else if (k == 2) {  // soil: dark brown, coarse mottling
    return vec3(0.40, 0.28, 0.18) * (0.8 + 0.4 * sp_fbm(p * 0.6));
  }
  // grass: green with streaks along x
  return vec3(0.30, 0.44, 0.18) * (0.8 + 0.4 * sp_fbm(vec2(p.x * 3.0, p.y * 0.8)));
}

// Normalised blend operator (Huhtiranta 2015, §6.2 eq. 2): C = sum C_n W_n / sum W_n.
// The weights must not sum to zero; below 1e-6 the result is material 0.
vec3 sp_blend_materials(vec4 w, vec2 p) {
  w = max(w, vec4(0.0));
  float sum = w.x + w.y + w.z + w.w;
  if (sum < 1e-6) return sp_material_color(0, p);
  vec3 c = vec3(0.0);
  if (w.x > 0.0) c += w.x * sp_material_color(0, p);
  if (w.y > 0.0) c += w.y * sp_material_color(1, p);
  if (w.z > 0.0) c += w.z * sp_material_color(2, p);
  if (w.w > 0.0) c += w.w * sp_material_color(3, p);
  return c / sum;
}

// One directional light (sun) plus ambient; n and sun_dir unit vectors (toward the sun).
// Ambient 0.3 and sun 1.2: with the default sun 25 deg above the horizon flat ground gets
// 0.3 + 1.2 sin 25 deg = 0.81, and a wall tilted 14 deg toward / away from the sun 1.06 / 0.53,
// so a crater one granule diameter deep reads (docs/rendering.md "Shading").
const float kAmbient = 0.3, kSun = 1.2;
uniform vec3 u_sun_dir;
// The light factor with a soft shoulder above 0.9 (value and slope continuous, tending to 1.2):
// flat ground (0.81) is untouched, a crater wall facing the sun (1.06) gets 1.02, and a
// granule's cap facing the low sun (up to 1.5, times the particle gain) 1.16 to 1.18 instead of
// clipping the sand to white.
float sp_shoulder(float light) { return light <= 0.9 ? light : 0.9 + 0.3 * (1.0 - exp(-(light - 0.9) / 0.3)); }
// The sun's share scaled by its visibility in [0, 1] (1 = lit, 0 = in shadow) and the whole by
// gain before the shoulder.
vec3 sp_shade_gain(vec3 albedo, vec3 n, float visibility, float gain) {
  float diffuse = max(dot(n, u_sun_dir), 0.0);
  return albedo * sp_shoulder(gain * (kAmbient + kSun * diffuse * visibility));
}
vec3 sp_shade(vec3 albedo, vec3 n) { return sp_shade_gain(albedo, n, 1.0, 1.0); }
vec3 sp_shade_visible(vec3 albedo, vec3 n, float visibility) { return sp_shade_gain(albedo, n, visibility, 1.0); }

// Bodies' shadows (render.cpp: an orthographic depth map of the bodies seen from the sun).
// u_shadow_matrix: local m -> [0, 1]^3 of the map; outside it everything is lit.
uniform bool u_shadow_on;
uniform mat4 u_shadow_matrix;
uniform sampler2DShadow u_shadow_map;  // depth compare, linear: 2 x 2 taps per lookup
uniform float u_shadow_bias;           // depth units of the map
uniform float u_shadow_texel;          // m, one texel's width (bodies' normal offset)
float sp_sun_visibility(vec3 p) {
  if (!u_shadow_on) return 1.0;
  vec4 q = u_shadow_matrix * vec4(p, 1.0);
  vec3 c = q.xyz / q.w;
  if (any(lessThan(c, vec3(0.0))) || any(greaterThan(c, vec3(1.0)))) return 1.0;
  vec2 texel = 1.0 / vec2(textureSize(u_shadow_map, 0));
  float v = 0.0;
  for (int j = -1; j <= 1; ++j)
    for (int i = -1; i <= 1; ++i) v += texture(u_shadow_map, vec3(c.xy + vec2(i, j) * texel, c.z - u_shadow_bias));
  return v / 9.0;
}
