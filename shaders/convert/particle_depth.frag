#version 430
// Writes the linear depth of the top of a sphere for an orthographic camera looking down
// (-y) from height y_c with near n and far f:  z = (y_c - n - h) / (f - n),  so that
// h = y_c - n - z (f - n) (Leach & Marais §5.2). The depth test keeps the highest surface.
uniform vec3 u_camera;   // y_c, n, f (m)
in vec2 v_offset;
flat in vec2 v_centre;

void main() {
  float d2 = dot(v_offset, v_offset);
  if (d2 > 1.0) discard;
  float h = v_centre.x + v_centre.y * sqrt(1.0 - d2);
  gl_FragDepth = clamp((u_camera.x - u_camera.y - h) / (u_camera.z - u_camera.y), 0.0, 1.0);
}
