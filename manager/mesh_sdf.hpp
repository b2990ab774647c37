// Signed distance to a closed triangle mesh, and body shells sampled from it (Leach & Marais
// §2.2: "a signed distance field is created for each model; particles are created at each
// negative value adjacent to a positive one").
//
// Distance: FCL distance queries (fcl::distance between a radius-0 sphere at the query point
// and an OBBRSS BVH of the mesh, double precision) give the nearest triangle; the closest point
// and the Voronoi feature of that triangle it lies on (face, edge or vertex) are then computed
// exactly (Ericson, Real-Time Collision Detection §5.1.5).
//
// Sign: the angle-weighted pseudo-normal of that feature (Bærentzen & Aanæs 2005): for a
// closed, consistently oriented mesh, (p − c)·N ≥ 0 exactly when p is outside, with N the face
// normal, the sum of the two face normals of an edge, or the angle-weighted sum of the face
// normals around a vertex. Chosen over ray parity because it costs nothing beyond the FCL
// query that is made anyway (ray parity needs a second O(triangles) ray cast per point), and
// because parity breaks when a ray grazes an edge or a vertex, which axis-aligned grid rays do
// on axis-aligned meshes such as boxes. Both need a closed mesh; MeshSdf::create refuses others.
//
// Shell (sample_mesh_shell): sphere centres on the offset surface sdf = −inset, so that shell
// spheres of radius `inset` touch the mesh from inside and the granules meet the body at its
// true surface. Leach puts particles on SDF grid nodes just inside the surface, i.e. at depths
// 0 … one grid cell, which makes a staircase; here the nodes of the narrow band around the
// offset surface (grid spacing h = spacing / 2) are moved onto it by Newton steps on the SDF,
// then centres closer than 0.75 spacing to an earlier one are dropped (creases and corners
// first, then z, y, x node order: deterministic). Where the body is thinner than 2 inset, the
// centre goes to the deepest point on the inward normal (half the local thickness) instead.
// docs/manager.md "Mesh shells" has the measurements.
#pragma once

#include <Eigen/Core>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "common/error.hpp"

namespace sandpatch {

class MeshSdf {
 public:
  // Errors (each naming `file` and `field`): no triangles, a non-finite vertex, an index out of
  // range, a degenerate triangle (area below 1e-12 of the bounding box diagonal squared), an
  // open, non-manifold or misoriented edge, a non-positive volume (inside out).
  static Result<MeshSdf> create(const std::vector<Eigen::Vector3f>& vertices,
                                const std::vector<std::array<int, 3>>& triangles, const std::string& file = "",
                                const std::string& field = "shape.mesh");
  MeshSdf(MeshSdf&&) noexcept;
  MeshSdf& operator=(MeshSdf&&) noexcept;
  ~MeshSdf();

  struct Query {
    double distance = 0;                         // m, signed: < 0 inside
    Eigen::Vector3d closest = Eigen::Vector3d::Zero();  // m, nearest point on the mesh
    Eigen::Vector3d outward = Eigen::Vector3d::Zero();  // unit: from the surface towards outside along p − closest
                                                        // (the feature's pseudo-normal when p is on the surface)
    int triangle = -1;                           // nearest triangle
  };
  // One FCL distance query (mesh frame, m).
  Query query(const Eigen::Vector3d& p) const;
  double signed_distance(const Eigen::Vector3d& p) const { return query(p).distance; }

  Eigen::Vector3d bounds_min() const;  // m, of the vertices
  Eigen::Vector3d bounds_max() const;
  double area() const;                 // m², of the surface
  int triangle_count() const;
  std::array<Eigen::Vector3d, 3> triangle(int k) const;  // m, corners of triangle k

 private:
  MeshSdf();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// What sample_mesh_shell did (for tests and reports).
struct MeshShellStats {
  long long grid_nodes = 0;    // nodes of the SDF grid over the padded bounds
  long long queried = 0;       // nodes near a triangle, given an FCL distance query
  long long band = 0;          // nodes within half a cell diagonal of the offset surface
  int thin = 0;                // centres moved to half the local thickness (body thinner than 2 inset)
  double grid_spacing = 0;     // m
};

// Sphere centres (mesh frame, m) on the offset surface sdf = −inset, at least 0.75 spacing
// apart and about `spacing` apart on flat faces (SDF grid spacing spacing / 2). inset in [0, ∞); 0 puts the centres on the surface.
// Errors when spacing is not finite and > 0, or when the shell would exceed max_points
// (naming pool.shell_particles_per_slot, the capacity to raise).
Result<std::vector<Eigen::Vector3f>> sample_mesh_shell(const MeshSdf& sdf, float spacing, float inset, int max_points,
                                                       MeshShellStats* stats = nullptr);

}  // namespace sandpatch
