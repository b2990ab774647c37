// Triangle meshes for bodies: see mesh.hpp.
#include "scene/mesh.hpp"

#include "common/limits.hpp"

#include <Eigen/Geometry>
#include <tiny_obj_loader.h>

#include <cassert>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <unordered_map>

namespace sandpatch {

double TriangleMesh::signed_volume() const {
  // Divergence theorem: V = Σ a·(b×c) / 6 over outward triangles (a, b, c).
  double v6 = 0.0;
  for (const auto& t : triangles) {
    const Eigen::Vector3d a = vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = vertices[t[2]].cast<double>();
    v6 += a.dot(b.cross(c));
  }
  return v6 / 6.0;
}

Eigen::Vector3d TriangleMesh::centroid() const {
  // Each signed tetrahedron (0, a, b, c) has volume a·(b×c)/6 and centroid (a+b+c)/4.
  double v6 = 0.0;
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& t : triangles) {
    const Eigen::Vector3d a = vertices[t[0]].cast<double>();
    const Eigen::Vector3d b = vertices[t[1]].cast<double>();
    const Eigen::Vector3d c = vertices[t[2]].cast<double>();
    const double w = a.dot(b.cross(c));
    v6 += w;
    m += w * (a + b + c) / 4.0;
  }
  if (std::abs(v6) > 0.0) return m / v6;
  // Degenerate (flat or empty): the mean of the vertices.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& v : vertices) mean += v.cast<double>();
  return vertices.empty() ? mean : Eigen::Vector3d(mean / static_cast<double>(vertices.size()));
}

Eigen::Matrix3d TriangleMesh::inertia(double mass) const {
  // Second moments about the origin, C = Σ det(A) A K Aᵀ with A = [a b c] (columns) and
  // K = (1 + δ_ij) / 120 the canonical tetrahedron's (Tonon 2004), volume Σ det(A) / 6.
  Eigen::Matrix3d K = Eigen::Matrix3d::Constant(1.0 / 120.0);
  K.diagonal().setConstant(2.0 / 120.0);
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  double v6 = 0.0;
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& t : triangles) {
    Eigen::Matrix3d A;
    A.col(0) = vertices[t[0]].cast<double>();
    A.col(1) = vertices[t[1]].cast<double>();
    A.col(2) = vertices[t[2]].cast<double>();
    const double det = A.determinant();
    C += det * A * K * A.transpose();
    v6 += det;
    m += det * A.rowwise().sum() / 4.0;
  }
  if (!(std::abs(v6) > 0.0)) return Eigen::Matrix3d::Zero();
  const double volume = v6 / 6.0;
  const Eigen::Vector3d c = m / v6;
  C -= volume * c * c.transpose();  // parallel axis: about the centroid
  const Eigen::Matrix3d I = C.trace() * Eigen::Matrix3d::Identity() - C;
  return (mass / volume) * I;
}

Eigen::Vector3f TriangleMesh::bounds_min() const {
  if (vertices.empty()) return Eigen::Vector3f::Zero();
  Eigen::Vector3f lo = vertices.front();
  for (const auto& v : vertices) lo = lo.cwiseMin(v);
  return lo;
}

Eigen::Vector3f TriangleMesh::bounds_max() const {
  if (vertices.empty()) return Eigen::Vector3f::Zero();
  Eigen::Vector3f hi = vertices.front();
  for (const auto& v : vertices) hi = hi.cwiseMax(v);
  return hi;
}

MeshTopology mesh_topology(const TriangleMesh& mesh) {
  // Count each directed edge; an undirected edge {a, b} of a closed oriented surface is
  // traversed exactly once as a→b and once as b→a.
  std::map<std::pair<int, int>, std::array<int, 2>> uses;  // (min, max) → {min→max, max→min}
  for (const auto& t : mesh.triangles) {
    for (int k = 0; k < 3; ++k) {
      const int a = t[k], b = t[(k + 1) % 3];
      auto& u = uses[{std::min(a, b), std::max(a, b)}];
      ++u[a < b ? 0 : 1];
    }
  }
  MeshTopology topo;
  topo.edges = uses.size();
  for (const auto& [edge, u] : uses) {
    const int total = u[0] + u[1];
    if (total == 1) ++topo.open_edges;
    else if (total > 2) ++topo.non_manifold_edges;
    else if (u[0] != 1) ++topo.misoriented_edges;  // total == 2, both the same direction
  }
  return topo;
}

Result<TriangleMesh> load_obj_mesh(const std::string& path, double scale) {
  assert(scale > 0.0 && std::isfinite(scale));
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(path, ec)) return Error{path, "", "", "", "file not found"};
  if (!fs::is_regular_file(path, ec)) return Error{path, "", "", "", "not a regular file"};
  if (!std::ifstream(path).good()) return Error{path, "", "", "", "file cannot be opened for reading"};

  // The file is read whole by tinyobj: its size, then a pass over the text that refuses what
  // tinyobj would silently read as 0 (a coordinate "nan", "inf" or not a number) and counts
  // the faces (common/limits.hpp) before anything is built from it.
  {
    const auto size = fs::file_size(path, ec);
    if (ec) return Error{path, "", "", "", "cannot read the file size: " + ec.message()};
    if (size > limits::kMaxMeshFileBytes)
      return Error{path, "", std::to_string(size) + " bytes",
                   "an OBJ file of at most " + std::to_string(limits::kMaxMeshFileBytes) + " bytes",
                   "simplify the mesh (fewer vertices and faces)"};
    std::ifstream in(path, std::ios::binary);
    std::string line;
    std::uint64_t faces = 0;
    for (std::size_t n = 1; std::getline(in, line); ++n) {
      std::size_t b = line.find_first_not_of(" \t");
      if (b == std::string::npos) continue;
      if (line.compare(b, 2, "f ") == 0 || line.compare(b, 2, "f\t") == 0) {
        // A polygon of k corners becomes k − 2 triangles.
        std::istringstream words(line.substr(b + 1));
        std::string w;
        std::uint64_t corners = 0;
        while (words >> w) ++corners;
        faces += corners > 2 ? corners - 2 : 1;
        if (faces > limits::kMaxMeshTriangles)
          return Error{path, "line " + std::to_string(n), "more than " + std::to_string(limits::kMaxMeshTriangles) + " triangles",
                       "a mesh of at most " + std::to_string(limits::kMaxMeshTriangles) + " triangles",
                       "simplify the mesh (fewer faces)"};
        continue;
      }
      if (!(line.compare(b, 2, "v ") == 0 || line.compare(b, 2, "v\t") == 0)) continue;
      std::istringstream words(line.substr(b + 1));
      std::string w;
      for (int k = 0; k < 3; ++k) {
        const bool got = static_cast<bool>(words >> w);
        char* end = nullptr;
        const double x = got ? std::strtod(w.c_str(), &end) : 0.0;
        if (!got || end != w.c_str() + w.size() || !std::isfinite(x))
          return Error{path, "line " + std::to_string(n), got ? w.substr(0, 40) : "(missing)",
                       "three finite vertex coordinates (a vertex line is \"v x y z\")",
                       got ? "coordinate " + std::to_string(k + 1) + " is not a finite number" : "the vertex has fewer than 3 coordinates"};
        if (!(std::abs(x * scale) <= 1e9))
          return Error{path, "line " + std::to_string(n), w.substr(0, 40),
                       "vertex coordinates × scale within ±1e9 m",
                       "coordinate " + std::to_string(k + 1) + " × scale = " + std::to_string(x * scale) + " m"};
      }
    }
  }

  tinyobj::attrib_t attrib;
  std::vector<tinyobj::shape_t> shapes;
  std::vector<tinyobj::material_t> materials;
  std::string warn, err;
  // No .mtl search: materials are irrelevant to a body's shape.
  const std::string mtl_dir = fs::path(path).parent_path().string() + "/";
  const bool ok = tinyobj::LoadObj(&attrib, &shapes, &materials, &warn, &err, path.c_str(),
                                   mtl_dir.c_str(), /*triangulate=*/true);
  if (!ok) return Error{path, "", "", "a Wavefront OBJ file", "OBJ parse failed: " + err};

  // Weld bit-identical positions so that duplicated vertices do not open the surface.
  TriangleMesh mesh;
  const std::size_t nv = attrib.vertices.size() / 3;
  std::vector<int> remap(nv, -1);
  std::map<std::array<float, 3>, int> welded;
  for (std::size_t i = 0; i < nv; ++i) {
    const std::array<float, 3> p{attrib.vertices[3 * i], attrib.vertices[3 * i + 1],
                                 attrib.vertices[3 * i + 2]};
    if (!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2])) {
      return Error{path, "", "v " + std::to_string(i + 1), "finite vertex coordinates",
                   "vertex " + std::to_string(i + 1) + " is NaN or infinite"};
    }
    auto [it, inserted] = welded.emplace(p, static_cast<int>(mesh.vertices.size()));
    if (inserted) {
      mesh.vertices.emplace_back(static_cast<float>(p[0] * scale), static_cast<float>(p[1] * scale),
                                 static_cast<float>(p[2] * scale));
    }
    remap[i] = it->second;
  }

  for (const auto& shape : shapes) {
    std::size_t offset = 0;
    for (const auto fv : shape.mesh.num_face_vertices) {
      if (fv != 3) {  // triangulation leaves only triangles; anything else is malformed
        return Error{path, "", "", "faces with at least 3 vertices",
                     "face with " + std::to_string(fv) + " vertices in shape '" + shape.name + "'"};
      }
      std::array<int, 3> t{};
      for (int k = 0; k < 3; ++k) {
        const int vi = shape.mesh.indices[offset + k].vertex_index;
        if (vi < 0 || static_cast<std::size_t>(vi) >= nv) {
          return Error{path, "", std::to_string(vi + 1), "vertex indices within the file",
                       "face refers to a vertex that does not exist"};
        }
        t[k] = remap[vi];
      }
      offset += 3;
      if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) continue;  // degenerate after welding
      mesh.triangles.push_back(t);
    }
  }
  if (mesh.triangles.empty()) return Error{path, "", "", "at least one triangle", "the OBJ has no faces"};
  const Eigen::Vector3f extent = mesh.bounds_max() - mesh.bounds_min();
  if (!(extent.allFinite() && extent.maxCoeff() <= limits::kMaxMeshExtent)) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%.6g x %.6g x %.6g m", double(extent.x()), double(extent.y()), double(extent.z()));
    return Error{path, "", buf, "a mesh at most 20000 m across on every axis (after scale)", "lower the scale"};
  }
  return mesh;
}

std::vector<Error> check_solid_mesh(const TriangleMesh& mesh, const std::string& file,
                                    const std::string& field) {
  std::vector<Error> errors;
  if (mesh.triangles.empty()) {
    errors.push_back({file, field, "0 triangles", "at least one triangle"});
    return errors;
  }
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    if (!mesh.vertices[i].allFinite()) {
      errors.push_back({file, field, "vertex " + std::to_string(i + 1), "finite vertex coordinates",
                        "vertex " + std::to_string(i + 1) + " is NaN or infinite"});
      return errors;
    }
  }
  for (std::size_t k = 0; k < mesh.triangles.size(); ++k) {
    for (int i : mesh.triangles[k]) {
      if (i < 0 || std::size_t(i) >= mesh.vertices.size()) {
        errors.push_back({file, field, "triangle " + std::to_string(k + 1) + " index " + std::to_string(i),
                          "vertex indices in [0, " + std::to_string(mesh.vertices.size()) + ")"});
        return errors;
      }
    }
  }
  // Degenerate triangles (collinear or coincident corners) have no normal: inside and outside
  // are undefined next to them.
  const double diag2 = (mesh.bounds_max() - mesh.bounds_min()).cast<double>().squaredNorm();
  std::size_t degenerate = 0, first = 0;
  for (std::size_t k = 0; k < mesh.triangles.size(); ++k) {
    const auto& t = mesh.triangles[k];
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    if (!(0.5 * (b - a).cross(c - a).norm() > 1e-12 * diag2)) {
      if (degenerate++ == 0) first = k;
    }
  }
  if (degenerate > 0) {
    errors.push_back({file, field, "triangle " + std::to_string(first + 1),
                      "triangles with a non-zero area (three distinct, non-collinear corners)",
                      std::to_string(degenerate) + " degenerate triangle(s); the first is triangle " +
                          std::to_string(first + 1) + " (1-based, in file order after dropping repeated indices)"});
  }
  const MeshTopology topo = mesh_topology(mesh);
  const std::string rule = "a closed mesh (every edge shared by exactly two triangles, consistently oriented)";
  if (topo.open_edges > 0) {
    errors.push_back({file, field, "", rule,
                      "mesh is not closed: " + std::to_string(topo.open_edges) + " open edges of " +
                          std::to_string(topo.edges)});
  }
  if (topo.non_manifold_edges > 0) {
    errors.push_back({file, field, "", rule,
                      "mesh is not manifold: " + std::to_string(topo.non_manifold_edges) +
                          " edges shared by three or more triangles"});
  }
  if (topo.misoriented_edges > 0) {
    errors.push_back({file, field, "", rule,
                      "mesh is not consistently oriented: " + std::to_string(topo.misoriented_edges) +
                          " edges traversed twice in the same direction"});
  }
  if (errors.empty()) {
    const double v = mesh.signed_volume();
    if (!(v > 0.0)) {
      char buf[64];
      std::snprintf(buf, sizeof buf, "%.6g", v);
      errors.push_back({file, field, "", "faces wound counter-clockwise seen from outside (positive volume)",
                        std::string("signed volume is ") + buf + " m^3: the mesh is inside out or flat"});
    }
  }
  return errors;
}

}  // namespace sandpatch
