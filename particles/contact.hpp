// Contact force laws of the granule DEM, for one sphere of a pair (sim units).
// Used by the contact stage of particles/dem.cpp; header-only so it inlines.
//
// Notation: n = unit normal pointing from the partner to this sphere; delta = overlap (m);
// v = velocity of this sphere's contact point relative to the partner's (m/s).
//   normal      f_n = max(0, k_n delta - d),  d = c_n v.n; in the first substep of a contact
//               (ContactParams::new_contact) |d| = c_n (min(delta/dt, |v.n|) + |v.n|/2)
//               instead, with the sign of v.n                          (N, never attractive)
//   tangential  v_t = v - (v.n) n
//     SpringHistory (Cundall-Strack): xi <- xi - (xi.n) n, rescaled to its old length;
//                 xi <- xi + v_t dt; slip: if k_t |xi| > mu f_n, xi is shortened to
//                 |xi| = mu f_n / k_t; then f_t = -k_t xi - beta c_t v_t with the largest
//                 beta in [0, 1] that keeps |f_t| <= mu f_n.
//                 Why not LAMMPS' xi <- -(f_t + c_t v_t)/k_t: that stores the damper's force
//                 in the spring and releases it later as work, so energy can rise (measured:
//                 +0.3% of the total in one step in a damped granule gas). Here the spring is
//                 only ever shortened by slip and the damper only ever removes energy.
//     Bell:       f_t = -min(mu f_n, k_b |v_t|) v_t/|v_t|
#pragma once

#include <cmath>

#include "particles/math.hpp"

namespace sandpatch {

struct ContactParams {
  float kn = 0;      // N/m
  float cn = 0;      // N s/m for this pair
  float kt = 0;      // N/m (spring) 
  float ct = 0;      // N s/m (spring law tangential damping)
  float mu = 0;      // friction coefficient
  float kb = 0;      // N s/m (Bell's velocity cap)
  float dt = 0;      // s, substep
  bool bell = false;
  // true in the first substep of a contact (the pair or plane did not touch at the previous
  // substep): the dashpot then gives the impulse of the time since the touch plus half a step
  // (see contact_force). particles/dem.cpp and shaders/dem/force.comp set it.
  bool new_contact = false;
};

struct ContactForce {
  Vec3 f;            // total force on this sphere, N
  Vec3 ft;           // tangential part, N
  float energy = 0;  // elastic energy of the pair's springs, J
};

// xi is the tangential spring (m) of this contact from the previous substep (zero for a new
// contact); it is updated in place (SpringHistory only).
inline ContactForce contact_force(const ContactParams& p, Vec3 n, float delta, Vec3 v, Vec3& xi) {
  ContactForce out;
  float vn = dot(v, n);
  // Dashpot c_n vn. The caller passes v at the substep's time t_n (particles/dem.cpp predicts
  // the bodies' translation as v + (dt/2) a_prev, symplectic Euler's v being half a step old;
  // less at large damping per substep, Simulation::velocity_predictor_gain). The kick at t_n stands
  // for [t_n - dt/2, t_n + dt/2]; in the first substep of a contact (p.new_contact) the touch
  // was delta/|vn| before t_n (delta < |vn| dt for an approach from outside), so the dashpot's
  // impulse from the touch to t_n + dt/2 is c_n (delta + |vn| dt/2): |fd| = c_n (delta/dt +
  // |vn|/2), with delta/dt capped at |vn| (a contact that did not start by approach, e.g. a
  // body placed overlapping, gets at most 1.5 c_n |vn|). With the full c_n |vn| whatever the
  // phase of the touch, e = 0.1 at dt = t_contact/50 came out -17 % ... +2 % with the phase;
  // with this and the predictor, -1.2 ... -1.0 % (docs/dem.md "Step size"). Only the first
  // substep: a cap on every contact with delta < |vn| dt also strips the damping from lightly
  // loaded resting contacts (overlap ~ m g / k_n) and beds stopped settling (measured, ibid.).
  // fd has the sign of vn, so the dashpot still opposes the normal motion.
  float fd = p.cn * vn;
  if (p.new_contact) {
    const float avn = std::fabs(vn);
    const float dd = delta < avn * p.dt ? delta / p.dt : avn;
    fd = std::copysign(p.cn * (dd + 0.5f * avn), vn);
  }
  float fn = p.kn * delta - fd;
  fn = fn > 0.0f ? fn : 0.0f;
  Vec3 vt = v - vn * n;
  Vec3 ft{};
  if (!p.bell) {
    float xi2 = dot(xi, xi);
    if (xi2 > 0.0f) {
      Vec3 xr = xi - dot(xi, n) * n;  // rotate into the new tangent plane
      float xr2 = dot(xr, xr);
      // rescale to the old length: sqrt(q), q = xi2/xr2 >= 1. The normal turns by
      // O(v dt / r) per substep, so q - 1 is tiny and (1 + q)/2 matches sqrt(q) to
      // (q-1)^2/8; fall back to the sqrt for larger turns.
      float q = xr2 > 0.0f ? xi2 / xr2 : 0.0f;
      float sc = q < 1.001f ? 0.5f * (1.0f + q) : std::sqrt(q);
      xi = xr2 > 0.0f ? xr * sc : Vec3{};
    }
    xi = xi + vt * p.dt;
    const float cap = p.mu * fn;
    float xl2 = dot(xi, xi);
    if (p.kt * p.kt * xl2 > cap * cap) xi = xi * (cap / (p.kt * std::sqrt(xl2)));  // slip
    Vec3 a = -p.kt * xi, b = -p.ct * vt;
    ft = a + b;
    float ft2 = dot(ft, ft);
    if (ft2 > cap * cap) {
      // largest beta with |a + beta b| <= cap; |a| <= cap so beta = 0 is always feasible
      float bb = dot(b, b), ab = dot(a, b), aa = dot(a, a);
      float disc = ab * ab - bb * (aa - cap * cap);
      float beta = bb > 0.0f ? (-ab + std::sqrt(disc > 0.0f ? disc : 0.0f)) / bb : 0.0f;
      beta = beta < 0.0f ? 0.0f : (beta > 1.0f ? 1.0f : beta);
      ft = a + beta * b;
    }
    out.energy = 0.5f * p.kn * delta * delta + 0.5f * p.kt * dot(xi, xi);
  } else {
    float vt2 = dot(vt, vt);
    if (vt2 > 0.0f) {
      float s = std::sqrt(vt2);
      float m = std::fmin(p.mu * fn, p.kb * s);
      ft = vt * (-m / s);
    }
    out.energy = 0.5f * p.kn * delta * delta;
  }
  out.f = fn * n + ft;
  out.ft = ft;
  return out;
}

}  // namespace sandpatch
