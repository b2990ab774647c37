#version 430
// Particles -> heightfield (Leach & Marais §5.2): each sphere is drawn as a screen-aligned
// quad seen from above by an orthographic camera; the fragment shader writes the depth of
// the sphere's upper surface. Six vertices per sphere, no vertex buffer: the sphere index
// and the quad corner come from gl_VertexID.
layout(std430, binding = 0) readonly buffer Spheres { vec4 spheres[]; };  // xyz (m, local), radius (m)
uniform vec4 u_region;   // x0, z0, x1, z1 (m, local): the rectangle mapped onto the image
out vec2 v_offset;       // position in the quad in units of the radius, [-1, 1]^2
flat out vec2 v_centre;  // sphere centre height (m) and radius (m)

const vec2 kCorners[6] = vec2[](vec2(-1, -1), vec2(1, -1), vec2(1, 1), vec2(-1, -1), vec2(1, 1), vec2(-1, 1));

void main() {
  vec4 s = spheres[gl_VertexID / 6];
  vec2 c = kCorners[gl_VertexID % 6];
  vec2 xz = s.xz + c * s.w;
  vec2 ndc = (xz - u_region.xy) / (u_region.zw - u_region.xy) * 2.0 - 1.0;
  v_offset = c;
  v_centre = vec2(s.y, s.w);
  gl_Position = vec4(ndc, 0.0, 1.0);
}
