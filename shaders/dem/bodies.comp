// Body stage (dem_bodies.cpp `bodies`): each body sums its own spheres' forces and torques in
// sphere-id order, integrates (symplectic Euler; normalised quaternion), and rebuilds its
// spheres' positions and velocities. u_mode = 1 only rebuilds the spheres of bodies
// [u_first_body, u_nb) (after an upload); u_mode = 2 only moves the kinematic bodies by u_dt
// (an asleep frame, dem_bodies.cpp move_kinematic).
// Compiled twice: without SP_WIDE_PASS one invocation steps one body, except in mode 0 a body
// of more than SP_WIDE spheres (a shell); with SP_WIDE_PASS (mode 0 only) a workgroup of
// SP_WIDE_WG invocations steps each body listed in G.wide_body: invocation t sums spheres t,
// t + SP_WIDE_WG, ... in order, a fixed tree adds the SP_WIDE_WG sums (the same order for any
// SP_WG), the first integrates, and all rebuild the spheres. One invocation looping over a
// shell of a few thousand spheres took most of a scene's step on a GPU, and 32 invocations
// over a crate of 48,000 spheres 70 % of it.
//   v += dt (F/m + g);  w += dt I^-1 (T - w x I w) (body frame; isotropic granules skip
//   the gyroscopic term);  x += dt v;  q += dt/2 (w, 0) q, normalised
// The spheres get the velocity predicted to the next contact stage's time, v + u_pred dt a
// with a = (v - v_old)/dt this substep's acceleration, translation only (dem_bodies.cpp `bodies`;
// u_pred = Simulation::velocity_predictor_gain; zero when a body is only rebuilt, modes 1, 2).
#ifdef SP_WIDE_PASS
layout(local_size_x = SP_WIDE_WG) in;
#else
layout(local_size_x = SP_WG) in;
#endif

uniform int u_mode;          // 0: sum + integrate + rebuild, 1: rebuild only, 2: move kinematic
uniform uint u_first_body;
uniform float u_dt;          // s
uniform vec3 u_gravity;      // m/s^2, sim units
uniform float u_reach;       // d + r of a granule (m), for its speed |v| + |w| (d + r)
uniform float u_pred;        // velocity predictor gain (1/2, less at large damping per substep)
uniform float u_resort_d2;   // (skin / 2)^2 (m^2): a larger displacement since the sort re-sorts

// Places spheres k0, k0 + stride, ... of the body; returns their largest squared displacement
// since the last sort.
float rebuild(uint b, vec3 x, vec4 q, vec3 v, vec3 w, float invm, int k0, int stride) {
  const int first = B.first[b], count = B.count[b];
  float d2max = 0.0;
  for (int k = k0; k < count; k += stride) {
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

// Integrates body b under the contact force F and torque T (about its centre of mass) summed
// this substep, and stores the new state. Returns false for a static body (nothing moves);
// else the state its spheres are rebuilt from: centre xn, orientation qn, the spheres'
// (predicted) velocity vs and angular velocity wn.
bool integrate(uint b, vec3 F, vec3 T, out vec3 xn, out vec4 qn, out vec3 vs, out vec3 wn) {
  const uint fl = B.flags[b];
  const vec3 x = B.pos[b].xyz;
  vec3 v = B.vel[b].xyz, w = B.omega[b].xyz;
  const vec3 v_old = v;
  vec4 q = B.quat[b];
  const float invm = B.mass[b].y;
  B.force[b].xyz = F;
  B.torque[b].xyz = T;
  if ((fl & SP_BODY_STATIC) != 0u) return false;
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
  xn = x + u_dt * v;
  const vec4 qd = quat_mul(vec4(w, 0.0), q);
  qn = quat_normalized(q + 0.5 * u_dt * qd);
  const float chk = xn.x + xn.y + xn.z + v.x + v.y + v.z + w.x + w.y + w.z + qn.w;
  if (isnan(chk) || isinf(chk)) atomicAdd(G.status.nonfinite_bodies, 1u);
  B.pos[b].xyz = xn;
  B.quat[b] = qn;
  vs = v + u_pred * (v - v_old);
  wn = w;
  return true;
}

// The force on sphere k of body b and its torque about the body's centre x (sphere-id order
// within a sum, as the CPU's body stage).
void add_sphere(uint b, int k, vec3 x, inout vec3 F, inout vec3 T) {
  const int s = S.slot_of[B.first[b] + k];
  const vec3 f = P.force[s].xyz;
  F = F + f;
  T = T + P.torque[s].xyz + cross(P.pos[s].xyz - x, f);
}

#ifdef SP_WIDE_PASS
shared vec4 w_F[SP_WIDE_WG], w_T[SP_WIDE_WG];  // (vec4: 16 bytes an element on every driver)
shared vec3 w_x, w_v, w_w;
shared vec4 w_q;
shared bool w_moves;

void main() {
  const uint b = uint(G.wide_body[gl_WorkGroupID.x]);
  const int t = int(gl_LocalInvocationID.x);
  const int count = B.count[b];
  vec3 F = vec3(0.0), T = vec3(0.0);
  const vec3 x = B.pos[b].xyz;
  for (int k = t; k < count; k += SP_WIDE_WG) add_sphere(b, k, x, F, T);
  w_F[t] = vec4(F, 0.0);
  w_T[t] = vec4(T, 0.0);
  barrier();
  for (int h = SP_WIDE_WG / 2; h > 0; h /= 2) {
    if (t < h) {
      w_F[t] = w_F[t] + w_F[t + h];
      w_T[t] = w_T[t] + w_T[t + h];
    }
    barrier();
  }
  if (t == 0) {
    vec3 xn, vs, wn;
    vec4 qn;
    w_moves = integrate(b, w_F[0].xyz, w_T[0].xyz, xn, qn, vs, wn);
    w_x = xn;
    w_q = qn;
    w_v = vs;
    w_w = wn;
  }
  barrier();
  if (w_moves && rebuild(b, w_x, w_q, w_v, w_w, B.mass[b].y, t, SP_WIDE_WG) > u_resort_d2) request_resort();  // common.glsl
}
#else
void main() {
  uint b = gl_GlobalInvocationID.x + (u_mode == 1 ? u_first_body : 0u);
  if (b >= u_nb) return;
  const uint fl = B.flags[b];
  const vec3 x = B.pos[b].xyz;
  const vec3 v = B.vel[b].xyz, w = B.omega[b].xyz;
  const vec4 q = B.quat[b];
  const float invm = B.mass[b].y;
  if (u_mode == 1) {
    rebuild(b, x, q, v, w, invm, 0, 1);  // the upload raised the re-sort flag
    return;
  }
  if (u_mode == 2) {
    if ((fl & SP_BODY_KINEMATIC) == 0u || (dot(v, v) == 0.0 && dot(w, w) == 0.0)) return;
    const vec3 xk = x + u_dt * v;
    const vec4 qk = quat_normalized(q + (0.5 * u_dt) * quat_mul(vec4(w, 0.0), q));
    B.pos[b].xyz = xk;
    B.quat[b] = qk;
    rebuild(b, xk, qk, v, w, invm, 0, 1);
    request_resort();  // moved: re-sort when awake (common.glsl)
    return;
  }
  const int count = B.count[b];
  if (count > SP_WIDE) return;  // the SP_WIDE_PASS's
  vec3 F = vec3(0.0), T = vec3(0.0);
  for (int k = 0; k < count; ++k) add_sphere(b, k, x, F, T);
  vec3 xn, vs, wn;
  vec4 qn;
  if (integrate(b, F, T, xn, qn, vs, wn) && rebuild(b, xn, qn, vs, wn, invm, 0, 1) > u_resort_d2)
    request_resort();  // common.glsl
}
#endif
