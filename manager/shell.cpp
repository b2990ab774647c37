// Body shells: see shell.hpp.
#include "manager/shell.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

namespace sandpatch {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;
constexpr float kGolden = 2.39996322972865332f;  // rad, π (3 − √5): Fibonacci lattice angle

// Fibonacci points on the sphere of radius R (or its upper / lower cap when hemi = ±1).
void fibonacci(float R, float spacing, int hemi, Eigen::Vector3f centre, std::vector<Eigen::Vector3f>& out) {
  const float area = 4 * kPi * R * R;
  const int n = std::max(4, int(std::ceil(area / (spacing * spacing * 0.8660254f))));
  for (int i = 0; i < n; ++i) {
    const float y = 1 - 2 * (i + 0.5f) / float(n);
    // Hemispheres leave out a band of spacing/2 at the equator: the side rings hold it.
    if ((hemi > 0 && y * R < 0.5f * spacing) || (hemi < 0 && -y * R < 0.5f * spacing)) continue;
    const float rho = std::sqrt(std::max(0.0f, 1 - y * y)), phi = kGolden * float(i);
    out.push_back(centre + R * Eigen::Vector3f(rho * std::cos(phi), y, rho * std::sin(phi)));
  }
}

// Rings of a cylinder side (radius R, y from y0 to y1, both ends included).
void side_rings(float R, float y0, float y1, float spacing, std::vector<Eigen::Vector3f>& out) {
  const int ny = std::max(1, int(std::ceil((y1 - y0) / spacing)));
  const int nt = std::max(3, int(std::ceil(2 * kPi * R / spacing)));
  for (int j = 0; j <= ny; ++j) {
    const float y = y0 + (y1 - y0) * float(j) / float(ny);
    for (int k = 0; k < nt; ++k) {
      const float t = 2 * kPi * float(k) / float(nt) + (j % 2) * kPi / float(nt);  // staggered rows
      out.push_back({R * std::cos(t), y, R * std::sin(t)});
    }
  }
}

// Concentric rings of a disc at height y (rim excluded: the side rings hold it).
void disc(float R, float y, float spacing, std::vector<Eigen::Vector3f>& out) {
  const int nr = std::max(1, int(std::ceil(R / spacing)));
  out.push_back({0, y, 0});
  for (int i = 1; i < nr; ++i) {
    const float r = R * float(i) / float(nr);
    const int nt = std::max(3, int(std::ceil(2 * kPi * r / spacing)));
    for (int k = 0; k < nt; ++k) {
      const float t = 2 * kPi * float(k) / float(nt);
      out.push_back({r * std::cos(t), y, r * std::sin(t)});
    }
  }
}

// Grid on every face of a box (half extents h); each point once.
void box(const Eigen::Vector3f& h, float spacing, std::vector<Eigen::Vector3f>& out) {
  int n[3];
  for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::ceil(2 * h[a] / spacing)));
  for (int i = 0; i <= n[0]; ++i)
    for (int j = 0; j <= n[1]; ++j)
      for (int k = 0; k <= n[2]; ++k) {
        const bool on = i == 0 || i == n[0] || j == 0 || j == n[1] || k == 0 || k == n[2];
        if (!on) continue;
        out.push_back({-h.x() + 2 * h.x() * float(i) / float(n[0]), -h.y() + 2 * h.y() * float(j) / float(n[1]),
                       -h.z() + 2 * h.z() * float(k) / float(n[2])});
      }
}

struct CellHash {
  std::size_t operator()(const Eigen::Vector3i& c) const {
    return std::size_t(c.x()) * 73856093u ^ std::size_t(c.y()) * 19349663u ^ std::size_t(c.z()) * 83492791u;
  }
};
struct CellEq {
  bool operator()(const Eigen::Vector3i& a, const Eigen::Vector3i& b) const { return a == b; }
};

// Triangle surfaces on barycentric grids, then points closer than spacing/2 to an earlier
// one are dropped (shared edges and vertices are sampled by both triangles).
void mesh(const RigidShape& s, float spacing, std::vector<Eigen::Vector3f>& out) {
  std::vector<Eigen::Vector3f> raw;
  for (const auto& t : s.triangles) {
    const Eigen::Vector3f a = s.vertices[t[0]], b = s.vertices[t[1]], c = s.vertices[t[2]];
    const float longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const int n = std::max(1, int(std::ceil(longest / spacing)));
    for (int i = 0; i <= n; ++i)
      for (int j = 0; i + j <= n; ++j) {
        const float u = float(i) / float(n), v = float(j) / float(n);
        raw.push_back(a + u * (b - a) + v * (c - a));
      }
  }
  const float cell = 0.5f * spacing;
  std::unordered_map<Eigen::Vector3i, std::vector<int>, CellHash, CellEq> grid;
  for (const auto& p : raw) {
    const Eigen::Vector3i c = (p / cell).array().floor().cast<int>();
    bool near = false;
    for (int dx = -1; dx <= 1 && !near; ++dx)
      for (int dy = -1; dy <= 1 && !near; ++dy)
        for (int dz = -1; dz <= 1 && !near; ++dz) {
          auto it = grid.find(c + Eigen::Vector3i(dx, dy, dz));
          if (it == grid.end()) continue;
          for (int q : it->second)
            if ((out[q] - p).squaredNorm() < cell * cell) {
              near = true;
              break;
            }
        }
    if (near) continue;
    grid[c].push_back(int(out.size()));
    out.push_back(p);
  }
}

}  // namespace

Result<std::vector<Eigen::Vector3f>> sample_shell(const RigidShape& s, float spacing, int max_points) {
  if (!(spacing > 0) || !std::isfinite(spacing)) {
    return Error{"", "shell spacing", std::to_string(spacing), "must be finite and > 0 (m)"};
  }
  std::vector<Eigen::Vector3f> out;
  switch (s.kind) {
    case RigidShapeKind::Sphere: fibonacci(s.radius, spacing, 0, Eigen::Vector3f::Zero(), out); break;
    case RigidShapeKind::Box: box(s.half_extents, spacing, out); break;
    case RigidShapeKind::Cylinder:
      side_rings(s.radius, -0.5f * s.height, 0.5f * s.height, spacing, out);
      disc(s.radius, -0.5f * s.height, spacing, out);
      disc(s.radius, 0.5f * s.height, spacing, out);
      break;
    case RigidShapeKind::Capsule:
      side_rings(s.radius, -0.5f * s.height, 0.5f * s.height, spacing, out);
      fibonacci(s.radius, spacing, +1, {0, 0.5f * s.height, 0}, out);
      fibonacci(s.radius, spacing, -1, {0, -0.5f * s.height, 0}, out);
      break;
    case RigidShapeKind::Mesh: mesh(s, spacing, out); break;
  }
  if (int(out.size()) > max_points) {
    return Error{"", "pool.shell_particles_per_slot", std::to_string(max_points),
                 "too small for a body shell of " + std::to_string(out.size()) + " spheres at spacing " +
                     std::to_string(spacing) + " m; raise it or use a coarser granule size"};
  }
  return out;
}

}  // namespace sandpatch
