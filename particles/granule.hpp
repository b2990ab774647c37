// Tetrahedral granule geometry (Bell et al. 2005; Leach & Marais §4): 4 equal spheres of
// radius r at the vertices of a regular tetrahedron of edge a = 2 r s.
//
//   s = edge_factor: s = 1 -> neighbouring spheres just touch; s < 1 -> they overlap (a
//   rounder, more compact granule). Default 1 (touching): the most interlocking shape
//   with no overlap, so mass = 4 sphere masses exactly.
//   centre-to-sphere distance  d = a sqrt(3/8)
//   mass                       m = 4 m_s,  m_s = rho (4/3) pi r^3
//   inertia (isotropic)        I = 4 (2/5) m_s r^2 + (8/3) m_s d^2
// The second term is the parallel-axis sum sum_k m_s (d^2 - (p_k . u)^2) with
// sum_k (p_k . u)^2 = (4/3) d^2 for every unit axis u (a regular tetrahedron is a spherical
// 2-design), hence isotropic. With s = 1: d^2 = 1.5 r^2 and I = 5.6 m_s r^2 = 1.4 m r^2.
#pragma once

#include <array>

#include "particles/math.hpp"

namespace sandpatch {

struct GranuleShape {
  float radius = 0;                  // r, m
  float edge_factor = 1;             // s
  std::array<Vec3, 4> offsets{};     // body-frame sphere centres, m (centroid at origin)
  float mass = 0;                    // kg
  float inertia = 0;                 // kg m^2, isotropic principal moment
  float centre_distance = 0;         // d, m
};

GranuleShape make_granule_shape(float radius, float edge_factor, float density);

// Effective mass (kg) of a rigid body of mass m and isotropic-or-smallest inertia I at a point
// at distance `arm` from its centre of mass, for a push perpendicular to the arm (the worst
// case): 1 / (1/m + arm^2 / I). Used by the stability guard.
double point_effective_mass(double mass, double inertia_min, double arm);

}  // namespace sandpatch
