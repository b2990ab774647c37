#version 430 core
// Circular splat with sphere shading and the sphere's depth: the point sprite is cut to a disc,
// the disc point lifted onto the sphere facing the eye, lit like the terrain, and its depth
// written so splats intersect each other and the terrain correctly.
// The normal may be bent (u_normal_bend) toward the bed's: the surface the granules make up,
// estimated from a depth pre-pass of the same granules (u_bed_depth: eye positions u_bed_scale
// granule radii to each side of the pixel, on screen), so a crater's or a heap's slopes are
// lit as slopes; where the pre-pass is missing (no granule there) the terrain's normal.

in vec3 v_center_eye;
in float v_radius;
in vec4 v_weights;
in vec3 v_ground_normal;
in float v_tint;
in float v_terrain_vis;

uniform mat4 u_proj;
uniform mat4 u_view_inv;   // eye -> local
uniform float u_fade;      // fade-in factor in [0, 1]
uniform float u_normal_bend;  // 0 = pure sphere normal, 1 = the terrain's normal
uniform float u_gain;      // brightness gain (RendererDef::particle_gain)
uniform bool u_bed_on;
uniform sampler2D u_bed_depth;  // depth of the granules' pre-pass (window depth in [0, 1])
uniform mat4 u_proj_inv;        // clip -> eye
uniform vec2 u_viewport;        // pixels
uniform float u_bed_scale;      // granule radii between the samples and the pixel
uniform float u_shading_scale;  // >= 1: how many times coarser than the sand they stand for the granules are

// Eye position of the pre-pass surface under window position px (w = 0: no granule there).
vec4 bed_eye(vec2 px) {
  vec2 uv = px / u_viewport;
  if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) return vec4(0.0);
  float d = texture(u_bed_depth, uv).r;
  if (d >= 1.0) return vec4(0.0);
  vec4 p = u_proj_inv * vec4(uv * 2.0 - 1.0, d * 2.0 - 1.0, 1.0);
  return vec4(p.xyz / p.w, 1.0);
}

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
  vec3 n_bed = normalize(v_ground_normal);
  vec4 c = vec4(0.0);  // the bed's eye position under this pixel (w = 0: none)
  if (u_bed_on) {
    // The bed's normal from the pre-pass, (1 + s) / 2 times further out at particle scale s: a
    // coarse patch's bed is as smooth as the sand it stands for, over as many granules. Eight
    // estimates, each the cross product of the differences across two perpendicular pairs of
    // samples, the pairs turned by 11.25 degrees from one estimate to the next, averaged (with two,
    // along the image's axes and diagonals, a patch of granules 1.5 px in radius was mottled: its
    // local contrast 15 luma against the ground's 0.5, now 10.5-13.8; docs/BENCHMARKS.md
    // "A fine patch at the default camera"). A sample across a
    // silhouette (a granule in front of or behind this pixel's bed point, or a gap) would tilt
    // an estimate wildly and leave a dark or bright speck at the patch's edge: an estimate counts
    // only when its four samples lie within kSteep times their distance across the image from
    // this pixel's bed point in depth (a slope of 72 degrees to the image plane). With neither,
    // the terrain's normal.
    float l_px = max(u_bed_scale * 0.5 * (1.0 + u_shading_scale) * v_radius * u_proj[1][1] * 0.5 * u_viewport.y /
                     max(-v_center_eye.z, 1e-4), 1.5);
    c = bed_eye(gl_FragCoord.xy);
    const float kSteep = 3.0;
    vec3 sum = vec3(0.0);
    for (int k = 0; k < 8 && c.w > 0.0; ++k) {
      const float a = 3.14159265 * 0.5 * float(k) / 8.0;
      vec2 u = vec2(cos(a), sin(a)) * l_px;
      vec2 v = vec2(-u.y, u.x);
      vec4 l = bed_eye(gl_FragCoord.xy - u), r = bed_eye(gl_FragCoord.xy + u);
      vec4 b = bed_eye(gl_FragCoord.xy - v), t = bed_eye(gl_FragCoord.xy + v);
      bool ok = l.w * r.w * b.w * t.w > 0.0 && abs(l.z - c.z) <= kSteep * length(l.xy - c.xy) &&
                abs(r.z - c.z) <= kSteep * length(r.xy - c.xy) && abs(b.z - c.z) <= kSteep * length(b.xy - c.xy) &&
                abs(t.z - c.z) <= kSteep * length(t.xy - c.xy);
      vec3 ne = cross(r.xyz - l.xyz, t.xyz - b.xyz);
      if (!ok || dot(ne, ne) <= 1e-20) continue;
      ne = normalize(ne);
      sum += ne.z < 0.0 ? -ne : ne;  // toward the eye
    }
    if (dot(sum, sum) > 1e-12) n_bed = normalize(mat3(u_view_inv) * normalize(sum));
  }
  // At particle scale s a granule stands for sand s times finer: its own shading is that of a
  // granule s times smaller on screen (a coarse patch does not turn into a heap of pebbles).
  float r_px = v_radius * u_proj[1][1] * 0.5 * u_viewport.y / max(-v_center_eye.z, 1e-4) / max(u_shading_scale, 1.0);
  float detail = smoothstep(1.5, 6.0, r_px);
  vec3 n = normalize(mix(n_sphere, n_bed, mix(1.0, u_normal_bend, detail)));
  vec3 p = (u_view_inv * vec4(p_eye, 1.0)).xyz;
  // Granule-scale occlusion: a sphere in a packed bed is shaded by its neighbours below its
  // equator (factor 0.8 facing into the bed to 1 facing out of it), so each granule reads as a
  // ball; u_gain brings the bed's mean brightness back to the terrain's.
  float occ = u_gain * mix(0.9, mix(0.8, 1.0, clamp(0.5 + 0.5 * dot(n_sphere, n_bed), 0.0, 1.0)), detail);
  float tint = mix(1.0, v_tint, 0.25 + 0.75 * detail);
  // The bodies' shadows, looked up where the light falls: on a fine bed (little detail of its
  // own) the smoothed bed under the pixel, so a shadow's edge crosses the bed as it crosses
  // sand, not cap by cap (looked up on the caps, a body's shadow edge left specks of 1.5 px
  // granules half lit); on granules large on screen their own surface.
  vec3 p_lit = c.w > 0.0 ? mix((u_view_inv * vec4(c.xyz, 1.0)).xyz, p, detail) : p;
  float vis = min(sp_sun_visibility(p_lit), v_terrain_vis);  // the bodies' shadows and the terrain's
  o_color = vec4(sp_shade_gain(tint * sp_blend_materials(v_weights, p.xz), n, vis, occ), u_fade);
}
