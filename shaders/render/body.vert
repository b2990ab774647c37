#version 430 core
// Rigid bodies: triangles tessellated on the CPU (render/bodies.hpp), already posed, in
// heightfield-local metres.

layout(location = 0) in vec3 a_position;  // m, local
layout(location = 1) in vec3 a_normal;    // unit, world axes
layout(location = 2) in vec3 a_color;     // albedo (lit) or ID colour (flat)

uniform mat4 u_view_proj;                 // local -> clip

out vec3 v_position;
out vec3 v_normal;
out vec3 v_color;

void main() {
  v_position = a_position;
  v_normal = a_normal;
  v_color = a_color;
  gl_Position = u_view_proj * vec4(a_position, 1.0);
}
