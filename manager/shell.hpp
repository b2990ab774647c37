// Body shells (Leach & Marais §2.2; Longmore et al. 2013): a body inside a granular patch is
// represented by spheres on its surface, all moving as one rigid body. Shell spacing follows
// the patch's granule size: neighbouring shell spheres are about `spacing` apart, so granule
// spheres (radius r) cannot pass between them when spacing <= 2 r.
//
// Sampling, per shape (body frame, centred on the centre of mass, axis of cylinders and
// capsules along y as in bullet_world.hpp):
//   sphere   Fibonacci lattice: N = ceil(4π R² / (spacing² · √3/2)) points (hexagonal density)
//   box      a regular grid on each face, edges and corners included once
//   cylinder rings on the side (Δy ≈ spacing, Δθ ≈ spacing/R) + concentric rings on both caps
//   capsule  rings on the side + Fibonacci hemispheres on the caps
//   mesh     from the mesh's signed distance field (FCL distance queries, manager/mesh_sdf.hpp):
//            centres on the offset surface sdf = −sphere_radius, so the shell spheres touch the
//            mesh from inside (Leach §2.2 puts them on the SDF grid nodes just inside the
//            surface), about `spacing` apart
// Primitive points lie on the surface (to float round-off): tests/manager/shell_test.cpp;
// mesh points at sphere_radius below it: tests/manager/mesh_sdf_test.cpp.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "common/error.hpp"
#include "manager/bullet_world.hpp"

namespace sandpatch {

// Points on the surface of `shape` about `spacing` m apart (body frame, m); for meshes, at
// `sphere_radius` (m, the shell spheres' radius) inside it. Errors when spacing is not > 0, the
// shell would exceed max_points (the capacity to raise is named), or a mesh is not a closed,
// outward-wound surface without degenerate triangles (field "shape.mesh").
Result<std::vector<Eigen::Vector3f>> sample_shell(const RigidShape& shape, float spacing, float sphere_radius,
                                                  int max_points);

}  // namespace sandpatch
