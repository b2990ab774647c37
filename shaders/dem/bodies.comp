// Body stage (dem_bodies.cpp `bodies`): each body sums its own spheres' forces and torques in
// sphere-id order, integrates (symplectic Euler; normalised quaternion), and rebuilds its
// spheres' positions and velocities. u_mode = 1 only rebuilds the spheres of bodies
// [u_first_body, u_nb) (after an upload); u_mode = 2 only moves the kinematic bodies by u_dt
// (an asleep frame, dem_bodies.cpp move_kinematic).
//   v += dt (F/m + g);  w += dt I^-1 (T - w x I w) (body frame; isotropic granules skip
//   the gyroscopic term);  x += dt v;  q += dt/2 (w, 0) q, normalised
// The spheres get the velocity predicted to the next contact stage's time, v + u_pred dt a
// with a = (v - v_old)/dt this substep's acceleration, translation only (dem_bodies.cpp `bodies`;
// u_pred = Simulation::velocity_predictor_gain; zero when a body is only rebuilt, modes 1, 2).
layout(local_size_x = SP_WG) in;

uniform int u_mode;          // 0: sum + integrate + rebuild, 1: rebuild only, 2: move kinematic
uniform uint u_first_body;
uniform float u_dt;          // s
uniform vec3 u_gravity;      // m/s^2, sim units
uniform float u_reach;       // d + r of a granule (m), for its speed |v| + |w| (d + r)
uniform float u_pred;        // velocity predictor gain (1/2, less at large damping per substep)
uniform float u_resort_d2;   // (skin / 2)^2 (m^2): a larger displacement since the sort re-sorts

// Returns the largest squared displacement of the body's spheres since the last sort.
float rebuild(uint b, vec3 x, vec4 q, vec3 v, vec3 w, float invm) {
  const int first = B.first[b], count = B.count[b];
  float d2max = 0.0;
  for (int k = 0; k < count; ++k) {
    const int s = S.slot_of[first + k];
    const vec3 arm = quat_rotate(q, P.offset[s].xyz);
    const vec3 xs = x + arm;
    P.pos[s].xyz = xs;
    P.vel[s] = vec4(v + cross(w, arm), invm);
    P.omega[s].xyz = w;
    const vec3 d = xs - S.pos_at_sort[s].xyz;
    d2max = max(d2max, dot(d, d));
  }
  return d2max;
}

void main() {
  uint b = gl_GlobalInvocationID.x + (u_mode == 1 ? u_first_body : 0u);
  if (b >= u_nb) return;
  const uint fl = B.flags[b];
  const vec3 x = B.pos[b].xyz;
  vec3 v = B.vel[b].xyz, w = B.omega[b].xyz;
  const vec3 v_old = v;
  vec4 q = B.quat[b];
  const float invm = B.mass[b].y;
  if (u_mode == 1) {
    rebuild(b, x, q, v, w, invm);  // the upload raised the re-sort flag
    return;
  }
  if (u_mode == 2) {
    if ((fl & SP_BODY_KINEMATIC) == 0u || (dot(v, v) == 0.0 && dot(w, w) == 0.0)) return;
    const vec3 xk = x + u_dt * v;
    q = quat_normalized(q + (0.5 * u_dt) * quat_mul(vec4(w, 0.0), q));
    B.pos[b].xyz = xk;
    B.quat[b] = q;
    rebuild(b, xk, q, v, w, invm);
    request_resort();  // moved: re-sort when awake (common.glsl)
    return;
  }
  vec3 F = vec3(0.0), T = vec3(0.0);
  const int first = B.first[b], count = B.count[b];
  for (int k = 0; k < count; ++k) {
    const int s = S.slot_of[first + k];
    const vec3 f = P.force[s].xyz;
    F = F + f;
    T = T + P.torque[s].xyz + cross(P.pos[s].xyz - x, f);
  }
  B.force[b].xyz = F;
  B.torque[b].xyz = T;
  if ((fl & SP_BODY_STATIC) != 0u) return;
  if ((fl & SP_BODY_DYNAMIC) != 0u) {
    v = v + u_dt * (F * invm + u_gravity);
    const vec3 iI = B.inv_inertia[b].xyz;
    if ((fl & SP_BODY_GRANULE) != 0u) {
      w = w + T * (u_dt * iI.x);  // isotropic inertia
    } else {
      vec3 wb = quat_rotate_inv(q, w), tb = quat_rotate_inv(q, T);
      vec3 Iw = vec3(iI.x > 0.0 ? wb.x / iI.x : 0.0, iI.y > 0.0 ? wb.y / iI.y : 0.0, iI.z > 0.0 ? wb.z / iI.z : 0.0);
      vec3 rhs = tb - cross(wb, Iw);
      wb = wb + u_dt * (rhs * iI);
      w = quat_rotate(q, wb);
    }
    B.vel[b].xyz = v;
    B.omega[b].xyz = w;
    if ((fl & SP_BODY_GRANULE) != 0u)
      atomicMax(G.status.max_granule_speed, floatBitsToUint(sqrt(dot(v, v)) + sqrt(dot(w, w)) * u_reach));
  }
  const vec3 xn = x + u_dt * v;
  const vec4 qd = quat_mul(vec4(w, 0.0), q);
  q = quat_normalized(q + 0.5 * u_dt * qd);
  const float chk = xn.x + xn.y + xn.z + v.x + v.y + v.z + w.x + w.y + w.z + q.w;
  if (isnan(chk) || isinf(chk)) atomicAdd(G.status.nonfinite_bodies, 1u);
  B.pos[b].xyz = xn;
  B.quat[b] = q;
  if (rebuild(b, xn, q, v + u_pred * (v - v_old), w, invm) > u_resort_d2) request_resort();  // common.glsl
}
