// tests render/bodies.cpp: tessellated shapes lie on the analytic surfaces with outward unit
// normals, at the body's pose; bad bodies are refused naming the field.
#include "render/bodies.hpp"

#include <gtest/gtest.h>

#include <cmath>

using namespace sandpatch;
using namespace sandpatch::render;

namespace {

BodyInstance posed(BodyShapeKind kind) {
  BodyInstance b;
  b.kind = kind;
  b.position = {100.0, 2.0, -50.0};
  b.orientation = Eigen::Quaternionf(Eigen::AngleAxisf(0.7f, Eigen::Vector3f(1, 2, 3).normalized()));
  return b;
}

// Vertices in the body frame (undo the pose and the origin shift).
Eigen::Vector3f body_frame(const BodyInstance& b, const Eigen::Vector3d& origin, const Eigen::Vector3f& p) {
  return b.orientation.conjugate() * (p - (b.position - origin).cast<float>());
}

}  // namespace

TEST(Bodies, SphereVerticesOnTheSphereWithRadialNormals) {
  BodyInstance b = posed(BodyShapeKind::Sphere);
  b.radius = 0.25f;
  const Eigen::Vector3d origin(90, 0, -60);
  std::vector<BodyVertex> v;
  const std::size_t tris = tessellate(b, origin, v, 32);
  EXPECT_EQ(v.size(), 3 * tris);
  EXPECT_EQ(tris, 2u * 32u * 16u);  // 16 latitude bands of 32 quads
  for (const BodyVertex& x : v) {
    const Eigen::Vector3f q = body_frame(b, origin, x.position);
    EXPECT_NEAR(q.norm(), 0.25f, 1e-5f);
    EXPECT_NEAR(x.normal.norm(), 1.0f, 1e-5f);
    if (q.norm() > 0) {
      EXPECT_GT(x.normal.dot(b.orientation * q.normalized()), 0.9999f);
    }
  }
}

TEST(Bodies, BoxCornersAndFaceNormals) {
  BodyInstance b = posed(BodyShapeKind::Box);
  b.half_extents = {0.25f, 0.5f, 1.0f};
  std::vector<BodyVertex> v;
  EXPECT_EQ(tessellate(b, Eigen::Vector3d::Zero(), v), 12u);
  for (const BodyVertex& x : v) {
    const Eigen::Vector3f q = body_frame(b, Eigen::Vector3d::Zero(), x.position);
    EXPECT_NEAR(std::fabs(q.x()), 0.25f, 1e-5f);
    EXPECT_NEAR(std::fabs(q.y()), 0.5f, 1e-5f);
    EXPECT_NEAR(std::fabs(q.z()), 1.0f, 1e-5f);
    // The normal is the face's axis, pointing out: q . n = that half extent.
    const Eigen::Vector3f n = b.orientation.conjugate() * x.normal;
    EXPECT_NEAR(n.norm(), 1.0f, 1e-5f);
    EXPECT_NEAR(q.dot(n), n.cwiseAbs().dot(b.half_extents), 1e-5f);
  }
}

TEST(Bodies, CylinderAndCapsuleSurfaces) {
  for (BodyShapeKind kind : {BodyShapeKind::Cylinder, BodyShapeKind::Capsule}) {
    BodyInstance b = posed(kind);
    b.radius = 0.3f;
    b.height = 0.9f;
    std::vector<BodyVertex> v;
    ASSERT_GT(tessellate(b, Eigen::Vector3d::Zero(), v, 24), 0u);
    float ymax = -1e9f, ymin = 1e9f;
    for (const BodyVertex& x : v) {
      const Eigen::Vector3f q = body_frame(b, Eigen::Vector3d::Zero(), x.position);
      ymax = std::max(ymax, q.y());
      ymin = std::min(ymin, q.y());
      const float rho = std::hypot(q.x(), q.z());
      if (kind == BodyShapeKind::Cylinder) {
        // On a cap (|y| = h/2, rho <= r) or on the side (rho = r).
        EXPECT_TRUE(std::fabs(std::fabs(q.y()) - 0.45f) < 1e-5f || std::fabs(rho - 0.3f) < 1e-5f) << q.transpose();
        EXPECT_LE(rho, 0.3f + 1e-5f);
      } else {
        // Distance to the axis segment y in [-h/2, h/2] is the radius.
        const float yc = std::clamp(q.y(), -0.45f, 0.45f);
        EXPECT_NEAR(std::hypot(rho, q.y() - yc), 0.3f, 1e-5f) << q.transpose();
      }
    }
    const float top = kind == BodyShapeKind::Cylinder ? 0.45f : 0.75f;
    EXPECT_NEAR(ymax, top, 1e-5f);
    EXPECT_NEAR(ymin, -top, 1e-5f);
  }
}

TEST(Bodies, MeshFlatNormalsAndDegenerateTrianglesSkipped) {
  BodyInstance b;
  b.kind = BodyShapeKind::Mesh;
  b.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {2, 0, 0}};
  b.triangles = {{0, 2, 1}, {0, 1, 3}};  // the second is degenerate (collinear)
  std::vector<BodyVertex> v;
  EXPECT_EQ(tessellate(b, Eigen::Vector3d::Zero(), v), 1u);
  ASSERT_EQ(v.size(), 3u);
  for (const BodyVertex& x : v) EXPECT_TRUE(x.normal.isApprox(Eigen::Vector3f(0, 1, 0), 1e-6f)) << x.normal.transpose();
}

TEST(Bodies, BadBodiesNameTheField) {
  BodyInstance b;
  b.radius = -1;
  auto st = validate(b, 2);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("bodies[2].radius"), std::string::npos) << st.message();
  b = BodyInstance{};
  b.position.x() = std::nan("");
  EXPECT_NE(validate(b, 0).message().find("bodies[0].position"), std::string::npos);
  b = BodyInstance{};
  b.kind = BodyShapeKind::Mesh;
  b.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}};
  b.triangles = {{0, 1, 3}};
  EXPECT_NE(validate(b, 1).message().find("bodies[1].triangles[0]"), std::string::npos) << validate(b, 1).message();
  b = BodyInstance{};
  b.kind = BodyShapeKind::Cylinder;
  b.height = 0;
  EXPECT_NE(validate(b, 0).message().find("bodies[0].height"), std::string::npos);
  b.kind = BodyShapeKind::Capsule;  // a capsule of no straight part is a sphere
  EXPECT_TRUE(validate(b, 0).ok());
  b = BodyInstance{};
  b.segments = 3;  // 0 (the renderer's 32) or [4, 64]
  EXPECT_NE(validate(b, 4).message().find("bodies[4].segments"), std::string::npos) << validate(b, 4).message();
  b.segments = 8;
  EXPECT_TRUE(validate(b, 4).ok());
  std::vector<BodyVertex> v;
  EXPECT_EQ(tessellate(b, Eigen::Vector3d::Zero(), v, b.segments), 2u * 8u * 4u);  // 8 around, 4 from pole to pole, two triangles each
}
