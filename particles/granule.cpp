// Tetrahedral granule geometry; formulas in granule.hpp.
#include "particles/granule.hpp"

#include <cmath>
#include <numbers>

namespace sandpatch {

GranuleShape make_granule_shape(float radius, float edge_factor, float density) {
  GranuleShape g;
  g.radius = radius;
  g.edge_factor = edge_factor;
  double a = 2.0 * radius * edge_factor;         // edge length
  double d = a * std::sqrt(3.0 / 8.0);           // centre-to-vertex distance
  g.centre_distance = float(d);
  // Vertices of a regular tetrahedron: alternate corners of a cube, |(1,1,1)| = sqrt 3.
  const double k = d / std::sqrt(3.0);
  const double c[4][3] = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  for (int i = 0; i < 4; ++i) g.offsets[i] = {float(k * c[i][0]), float(k * c[i][1]), float(k * c[i][2])};
  double ms = density * 4.0 / 3.0 * std::numbers::pi * double(radius) * radius * radius;
  g.mass = float(4.0 * ms);
  g.inertia = float(4.0 * 0.4 * ms * radius * radius + 8.0 / 3.0 * ms * d * d);
  return g;
}

double point_effective_mass(double mass, double inertia_min, double arm) {
  return 1.0 / (1.0 / mass + arm * arm / inertia_min);
}

}  // namespace sandpatch
