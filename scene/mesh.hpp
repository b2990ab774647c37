// Triangle meshes for bodies: OBJ loading (tinyobjloader), closedness, volume, centroid.
//
// A solid body needs a closed, consistently oriented surface: every undirected edge is
// shared by exactly two triangles that traverse it in opposite directions. The volume and
// centroid come from the divergence theorem (sum of signed tetrahedra from the origin),
// which is exact for such a surface and positive when the faces wind counter-clockwise
// seen from outside (the OBJ convention).
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/error.hpp"

namespace sandpatch {

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;       // m, mesh frame (scale already applied)
  std::vector<std::array<int, 3>> triangles;   // vertex indices, counter-clockwise seen from outside

  // Signed volume (m³) by the divergence theorem: sum over triangles of a·(b×c)/6.
  // Positive for a closed outward-wound surface; meaningless for an open one.
  double signed_volume() const;
  // Centroid of the enclosed solid (m, mesh frame), assuming uniform density.
  // Falls back to the vertex mean when the volume is zero.
  Eigen::Vector3d centroid() const;
  // Inertia tensor about the centroid (kg m², mesh axes) of the enclosed solid with uniform
  // density and total mass `mass` (kg): from the second moments ∫ x xᵀ dV of the signed
  // tetrahedra (0, a, b, c) (Tonon 2004: each is det[a b c] · A C Aᵀ with C = (1 + δ_ij)/120),
  // moved to the centroid, then I = tr(C) Id − C. Exact for a closed outward-wound surface.
  Eigen::Matrix3d inertia(double mass) const;
  // Axis-aligned bounds of the vertices (m, mesh frame). Both zero for an empty mesh.
  Eigen::Vector3f bounds_min() const;
  Eigen::Vector3f bounds_max() const;
};

// Edge statistics of a triangle mesh (edges keyed by vertex index).
struct MeshTopology {
  std::size_t edges = 0;               // distinct undirected edges
  std::size_t open_edges = 0;          // used by exactly one triangle (a hole's rim)
  std::size_t non_manifold_edges = 0;  // used by three or more triangles
  std::size_t misoriented_edges = 0;   // used twice in the same direction (flipped neighbour)
  bool closed() const { return open_edges == 0 && non_manifold_edges == 0 && misoriented_edges == 0; }
};
MeshTopology mesh_topology(const TriangleMesh& mesh);

// Loads an OBJ file: polygons are triangulated, vertices with bit-identical positions are
// welded (so per-face duplicates do not open the surface), degenerate triangles (two equal
// indices after welding) are dropped, and positions are multiplied by `scale` (> 0).
// Errors: missing/unreadable file, OBJ syntax, no triangles, non-finite coordinates.
// Does not require the mesh to be closed; use check_solid_mesh for that.
Result<TriangleMesh> load_obj_mesh(const std::string& path, double scale = 1.0);

// Errors when `mesh` cannot bound a solid: no triangles, a non-finite vertex, an index out of
// range, a degenerate triangle (area below 1e-12 of the squared bounding-box diagonal: first
// one named, with the count), open, non-manifold or misoriented edges (each reported with its
// count), or a non-positive signed volume (inside-out winding).
// `file` and `field` go into the errors as they are.
std::vector<Error> check_solid_mesh(const TriangleMesh& mesh, const std::string& file,
                                    const std::string& field);

}  // namespace sandpatch
