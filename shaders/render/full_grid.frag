#version 430 core
// Benchmark only: shading of the full-resolution grid (material 0, the same light).
in vec2 v_xz;
in vec3 v_normal;
out vec4 o_color;
void main() {
  o_color = vec4(sp_shade(sp_material_color(0, v_xz), normalize(v_normal)), 1.0);
}
