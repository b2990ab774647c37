// Rigid bodies as the renderer sees them: a shape and a pose, filled by whoever owns the frame
// (manager/run_outputs.cpp fills them from World and BulletWorld). Pure: tessellation into
// triangles with normals, no GL (render/body_renderer.hpp draws them).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <array>
#include <string>
#include <vector>

#include "common/error.hpp"

namespace sandpatch::render {

enum class BodyShapeKind { Sphere, Box, Cylinder, Capsule, Mesh };

// One body to draw. Shapes are centred on the body frame's origin; cylinders and capsules
// have their axis on the body's y (the scene format's and Bullet's convention).
struct BodyInstance {
  BodyShapeKind kind = BodyShapeKind::Sphere;
  float radius = 0.5f;                                              // m (sphere, cylinder, capsule)
  float height = 1.0f;                                              // m, along y (cylinder; capsule: the straight part)
  Eigen::Vector3f half_extents = Eigen::Vector3f::Constant(0.5f);  // m (box)
  std::vector<Eigen::Vector3f> vertices;                            // m, body frame (mesh)
  std::vector<std::array<int, 3>> triangles;                        // indices into vertices (mesh)
  Eigen::Vector3d position = Eigen::Vector3d::Zero();               // m, world: the body frame's origin
  Eigen::Quaternionf orientation = Eigen::Quaternionf::Identity();  // body -> world
  Eigen::Vector3f albedo{0.6f, 0.6f, 0.6f};                         // linear RGB in [0, 1]
  // Tessellation (spheres, capsules, cylinders): segments around, 0 = the renderer's 32; else
  // in [4, 64] (a debug overlay of many small spheres takes 8).
  int segments = 0;
};

// Checks one body; errors name the field ("bodies[1].radius = -1: must be > 0 and finite (m)").
Status validate(const BodyInstance& b, int index);

// A default albedo for the k-th body (a small palette that no sand, gravel, soil or grass
// shade is close to: red, blue, wood, teal, ...).
Eigen::Vector3f body_palette(int k);

// One vertex of a tessellated body: position local to the heightfield origin (m, float) and
// unit normal (world axes).
struct BodyVertex {
  Eigen::Vector3f position;
  Eigen::Vector3f normal;
};

// Appends the body's triangles (three vertices each) to `out`, posed and moved into the frame
// whose origin is `world_origin` (m, world): sphere and capsule caps as latitude-longitude
// grids (`segments` around, segments / 2 from pole to pole), cylinders with `segments` sides
// and flat caps, boxes as 12 triangles, meshes with one flat normal per triangle (degenerate
// triangles are skipped). The body must be valid. Returns the number of triangles appended.
std::size_t tessellate(const BodyInstance& b, const Eigen::Vector3d& world_origin, std::vector<BodyVertex>& out,
                       int segments = 32);

}  // namespace sandpatch::render
