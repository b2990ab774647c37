// Signed distance to a closed mesh by FCL, and mesh shells: see mesh_sdf.hpp.
#include "manager/mesh_sdf.hpp"

#include <fcl/geometry/bvh/BVH_model.h>
#include <fcl/geometry/shape/sphere.h>
#include <fcl/math/bv/OBBRSS.h>
#include <fcl/narrowphase/distance.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unordered_map>

#include "scene/mesh.hpp"

namespace sandpatch {
namespace {

// Closest point on triangle (a, b, c) to p, and the Voronoi feature it lies on
// (Ericson 2005, §5.1.5): 0 = inside the face, 1/2/3 = vertex a/b/c, 4/5/6 = edge ab/bc/ca.
Eigen::Vector3d closest_on_triangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                    const Eigen::Vector3d& c, int* feature) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return *feature = 1, a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return *feature = 2, b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return *feature = 4, Eigen::Vector3d(a + (d1 / (d1 - d3)) * ab);
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return *feature = 3, c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return *feature = 6, Eigen::Vector3d(a + (d2 / (d2 - d6)) * ac);
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0)
    return *feature = 5, Eigen::Vector3d(b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b));
  const double s = 1.0 / (va + vb + vc);
  *feature = 0;
  return a + ab * (vb * s) + ac * (vc * s);
}

std::uint64_t edge_key(int a, int b) {
  return (std::uint64_t(std::uint32_t(std::min(a, b))) << 32) | std::uint32_t(std::max(a, b));
}

}  // namespace

struct MeshSdf::Impl {
  std::vector<Eigen::Vector3d> v;            // m
  std::vector<std::array<int, 3>> t;
  std::vector<Eigen::Vector3d> face_n;       // unit outward face normals
  std::vector<Eigen::Vector3d> vertex_n;     // angle-weighted pseudo-normals (Bærentzen & Aanæs)
  std::unordered_map<std::uint64_t, Eigen::Vector3d> edge_n;  // sum of the two face normals
  std::shared_ptr<fcl::BVHModel<fcl::OBBRSSd>> bvh;
  std::shared_ptr<fcl::Sphered> point;       // radius 0: the query point
  Eigen::Vector3d lo, hi;
  double area = 0;

  // Nearest triangle without FCL (only when FCL names none, e.g. p exactly on the surface).
  int brute_nearest(const Eigen::Vector3d& p) const {
    double best = std::numeric_limits<double>::max();
    int k = 0;
    for (int i = 0; i < int(t.size()); ++i) {
      int f;
      const double d = (closest_on_triangle(p, v[t[i][0]], v[t[i][1]], v[t[i][2]], &f) - p).squaredNorm();
      if (d < best) best = d, k = i;
    }
    return k;
  }
};

MeshSdf::MeshSdf() : impl_(std::make_unique<Impl>()) {}
MeshSdf::MeshSdf(MeshSdf&&) noexcept = default;
MeshSdf& MeshSdf::operator=(MeshSdf&&) noexcept = default;
MeshSdf::~MeshSdf() = default;

Result<MeshSdf> MeshSdf::create(const std::vector<Eigen::Vector3f>& vertices,
                                const std::vector<std::array<int, 3>>& triangles, const std::string& file,
                                const std::string& field) {
  TriangleMesh m;
  m.vertices = vertices;
  m.triangles = triangles;
  // Non-finite vertices, bad indices, degenerate triangles, open / non-manifold / misoriented
  // edges, inside-out winding: inside and outside would be undefined.
  if (auto errs = check_solid_mesh(m, file, field); !errs.empty()) return errs;

  MeshSdf sdf;
  Impl& I = *sdf.impl_;
  for (const auto& p : vertices) I.v.push_back(p.cast<double>());
  I.t = triangles;
  I.vertex_n.assign(I.v.size(), Eigen::Vector3d::Zero());
  I.lo = I.hi = I.v.front();
  for (const auto& p : I.v) I.lo = I.lo.cwiseMin(p), I.hi = I.hi.cwiseMax(p);
  for (const auto& tri : I.t) {
    const Eigen::Vector3d& a = I.v[tri[0]];
    const Eigen::Vector3d& b = I.v[tri[1]];
    const Eigen::Vector3d& c = I.v[tri[2]];
    const Eigen::Vector3d n2 = (b - a).cross(c - a);
    I.area += 0.5 * n2.norm();
    const Eigen::Vector3d n = n2.normalized();
    I.face_n.push_back(n);
    for (int k = 0; k < 3; ++k) {
      // Pseudo-normal weights: the triangle's angle at each vertex; each edge gets both faces.
      const Eigen::Vector3d& p = I.v[tri[k]];
      const Eigen::Vector3d e1 = (I.v[tri[(k + 1) % 3]] - p).normalized(), e2 = (I.v[tri[(k + 2) % 3]] - p).normalized();
      I.vertex_n[tri[k]] += std::acos(std::clamp(e1.dot(e2), -1.0, 1.0)) * n;
      // (Eigen vectors are not zeroed by operator[]'s value-initialisation.)
      I.edge_n.try_emplace(edge_key(tri[k], tri[(k + 1) % 3]), Eigen::Vector3d::Zero()).first->second += n;
    }
  }
  // The BVH FCL searches (OBBRSS: tight for distance queries).
  I.bvh = std::make_shared<fcl::BVHModel<fcl::OBBRSSd>>();
  I.bvh->beginModel(int(I.t.size()), int(I.v.size()));
  std::vector<fcl::Vector3d> pts(I.v.begin(), I.v.end());
  std::vector<fcl::Triangle> tris;
  for (const auto& tri : I.t) tris.emplace_back(tri[0], tri[1], tri[2]);
  I.bvh->addSubModel(pts, tris);
  I.bvh->endModel();
  I.point = std::make_shared<fcl::Sphered>(0.0);
  return sdf;
}

MeshSdf::Query MeshSdf::query(const Eigen::Vector3d& p) const {
  const Impl& I = *impl_;
  fcl::DistanceRequestd request;
  fcl::DistanceResultd result;
  fcl::Transform3d at = fcl::Transform3d::Identity();
  at.translation() = p;
  fcl::distance(I.bvh.get(), fcl::Transform3d::Identity(), I.point.get(), at, request, result);
  int k = int(result.b1);
  if (k < 0 || k >= int(I.t.size())) k = I.brute_nearest(p);
  // The closest point and its feature on FCL's nearest triangle, exactly.
  const auto& tri = I.t[k];
  int feature = 0;
  Query q;
  q.triangle = k;
  q.closest = closest_on_triangle(p, I.v[tri[0]], I.v[tri[1]], I.v[tri[2]], &feature);
  Eigen::Vector3d n;
  if (feature == 0) n = I.face_n[k];
  else if (feature <= 3) n = I.vertex_n[tri[feature - 1]];
  else n = I.edge_n.at(edge_key(tri[feature - 4], tri[(feature - 3) % 3]));
  const Eigen::Vector3d d = p - q.closest;
  const double len = d.norm();
  const double scale = (I.hi - I.lo).norm();
  if (len <= 1e-12 * scale) {  // on the surface
    q.distance = 0;
    q.outward = n.normalized();
    return q;
  }
  const bool outside = d.dot(n) >= 0;
  q.distance = outside ? len : -len;
  q.outward = (outside ? d : Eigen::Vector3d(-d)) / len;
  return q;
}

Eigen::Vector3d MeshSdf::bounds_min() const { return impl_->lo; }
Eigen::Vector3d MeshSdf::bounds_max() const { return impl_->hi; }
double MeshSdf::area() const { return impl_->area; }
int MeshSdf::triangle_count() const { return int(impl_->t.size()); }
std::array<Eigen::Vector3d, 3> MeshSdf::triangle(int k) const {
  const auto& t = impl_->t[k];
  return {impl_->v[t[0]], impl_->v[t[1]], impl_->v[t[2]]};
}

Result<std::vector<Eigen::Vector3f>> sample_mesh_shell(const MeshSdf& sdf, float spacing, float inset, int max_points,
                                                       MeshShellStats* stats) {
  if (!(spacing > 0) || !std::isfinite(spacing))
    return Error{"", "shell spacing", std::to_string(spacing), "must be finite and > 0 (m)"};
  if (!(inset >= 0) || !std::isfinite(inset))
    return Error{"", "shell inset", std::to_string(inset), "must be finite and >= 0 (m)"};
  auto too_many = [&](double n) {
    return Error{"", "simulation.pool.shell_spheres_per_slot", std::to_string(max_points),
                 "too small for a body shell of " + std::to_string((long long)std::llround(n)) + " spheres at spacing " +
                     std::to_string(spacing) + " m; raise it or use a coarser granule size"};
  };
  // A hexagonal layer of spacing s holds area / (s² √3/2) spheres; refuse before the grid is
  // built when even that is far over the capacity.
  const double estimate = sdf.area() / (double(spacing) * spacing * 0.8660254);
  if (estimate > 4.0 * max_points) return too_many(estimate);

  // The SDF grid: spacing h = spacing / 2 over the bounds padded by inset + 2 h.
  const double h = 0.5 * spacing;
  const Eigen::Vector3d pad = Eigen::Vector3d::Constant(inset + 2 * h);
  const Eigen::Vector3d lo = sdf.bounds_min() - pad, hi = sdf.bounds_max() + pad;
  const Eigen::Array3d ext = ((hi - lo) / h).array().ceil() + 1;
  const double nodes = ext.prod();
  if (nodes > double(1 << 26))
    return Error{"", "shell spacing", std::to_string(spacing),
                 "gives an SDF grid of " + std::to_string((long long)nodes) + " nodes (more than 2^26) for this mesh"};
  const int nx = int(ext.x()), ny = int(ext.y()), nz = int(ext.z());
  auto node = [&](int i, int j, int k) -> Eigen::Vector3d { return lo + h * Eigen::Vector3d(i, j, k); };

  // Only nodes at a distance in [inset − band, inset + band] from some triangle can lie in
  // the band (band = half a cell diagonal): mark them from each triangle's padded bounds with
  // an exact point-triangle distance (cheap), so that FCL is asked about those nodes only.
  const double band = 0.5 * std::sqrt(3.0) * h + 1e-9 * h;
  std::vector<std::uint8_t> near(std::size_t(nx) * ny * nz, 0);
  const double reach = inset + band;
  const double inner2 = std::max(0.0, inset - band) * std::max(0.0, inset - band), outer2 = reach * reach;
  MeshShellStats st;
  st.grid_nodes = (long long)near.size();
  st.grid_spacing = h;
  for (int t = 0; t < sdf.triangle_count(); ++t) {
    const auto c = sdf.triangle(t);
    const Eigen::Vector3d tlo = c[0].cwiseMin(c[1]).cwiseMin(c[2]).array() - reach;
    const Eigen::Vector3d thi = c[0].cwiseMax(c[1]).cwiseMax(c[2]).array() + reach;
    const Eigen::Array3i a = ((tlo - lo) / h).array().ceil().cast<int>().max(0);
    const Eigen::Array3i b = ((thi - lo) / h).array().floor().cast<int>().min(Eigen::Array3i(nx - 1, ny - 1, nz - 1));
    for (int k = a.z(); k <= b.z(); ++k)
      for (int j = a.y(); j <= b.y(); ++j)
        for (int i = a.x(); i <= b.x(); ++i) {
          std::uint8_t& m = near[(std::size_t(k) * ny + j) * nx + i];
          if (m) continue;
          int f;
          const Eigen::Vector3d p = node(i, j, k);
          const double d2 = (closest_on_triangle(p, c[0], c[1], c[2], &f) - p).squaredNorm();
          m = d2 >= inner2 && d2 <= outer2;
        }
  }
  std::vector<std::size_t> todo;
  for (std::size_t n = 0; n < near.size(); ++n)
    if (near[n]) todo.push_back(n);
  st.queried = (long long)todo.size();

  // One FCL query per marked node; nodes within half a cell diagonal of the offset surface
  // sdf = −inset are moved onto it by Newton steps x ← x − (sdf(x) + inset) ∇sdf(x), with
  // ∇sdf = the outward direction of the query (exact in one step next to a face, one step per
  // face at creases and corners). Where that does not converge the body is thinner than
  // 2 inset: the centre goes to the deepest point on the inward normal of the node's nearest
  // point c, found by bisection of "depth t is real": −sdf(c − t u) ≥ t.
  // Nodes are independent: any thread count gives the same points.
  struct Candidate {
    bool band = false, thin = false;
    int steps = 0;  // Newton steps taken: 1 next to a face, more at creases and corners
    Eigen::Vector3d p;
  };
  std::vector<Candidate> cand(todo.size());
  const double tol = 1e-4 * h;
#pragma omp parallel for schedule(dynamic, 64)
  for (long long q = 0; q < (long long)todo.size(); ++q) {
    const std::size_t n = todo[q];
    const int i = int(n % nx), j = int((n / nx) % ny), k = int(n / (std::size_t(nx) * ny));
    const MeshSdf::Query r0 = sdf.query(node(i, j, k));
    if (std::abs(r0.distance + inset) > band) continue;
    Candidate& c = cand[q];
    c.band = true;
    c.p = node(i, j, k);
    MeshSdf::Query r = r0;
    bool converged = false;
    for (int it = 0; it < 12 && !converged; ++it) {
      const double e = r.distance + inset;
      if (std::abs(e) <= tol) converged = true;
      else c.p -= e * r.outward, r = sdf.query(c.p), ++c.steps;
    }
    if (converged) continue;
    double a = 0, b = inset;
    for (int it = 0; it < 30; ++it) {
      const double m = 0.5 * (a + b);
      (-sdf.signed_distance(r0.closest - m * r0.outward) >= m - tol ? a : b) = m;
    }
    c.p = r0.closest - a * r0.outward;
    c.thin = true;
  }

  // Centres closer than kGap spacing to an earlier one are dropped (grid order: deterministic);
  // a uniform hash of cells of size kGap spacing finds the earlier ones.
  constexpr double kGap = 0.75;  // × spacing (on a flat face: every other node of the h = spacing / 2 grid)
  const double gap = kGap * spacing;
  struct CellHash {
    std::size_t operator()(const Eigen::Vector3i& c) const {
      return std::size_t(c.x()) * 73856093u ^ std::size_t(c.y()) * 19349663u ^ std::size_t(c.z()) * 83492791u;
    }
  };
  struct CellEq {
    bool operator()(const Eigen::Vector3i& a, const Eigen::Vector3i& b) const { return a == b; }
  };
  std::unordered_map<Eigen::Vector3i, std::vector<int>, CellHash, CellEq> cells;
  std::vector<Eigen::Vector3d> out;
  auto cell_of = [&](const Eigen::Vector3d& p) { return Eigen::Vector3i(((p - lo) / gap).array().floor().cast<int>()); };
  auto crowded = [&](const Eigen::Vector3d& p) {
    const Eigen::Vector3i c = cell_of(p);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          auto it = cells.find(c + Eigen::Vector3i(dx, dy, dz));
          if (it == cells.end()) continue;
          for (int o : it->second)
            if ((out[o] - p).squaredNorm() < gap * gap) return true;
        }
    return false;
  };
  // Creases and corners first (most Newton steps), so that the offset surface's sharp
  // features get a centre before the faces next to them crowd them out; then grid order.
  std::vector<int> order;
  for (int q = 0; q < int(cand.size()); ++q)
    if (cand[q].band) order.push_back(q);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return std::min(cand[a].steps, 3) > std::min(cand[b].steps, 3); });
  for (int q : order) {
    const Candidate& c = cand[q];
    if (crowded(c.p)) continue;
    st.thin += c.thin;
    cells[cell_of(c.p)].push_back(int(out.size()));
    out.push_back(c.p);
  }
  for (const Candidate& c : cand) st.band += c.band;
  if (stats) *stats = st;
  if (int(out.size()) > max_points) return too_many(double(out.size()));
  std::vector<Eigen::Vector3f> pts;
  pts.reserve(out.size());
  for (const auto& p : out) pts.push_back(p.cast<float>());
  return pts;
}

}  // namespace sandpatch
