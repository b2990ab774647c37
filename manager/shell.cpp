// Body shells: see shell.hpp.
#include "manager/shell.hpp"

#include "common/hash.hpp"
#include "manager/mesh_sdf.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <mutex>
#include <numbers>

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

}  // namespace

Result<std::vector<Eigen::Vector3f>> sample_shell(const RigidShape& s, float spacing, float sphere_radius,
                                                  int max_points) {
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
    case RigidShapeKind::Mesh: {
      // The SDF is the expensive part (Leach: "a pre-processing step"): a mesh body re-entering
      // patches, or many bodies of one mesh, reuse the shell of the same mesh, spacing and radius.
      Hasher key;
      key.bytes(s.vertices.data(), s.vertices.size() * sizeof(Eigen::Vector3f));
      key.bytes(s.triangles.data(), s.triangles.size() * sizeof(std::array<int, 3>));
      key.pod(spacing);
      key.pod(sphere_radius);
      static std::mutex mutex;
      static std::map<std::uint64_t, std::vector<Eigen::Vector3f>> cache;  // at most kCached shells
      constexpr std::size_t kCached = 32;
      {
        std::lock_guard<std::mutex> lock(mutex);
        auto it = cache.find(key.value());
        if (it != cache.end()) {
          if (int(it->second.size()) <= max_points) return it->second;
          out = it->second;  // over this capacity: the error below
        }
      }
      if (!out.empty()) break;
      auto sdf = MeshSdf::create(s.vertices, s.triangles);
      if (!sdf) return sdf.errors();
      auto pts = sample_mesh_shell(*sdf, spacing, sphere_radius, max_points);
      if (pts) {
        std::lock_guard<std::mutex> lock(mutex);
        if (cache.size() >= kCached) cache.erase(cache.begin());
        cache[key.value()] = *pts;
      }
      return pts;
    }
  }
  if (int(out.size()) > max_points) {
    return Error{"", "simulation.pool.shell_spheres_per_slot", std::to_string(max_points),
                 "too small for a body shell of " + std::to_string(out.size()) + " spheres at spacing " +
                     std::to_string(spacing) + " m; raise it or use a coarser granule size"};
  }
  return out;
}

}  // namespace sandpatch
