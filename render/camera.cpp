// Camera matrices (the classic gluLookAt / gluPerspective forms).
#include "render/camera.hpp"

#include <Eigen/Geometry>
#include <cmath>

namespace sandpatch::render {

Eigen::Matrix4f look_at(const Eigen::Vector3f& eye, const Eigen::Vector3f& target) {
  Eigen::Vector3f f = target - eye;
  if (f.squaredNorm() == 0) f = Eigen::Vector3f(0, 0, -1);
  f.normalize();
  Eigen::Vector3f up(0, 1, 0);
  if (std::fabs(f.dot(up)) > 0.999f) up = Eigen::Vector3f(0, 0, 1);
  const Eigen::Vector3f s = f.cross(up).normalized();  // right
  const Eigen::Vector3f u = s.cross(f);                // true up
  Eigen::Matrix4f v = Eigen::Matrix4f::Identity();
  v.block<1, 3>(0, 0) = s.transpose();
  v.block<1, 3>(1, 0) = u.transpose();
  v.block<1, 3>(2, 0) = -f.transpose();
  v(0, 3) = -s.dot(eye);
  v(1, 3) = -u.dot(eye);
  v(2, 3) = f.dot(eye);
  return v;
}

Eigen::Matrix4f perspective(float fov_y_deg, float aspect, float n, float f) {
  const float t = 1.0f / std::tan(fov_y_deg * 0.5f * 3.14159265358979f / 180.0f);
  Eigen::Matrix4f p = Eigen::Matrix4f::Zero();
  p(0, 0) = t / aspect;
  p(1, 1) = t;
  p(2, 2) = (f + n) / (n - f);
  p(2, 3) = 2.0f * f * n / (n - f);
  p(3, 2) = -1.0f;
  return p;
}

}  // namespace sandpatch::render
