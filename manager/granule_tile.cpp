// Pre-settled granule tiles: see granule_tile.hpp.
#include "manager/granule_tile.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

#include "particles/bed.hpp"

namespace sandpatch {
namespace {

// Sphere centres of a placed granule.
std::array<Vec3, 4> spheres(const PlacedGranule& g, const GranuleShape& s) {
  std::array<Vec3, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = g.position + rotate(g.orientation, s.offsets[k]);
  return out;
}

// A hash grid of sphere centres with cells of `cell` m.
class SphereGrid {
 public:
  explicit SphereGrid(float cell) : cell_(cell) {}
  void insert(Vec3 p) { cells_[key(p)].push_back(p); }
  // True when some stored centre is closer than `dist` to p.
  bool near(Vec3 p, float dist) const {
    const auto [i, j, k] = index(p);
    for (int a = -1; a <= 1; ++a)
      for (int b = -1; b <= 1; ++b)
        for (int c = -1; c <= 1; ++c) {
          auto it = cells_.find(pack(i + a, j + b, k + c));
          if (it == cells_.end()) continue;
          for (const Vec3& q : it->second)
            if (dot(q - p, q - p) < dist * dist) return true;
        }
    return false;
  }

 private:
  std::array<std::int64_t, 3> index(Vec3 p) const {
    return {std::int64_t(std::floor(p.x / cell_)), std::int64_t(std::floor(p.y / cell_)),
            std::int64_t(std::floor(p.z / cell_))};
  }
  static std::int64_t pack(std::int64_t i, std::int64_t j, std::int64_t k) {
    return (i & 0x1fffff) | ((j & 0x1fffff) << 21) | ((k & 0x1fffff) << 42);
  }
  std::int64_t key(Vec3 p) const {
    const auto [i, j, k] = index(p);
    return pack(i, j, k);
  }
  float cell_;
  std::unordered_map<std::int64_t, std::vector<Vec3>> cells_;
};

}  // namespace

float mean_top_height(const std::vector<PlacedGranule>& granules, const GranuleShape& shape, float x0, float z0,
                      float x1, float z1, float step, float floor) {
  const int nx = std::max(1, int((x1 - x0) / step)), nz = std::max(1, int((z1 - z0) / step));
  std::vector<float> top(std::size_t(nx) * nz, floor);
  const float r = shape.radius;
  for (const auto& g : granules) {
    for (const Vec3& c : spheres(g, shape)) {
      const int i0 = std::max(0, int(std::floor((c.x - r - x0) / step))), i1 = std::min(nx - 1, int((c.x + r - x0) / step));
      const int k0 = std::max(0, int(std::floor((c.z - r - z0) / step))), k1 = std::min(nz - 1, int((c.z + r - z0) / step));
      for (int k = k0; k <= k1; ++k)
        for (int i = i0; i <= i1; ++i) {
          const float x = x0 + (i + 0.5f) * step, z = z0 + (k + 0.5f) * step;
          const float d2 = (x - c.x) * (x - c.x) + (z - c.z) * (z - c.z);
          if (d2 <= r * r) {
            float& t = top[std::size_t(k) * nx + i];
            t = std::max(t, c.y + std::sqrt(r * r - d2));
          }
        }
    }
  }
  double sum = 0;
  for (float t : top) sum += t;
  return float(sum / double(top.size()));
}

std::vector<PlacedGranule> fill_from_tile(const GranuleTile& tile, float width, float depth,
                                          const std::function<float(float, float)>& surface) {
  const float r = tile.shape.radius, P = tile.period_xz, Py = tile.period_y;
  const float bound = tile.shape.centre_distance + r;
  // 1. Candidates: tile copies whose centres lie in the patch and at most one bounding radius
  //    above the surface, lowest first.
  float top = 0;
  const float probe = std::max(r, 0.25f * P);
  for (float z = 0; z <= depth + probe; z += probe)
    for (float x = 0; x <= width + probe; x += probe) top = std::max(top, surface(std::min(x, width), std::min(z, depth)));
  const int cx = int(std::ceil(width / P)), cz = int(std::ceil(depth / P)), cy = int(std::ceil(top / Py)) + 1;
  std::vector<PlacedGranule> cand;
  for (int b = 0; b < cy; ++b)
    for (int c = 0; c < cz; ++c)
      for (int a = 0; a < cx; ++a)
        for (const auto& g : tile.granules) {
          const Vec3 p{g.position.x + a * P, g.position.y + b * Py, g.position.z + c * P};
          if (p.x < 0 || p.x >= width || p.z < 0 || p.z >= depth) continue;
          if (p.y > surface(p.x, p.z) + bound) continue;
          cand.push_back({p, g.orientation});
        }
  std::stable_sort(cand.begin(), cand.end(),
                   [](const PlacedGranule& u, const PlacedGranule& v) { return u.position.y < v.position.y; });

  // 2. Greedy cut, bottom up: a texel map (step r/2) holds the top of the spheres placed so
  //    far; the patch is divided into columns of one granule diameter, each with the mean
  //    surface height it must render at. A candidate is placed when that brings the mean top
  //    of its column closer to the column's target (and it overlaps nothing placed).
  const float step = 0.5f * r, col = 2.0f * bound;
  const int tx = std::max(1, int(std::ceil(width / step))), tz = std::max(1, int(std::ceil(depth / step)));
  const int ncx = std::max(1, int(std::ceil(width / col))), ncz = std::max(1, int(std::ceil(depth / col)));
  std::vector<float> texel(std::size_t(tx) * tz, 0.0f);
  std::vector<double> col_sum(std::size_t(ncx) * ncz, 0.0), col_target(col_sum.size(), 0.0);
  std::vector<int> col_count(col_sum.size(), 0);
  auto column_of = [&](float x, float z) {
    return std::size_t(std::min(ncz - 1, int(z / col))) * ncx + std::size_t(std::min(ncx - 1, int(x / col)));
  };
  for (int k = 0; k < tz; ++k)
    for (int i = 0; i < tx; ++i) {
      const float x = (i + 0.5f) * step, z = (k + 0.5f) * step;
      const std::size_t c = column_of(x, z);
      col_target[c] += surface(std::min(x, width), std::min(z, depth));
      ++col_count[c];
    }
  for (std::size_t c = 0; c < col_sum.size(); ++c) col_target[c] /= std::max(1, col_count[c]);

  SphereGrid grid(2.0f * r);
  const float min_dist = 1.8f * r;  // spheres closer than this overlap by more than 10% of r
  std::vector<PlacedGranule> out;
  std::vector<std::pair<std::size_t, float>> raised;  // texel index, new top
  for (const auto& g : cand) {
    const auto sph = spheres(g, tile.shape);
    bool clash = false;
    for (const Vec3& sp : sph) clash = clash || sp.y < 0.5f * r || grid.near(sp, min_dist);
    if (clash) continue;
    // Texels this granule would raise, and by how much its own column's sum changes.
    raised.clear();
    const std::size_t home = column_of(g.position.x, g.position.z);
    double delta = 0;
    for (const Vec3& c : sph) {
      const int i0 = std::max(0, int(std::floor((c.x - r) / step))), i1 = std::min(tx - 1, int((c.x + r) / step));
      const int k0 = std::max(0, int(std::floor((c.z - r) / step))), k1 = std::min(tz - 1, int((c.z + r) / step));
      for (int k = k0; k <= k1; ++k)
        for (int i = i0; i <= i1; ++i) {
          const float x = (i + 0.5f) * step, z = (k + 0.5f) * step;
          const float d2 = (x - c.x) * (x - c.x) + (z - c.z) * (z - c.z);
          if (d2 > r * r) continue;
          const float h = c.y + std::sqrt(r * r - d2);
          const std::size_t t = std::size_t(k) * tx + i;
          if (h <= texel[t]) continue;
          raised.emplace_back(t, h);
        }
    }
    // Deduplicate per texel (keep the highest) while summing the home column's change.
    std::sort(raised.begin(), raised.end());
    for (std::size_t q = 0; q < raised.size(); ++q) {
      if (q + 1 < raised.size() && raised[q + 1].first == raised[q].first) continue;  // a higher one follows
      const std::size_t t = raised[q].first;
      const int i = int(t % std::size_t(tx)), k = int(t / std::size_t(tx));
      if (column_of((i + 0.5f) * step, (k + 0.5f) * step) == home) delta += raised[q].second - texel[t];
    }
    const double n = std::max(1, col_count[home]);
    const double before = col_sum[home] / n - col_target[home], after = (col_sum[home] + delta) / n - col_target[home];
    if (std::abs(after) >= std::abs(before)) continue;
    for (std::size_t q = 0; q < raised.size(); ++q) {
      if (q + 1 < raised.size() && raised[q + 1].first == raised[q].first) continue;
      const std::size_t t = raised[q].first;
      const int i = int(t % std::size_t(tx)), k = int(t / std::size_t(tx));
      col_sum[column_of((i + 0.5f) * step, (k + 0.5f) * step)] += raised[q].second - texel[t];
      texel[t] = raised[q].second;
    }
    for (const Vec3& sp : sph) grid.insert(sp);
    out.push_back(g);
  }
  return out;
}

Result<GranuleTile> make_granule_tile(const GranuleTileDef& def) {
  if (def.columns < 4) return Error{"", "granule_tile.columns", std::to_string(def.columns), "must be >= 4"};
  if (def.layers < 4) return Error{"", "granule_tile.layers", std::to_string(def.layers), "must be >= 4"};
  const GranuleShape shape = make_granule_shape(def.radius, 1.0f, def.material.density);
  const float bound = shape.centre_distance + shape.radius;  // bounding radius of a granule
  const float a = 2.0f * bound * 1.02f;                        // lattice spacing (add_lattice_bed's default)
  const float L = a * float(def.columns);

  SimulationDef sd;
  sd.max_bodies = def.columns * def.columns * def.layers;
  sd.max_particles = 4 * sd.max_bodies;
  sd.particle_radius = def.radius;
  sd.material = def.material;
  sd.gravity_world = def.gravity;
  sd.bounds_min = {0, 0, 0};
  sd.bounds_max = {L, a * float(def.layers + 2), L};
  sd.floor_height = 0;
  sd.side_walls = true;
  sd.threads = def.threads;
  auto sim = Simulation::create(sd);
  if (!sim) return sim.errors();
  LatticeBedDef bed;
  bed.min = {0.5f * a, bound * 1.05f, 0.5f * a};
  bed.nx = bed.nz = def.columns;
  bed.layers = def.layers;
  bed.seed = def.seed;
  bed.jitter = 0.4f;  // a strongly jittered lattice settles without remembering its layers
  if (Status s = add_lattice_bed(*sim, bed); !s) return s.errors();

  // Settle: frames of 1/120 s until every granule is slower than settle_speed.
  GranuleTile tile;
  const double frame = 1.0 / 120.0;
  double t = 0;
  for (; t < def.settle_max_time; t += frame) {
    if (Status s = sim->step(frame); !s) return s.errors();
    if (t > 0.25 && sim->max_granule_speed() < def.settle_speed) break;
  }
  tile.settle_time = t;
  tile.settled_speed = float(sim->max_granule_speed());
  tile.shape = shape;

  // Interior: two bounding diameters from each wall; vertical period: below the rough top.
  const float margin = 2.0f * bound;
  tile.period_xz = L - 2.0f * margin;
  float ymax = 0;
  for (int b = 0; b < sim->body_count(); ++b) ymax = std::max(ymax, sim->body_position(BodyId{b}).y);
  tile.period_y = ymax - 2.0f * bound;
  for (int b = 0; b < sim->body_count(); ++b) {
    const Vec3 p = sim->body_position(BodyId{b});
    if (p.x < margin || p.x >= margin + tile.period_xz || p.z < margin || p.z >= margin + tile.period_xz) continue;
    if (p.y >= tile.period_y) continue;
    tile.granules.push_back({{p.x - margin, p.y, p.z - margin}, sim->body_orientation(BodyId{b})});
  }
  const double vg = 4.0 * 4.0 / 3.0 * std::numbers::pi * double(def.radius) * def.radius * def.radius;
  tile.packing_fraction =
      float(double(tile.granules.size()) * vg / (double(tile.period_xz) * tile.period_xz * tile.period_y));

  return tile;
}

}  // namespace sandpatch
