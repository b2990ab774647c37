// Orbit camera (render/orbit_camera.hpp).
#include "render/orbit_camera.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numbers>

namespace sandpatch::render {

OrbitCamera OrbitCamera::looking(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  OrbitCamera c;
  c.target = target;
  Eigen::Vector3d d = eye - target;
  if (!(d.norm() > 0) || !d.allFinite()) d = Eigen::Vector3d(0, 1, 0);
  c.distance = std::clamp(d.norm(), kMinDistance, kMaxDistance);
  c.pitch = std::clamp(std::asin(std::clamp(d.y() / d.norm(), -1.0, 1.0)), -kMaxPitch, kMaxPitch);
  c.yaw = std::atan2(d.z(), d.x());
  return c;
}

Eigen::Vector3d OrbitCamera::eye() const {
  return target + distance * Eigen::Vector3d(std::cos(pitch) * std::cos(yaw), std::sin(pitch),
                                             std::cos(pitch) * std::sin(yaw));
}

void OrbitCamera::rotate(double dx_px, double dy_px) {
  if (!std::isfinite(dx_px) || !std::isfinite(dy_px)) return;
  yaw = std::remainder(yaw - dx_px * kRadiansPerPixel, 2 * std::numbers::pi);
  pitch = std::clamp(pitch + dy_px * kRadiansPerPixel, -kMaxPitch, kMaxPitch);
}

void OrbitCamera::zoom(double notches) {
  if (!std::isfinite(notches)) return;
  distance = std::clamp(distance * std::pow(kZoomPerNotch, notches), kMinDistance, kMaxDistance);
}

void OrbitCamera::pan(double dx_px, double dy_px, double fov_deg, int height_px) {
  if (!std::isfinite(dx_px) || !std::isfinite(dy_px) || height_px < 1 || !(fov_deg > 0 && fov_deg < 180)) return;
  // Metres per pixel at the target's depth: the view's height there is 2 d tan(fov / 2).
  const double m_per_px = 2 * distance * std::tan(fov_deg * std::numbers::pi / 360) / height_px;
  const Eigen::Vector3d forward = (target - eye()).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitY());
  if (right.norm() < 1e-9) right = Eigen::Vector3d::UnitX();
  right.normalize();
  const Eigen::Vector3d up = right.cross(forward);
  // The scene follows the mouse: the camera (and its target) moves the other way.
  target += (-dx_px * right + dy_px * up) * m_per_px;
}

}  // namespace sandpatch::render
