#version 430 core
// One direction of the granule bed's smoothing (docs/rendering.md "Particles"): the depth
// pre-pass of the granules, blurred along u_dir by a Gaussian of one drawn sphere radius
// (sigma, in pixels at each pixel's own depth), so the bed the colour pass takes its normal
// and its shadow lookup from is the surface the granules make up, not their caps. A sample
// counts only where it lies on the same surface as the pixel: within two sphere radii in eye
// depth, plus kSteep times its distance across the image (a granule in front of or behind the
// bed, a body's edge, or a gap to the ground far below stays out of the mean). Window depth in,
// window depth out (R32F); 1 where no granule was drawn.

in vec2 v_uv;

uniform sampler2D u_depth;   // window depth in [0, 1], 1 = no granule
uniform mat4 u_proj_inv;     // clip -> eye
uniform vec2 u_size;         // pixels
uniform ivec2 u_dir;         // (1, 0) or (0, 1)
uniform float u_px_per_m;    // P[1][1] * height / 2: pixels per metre at eye distance 1
uniform float u_radius;      // m: the drawn sphere radius (the finest of the frame's patches)
uniform float u_sigma;       // the Gaussian's sigma in sphere radii

out float o_depth;

float eye_depth(ivec2 px, float d) {
  vec2 ndc = (vec2(px) + 0.5) / u_size * 2.0 - 1.0;
  vec4 p = u_proj_inv * vec4(ndc, d * 2.0 - 1.0, 1.0);
  return -p.z / p.w;  // > 0 in front of the eye
}

void main() {
  const float kSteep = 3.0;
  ivec2 px = ivec2(gl_FragCoord.xy);
  float d0 = texelFetch(u_depth, px, 0).r;
  if (d0 >= 1.0) {
    o_depth = 1.0;
    return;
  }
  float z0 = eye_depth(px, d0);
  float m_per_px = max(z0, 1e-4) / u_px_per_m;
  float sigma = clamp(u_sigma * u_radius / m_per_px, 0.5, 8.0);
  int reach = int(ceil(2.0 * sigma));
  float sum = 0.0, wsum = 0.0;
  for (int k = -reach; k <= reach; ++k) {
    ivec2 q = px + k * u_dir;
    if (any(lessThan(q, ivec2(0))) || any(greaterThanEqual(q, ivec2(u_size)))) continue;
    float d = texelFetch(u_depth, q, 0).r;
    if (d >= 1.0) continue;
    if (abs(eye_depth(q, d) - z0) > 2.0 * u_radius + kSteep * float(abs(k)) * m_per_px) continue;
    float w = exp(-0.5 * float(k * k) / (sigma * sigma));
    sum += w * d;
    wsum += w;
  }
  o_depth = sum / wsum;  // (the pixel itself always counts)
}
