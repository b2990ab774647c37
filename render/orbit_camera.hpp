// The orbit camera of `sandpatch view`: an eye on a sphere around a target point, turned by
// mouse drags, zoomed by the wheel and panned in the screen plane. Pure functions of the
// mouse motion (pixels), no window; world coordinates in m, y up.
#pragma once

#include <Eigen/Core>

namespace sandpatch::render {

struct OrbitCamera {
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  // m, world: the point looked at and orbited
  double distance = 10;  // m, eye to target, in [kMinDistance, kMaxDistance]
  double yaw = 0;        // rad, direction from the target to the eye about +y (0 = +x, pi/2 = +z)
  double pitch = 0.5;    // rad, elevation of the eye above the target's horizontal plane, |pitch| <= kMaxPitch

  static constexpr double kMaxPitch = 1.55;          // rad (88.8 degrees): never exactly vertical
  static constexpr double kMinDistance = 0.05;       // m
  static constexpr double kMaxDistance = 1e6;        // m
  static constexpr double kRadiansPerPixel = 0.005;  // rotation per pixel dragged
  static constexpr double kZoomPerNotch = 0.85;      // distance factor per wheel notch toward the target

  // The camera at `eye` looking at `target` (eye == target: one metre above it).
  static OrbitCamera looking(const Eigen::Vector3d& eye, const Eigen::Vector3d& target);
  Eigen::Vector3d eye() const;

  // A drag of (dx, dy) pixels (x right, y down): the scene turns with the mouse (yaw by
  // -dx, pitch by +dy, kRadiansPerPixel each); the pitch is clamped to +-kMaxPitch.
  void rotate(double dx_px, double dy_px);
  // `notches` of the wheel (> 0 toward the target): distance × kZoomPerNotch^notches, clamped.
  void zoom(double notches);
  // A drag of (dx, dy) pixels with the right button: the target moves in the screen plane so
  // that a point at the target's depth follows the mouse, for a vertical field of view of
  // fov_deg over height_px pixels. The distance and direction stay.
  void pan(double dx_px, double dy_px, double fov_deg, int height_px);
};

}  // namespace sandpatch::render
