// Lattice beds; see bed.hpp.
#include "particles/bed.hpp"

#include <cmath>
#include <numbers>

#include "common/random.hpp"

namespace sandpatch {


Status add_lattice_bed(Simulation& sim, const LatticeBedDef& bed) {
  const GranuleShape& g = sim.granule_shape();
  float a = bed.spacing > 0 ? bed.spacing : 2.0f * (g.centre_distance + g.radius) * 1.02f;
  std::uint64_t s = bed.seed;
  int total = bed.count >= 0 ? bed.count : bed.nx * bed.nz * bed.layers;
  int n = 0;
  for (int l = 0; l < bed.layers && n < total; ++l)
    for (int k = 0; k < bed.nz && n < total; ++k)
      for (int i = 0; i < bed.nx && n < total; ++i, ++n) {
        float jx = float((uniform(s) - 0.5) * 2.0 * bed.jitter * a);
        float jz = float((uniform(s) - 0.5) * 2.0 * bed.jitter * a);
        // uniform random rotation (Shoemake)
        double u1 = uniform(s), u2 = uniform(s), u3 = uniform(s);
        double r1 = std::sqrt(1 - u1), r2 = std::sqrt(u1), t1 = 2 * std::numbers::pi * u2, t2 = 2 * std::numbers::pi * u3;
        Quat q{float(r1 * std::sin(t1)), float(r1 * std::cos(t1)), float(r2 * std::sin(t2)), float(r2 * std::cos(t2))};
        Vec3 x{bed.min.x + i * a + jx, bed.min.y + l * a, bed.min.z + k * a + jz};
        auto id = sim.add_granule(x, q);
        if (!id) return id.errors();
      }
  return Ok{};
}

double peer_footprint(int granules, double radius) {
  double spheres = 4.0 * granules;
  return 0.4 * std::sqrt(spheres / 20000.0) * (2.0 * radius / 0.01);
}

}  // namespace sandpatch
