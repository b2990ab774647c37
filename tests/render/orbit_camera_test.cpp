// tests render/orbit_camera.cpp: the viewer's orbit camera keeps its target and distance
// where it should, and a pan moves the scene with the mouse by exactly the pixels dragged.
#include "render/orbit_camera.hpp"

#include <gtest/gtest.h>

#include <cmath>

#include "render/camera.hpp"

using namespace sandpatch::render;

TEST(OrbitCamera, LookingFromAnEyeGivesThatEyeBack) {
  for (const auto& [eye, target] : {std::pair{Eigen::Vector3d(6, 4, 8), Eigen::Vector3d(0, 0, 0)},
                                    std::pair{Eigen::Vector3d(-3, 1.5, 3), Eigen::Vector3d(0, 0.3, 0)},
                                    std::pair{Eigen::Vector3d(10, -2, -7), Eigen::Vector3d(1, 1, 1)}}) {
    const OrbitCamera c = OrbitCamera::looking(eye, target);
    EXPECT_LT((c.eye() - eye).norm(), 1e-9);
    EXPECT_LT((c.target - target).norm(), 1e-12);
  }
  // Straight above: the pitch stops short of vertical, the distance stays.
  const OrbitCamera top = OrbitCamera::looking({0, 5, 0}, {0, 0, 0});
  EXPECT_NEAR(top.pitch, OrbitCamera::kMaxPitch, 1e-12);
  EXPECT_NEAR(top.distance, 5, 1e-12);
}

TEST(OrbitCamera, RotateTurnsAboutTheTargetAndClampsThePitch) {
  OrbitCamera c = OrbitCamera::looking({6, 4, 8}, {1, 0, 2});
  const double d = c.distance;
  c.rotate(100, -40);
  EXPECT_NEAR((c.eye() - c.target).norm(), d, 1e-9);
  EXPECT_LT((c.target - Eigen::Vector3d(1, 0, 2)).norm(), 1e-12);
  c.rotate(0, 1e6);
  EXPECT_DOUBLE_EQ(c.pitch, OrbitCamera::kMaxPitch);
  c.rotate(0, -1e6);
  EXPECT_DOUBLE_EQ(c.pitch, -OrbitCamera::kMaxPitch);
  c.rotate(NAN, 0);  // ignored
  EXPECT_TRUE(c.eye().allFinite());
}

TEST(OrbitCamera, ZoomScalesTheDistanceOnlyAndIsClamped) {
  OrbitCamera c = OrbitCamera::looking({6, 4, 8}, {0, 0, 0});
  const Eigen::Vector3d dir = (c.eye() - c.target).normalized();
  c.zoom(2);
  EXPECT_NEAR(c.distance, std::sqrt(116.0) * 0.85 * 0.85, 1e-9);
  EXPECT_LT(((c.eye() - c.target).normalized() - dir).norm(), 1e-12);
  c.zoom(1e4);
  EXPECT_DOUBLE_EQ(c.distance, OrbitCamera::kMinDistance);
  c.zoom(-1e6);
  EXPECT_DOUBLE_EQ(c.distance, OrbitCamera::kMaxDistance);
}

// After a pan of (dx, dy) pixels, the old target (a point at the target's depth) projects
// (dx, dy) pixels from the image centre: the scene follows the mouse.
TEST(OrbitCamera, PanMovesTheSceneByThePixelsDragged) {
  const int w = 1280, h = 720;
  const double fov = 45;
  OrbitCamera c = OrbitCamera::looking({6, 4, 8}, {0, 0, 0});
  const Eigen::Vector3d old_target = c.target;
  const double d = c.distance;
  c.pan(50, -30, fov, h);
  EXPECT_NEAR(c.distance, d, 1e-12);
  const Eigen::Matrix4f vp = perspective(float(fov), float(w) / h, 0.1f, 100.0f) *
                             look_at(c.eye().cast<float>(), c.target.cast<float>());
  const Eigen::Vector4f q = vp * Eigen::Vector4f(float(old_target.x()), float(old_target.y()), float(old_target.z()), 1);
  const double px = (q.x() / q.w() + 1) * 0.5 * w, py = (1 - q.y() / q.w()) * 0.5 * h;
  EXPECT_NEAR(px - w / 2.0, 50, 0.05);
  EXPECT_NEAR(py - h / 2.0, -30, 0.05);
}
