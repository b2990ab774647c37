// Camera matrices (OpenGL conventions: right-handed eye space looking down -z, clip depth
// [-1, 1]), pure functions. Positions are local to the heightfield origin (float), y up.
#pragma once

#include <Eigen/Core>

namespace sandpatch::render {

// View matrix of an eye at `eye` looking at `target` with +y up (falls back to +z up when the
// view is vertical).
Eigen::Matrix4f look_at(const Eigen::Vector3f& eye, const Eigen::Vector3f& target);
// Perspective projection: vertical field of view fov_y (degrees), aspect = width / height,
// near and far planes (m, 0 < near < far).
Eigen::Matrix4f perspective(float fov_y_deg, float aspect, float near_m, float far_m);

}  // namespace sandpatch::render
