// tests render/camera.cpp: look_at and perspective map known points where OpenGL puts them.
#include "render/camera.hpp"

#include <gtest/gtest.h>

using namespace sandpatch::render;

// The target lands in the centre of the image; near and far map to depth -1 and +1.
TEST(Camera, TargetProjectsToTheCentreAndPlanesToTheDepthRange) {
  const Eigen::Vector3f eye(3, 10, -2), target(20, 1, 15);
  const Eigen::Matrix4f vp = perspective(60, 4.0f / 3.0f, 0.5f, 100.0f) * look_at(eye, target);
  Eigen::Vector4f c = vp * Eigen::Vector4f(target.x(), target.y(), target.z(), 1);
  EXPECT_NEAR(c.x() / c.w(), 0, 1e-5);
  EXPECT_NEAR(c.y() / c.w(), 0, 1e-5);
  const Eigen::Vector3f dir = (target - eye).normalized();
  for (auto [d, want] : {std::pair{0.5f, -1.0f}, std::pair{100.0f, 1.0f}}) {
    const Eigen::Vector3f p = eye + d * dir;
    Eigen::Vector4f q = vp * Eigen::Vector4f(p.x(), p.y(), p.z(), 1);
    EXPECT_NEAR(q.z() / q.w(), want, 1e-4);
  }
}

// y up stays up on screen; a point at the top edge of the vertical field of view maps to y = 1.
TEST(Camera, VerticalFieldOfViewAndUp) {
  const Eigen::Vector3f eye(0, 0, 0), target(0, 0, -10);
  const Eigen::Matrix4f vp = perspective(90, 1.0f, 0.1f, 100.0f) * look_at(eye, target);
  Eigen::Vector4f q = vp * Eigen::Vector4f(0, 10, -10, 1);  // 45 degrees up
  EXPECT_NEAR(q.y() / q.w(), 1.0f, 1e-5);
  // Looking straight down still gives a valid basis.
  const Eigen::Matrix4f down = look_at({0, 10, 0}, {0, 0, 0});
  EXPECT_TRUE(down.allFinite());
}
