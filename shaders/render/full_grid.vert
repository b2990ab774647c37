#version 430 core
// Benchmark only: the whole heightfield at full resolution, one triangle strip per row of
// cells (instance = row), vertices generated from gl_VertexID; heights from an R32F texture of
// the full grid. The yardstick clipmaps are compared against (docs/rendering.md).

uniform mat4 u_view_proj;
uniform float u_spacing;          // m
uniform sampler2D u_heights;      // samples_x x samples_z, R32F (m, local)

out vec2 v_xz;
out vec3 v_normal;

float h_at(ivec2 g) {
  ivec2 size = textureSize(u_heights, 0);
  return texelFetch(u_heights, clamp(g, ivec2(0), size - 1), 0).r;
}

void main() {
  ivec2 g = ivec2(gl_VertexID >> 1, gl_InstanceID + (gl_VertexID & 1));
  float h = h_at(g);
  float dx = (h_at(g + ivec2(1, 0)) - h_at(g - ivec2(1, 0))) / (2.0 * u_spacing);
  float dz = (h_at(g + ivec2(0, 1)) - h_at(g - ivec2(0, 1))) / (2.0 * u_spacing);
  v_normal = normalize(vec3(-dx, 1.0, -dz));
  v_xz = vec2(g) * u_spacing;
  gl_Position = u_view_proj * vec4(v_xz.x, h, v_xz.y, 1.0);
}
