// Body shapes into triangles; see bodies.hpp.
#include "render/bodies.hpp"

#include <cmath>
#include <numbers>

namespace sandpatch::render {

namespace {

bool positive(float v) { return v > 0 && std::isfinite(v); }

// A point of a profile revolved around y: distance from the axis rho, height y (m) and the
// outward normal's (radial, vertical) components.
struct ProfilePoint {
  float rho, y, n_rho, n_y;
};

void revolve(const std::vector<ProfilePoint>& profile, int segments, const Eigen::Matrix3f& rot,
             const Eigen::Vector3f& t, std::vector<BodyVertex>& out, std::size_t& tris) {
  auto vertex = [&](const ProfilePoint& p, int s) {
    const float a = 2.0f * std::numbers::pi_v<float> * float(s % segments) / float(segments);
    const float c = std::cos(a), sn = std::sin(a);
    return BodyVertex{rot * Eigen::Vector3f(p.rho * c, p.y, p.rho * sn) + t,
                      (rot * Eigen::Vector3f(p.n_rho * c, p.n_y, p.n_rho * sn)).normalized()};
  };
  for (std::size_t k = 0; k + 1 < profile.size(); ++k) {
    const ProfilePoint &p = profile[k], &q = profile[k + 1];
    if (p.rho == q.rho && p.y == q.y) continue;  // a hard edge: the same ring twice
    for (int s = 0; s < segments; ++s) {
      const BodyVertex a = vertex(p, s), b = vertex(p, s + 1), c = vertex(q, s + 1), d = vertex(q, s);
      out.insert(out.end(), {a, b, c, a, c, d});
      tris += 2;
    }
  }
}

}  // namespace

Status validate(const BodyInstance& b, int index) {
  const std::string f = "bodies[" + std::to_string(index) + "].";
  std::vector<Error> es;
  if (!b.position.allFinite()) es.push_back(Error{"", f + "position", "non-finite", "must be finite (m)"});
  if (!b.orientation.coeffs().allFinite() || std::fabs(b.orientation.norm() - 1.0f) > 1e-3f)
    es.push_back(Error{"", f + "orientation", "non-finite or not unit", "must be a unit quaternion"});
  if (!(b.albedo.allFinite() && b.albedo.minCoeff() >= 0 && b.albedo.maxCoeff() <= 1))
    es.push_back(Error{"", f + "albedo", "out of range", "must be in [0, 1] per channel"});
  if (b.segments != 0 && (b.segments < 4 || b.segments > 64))
    es.push_back(Error{"", f + "segments", std::to_string(b.segments), "must be 0 (the default) or in [4, 64]"});
  switch (b.kind) {
    case BodyShapeKind::Sphere:
      if (!positive(b.radius)) es.push_back(Error{"", f + "radius", std::to_string(b.radius), "must be > 0 and finite (m)"});
      break;
    case BodyShapeKind::Cylinder:
    case BodyShapeKind::Capsule:
      if (!positive(b.radius)) es.push_back(Error{"", f + "radius", std::to_string(b.radius), "must be > 0 and finite (m)"});
      if (!(std::isfinite(b.height) && (b.height > 0 || (b.kind == BodyShapeKind::Capsule && b.height == 0))))
        es.push_back(Error{"", f + "height", std::to_string(b.height),
                           b.kind == BodyShapeKind::Capsule ? "must be >= 0 and finite (m)" : "must be > 0 and finite (m)"});
      break;
    case BodyShapeKind::Box:
      if (!(b.half_extents.allFinite() && b.half_extents.minCoeff() > 0))
        es.push_back(Error{"", f + "half_extents", "non-positive or non-finite", "must be > 0 and finite (m)"});
      break;
    case BodyShapeKind::Mesh: {
      if (b.triangles.empty()) es.push_back(Error{"", f + "triangles", "empty", "a mesh needs at least one triangle"});
      for (std::size_t k = 0; k < b.vertices.size(); ++k)
        if (!b.vertices[k].allFinite()) {
          es.push_back(Error{"", f + "vertices[" + std::to_string(k) + "]", "non-finite", "must be finite (m)"});
          break;
        }
      const int nv = int(b.vertices.size());
      for (std::size_t k = 0; k < b.triangles.size(); ++k) {
        const auto& t = b.triangles[k];
        if (t[0] < 0 || t[0] >= nv || t[1] < 0 || t[1] >= nv || t[2] < 0 || t[2] >= nv) {
          es.push_back(Error{"", f + "triangles[" + std::to_string(k) + "]",
                             std::to_string(t[0]) + ", " + std::to_string(t[1]) + ", " + std::to_string(t[2]),
                             "indices must be in [0, " + std::to_string(nv) + ")"});
          break;
        }
      }
      break;
    }
  }
  if (!es.empty()) return es;
  return Ok{};
}

Eigen::Vector3f body_palette(int k) {
  static const Eigen::Vector3f colours[] = {
      {0.72f, 0.16f, 0.12f},  // red
      {0.20f, 0.36f, 0.70f},  // blue
      {0.55f, 0.36f, 0.18f},  // wood
      {0.12f, 0.55f, 0.52f},  // teal
      {0.55f, 0.20f, 0.55f},  // purple
      {0.85f, 0.55f, 0.10f},  // orange
  };
  const int n = int(std::size(colours));
  return colours[((k % n) + n) % n];
}

std::size_t tessellate(const BodyInstance& b, const Eigen::Vector3d& world_origin, std::vector<BodyVertex>& out,
                       int segments) {
  segments = std::max(8, (segments + 3) / 4 * 4);  // a multiple of 4: a ring at the equator
  const Eigen::Matrix3f rot = b.orientation.normalized().toRotationMatrix();
  const Eigen::Vector3f t = (b.position - world_origin).cast<float>();
  std::size_t tris = 0;
  const float pi = std::numbers::pi_v<float>;
  const int half = segments / 2;
  switch (b.kind) {
    case BodyShapeKind::Sphere:
    case BodyShapeKind::Capsule: {
      // Latitude rings from the top pole to the bottom one; a capsule's hemispheres sit at
      // y = +-height / 2 and the band between them is its straight part.
      const float off = b.kind == BodyShapeKind::Capsule ? 0.5f * b.height : 0.0f;
      std::vector<ProfilePoint> prof;
      for (int i = 0; i <= half; ++i) {
        const float th = pi * float(i) / float(half);
        const float y = b.radius * std::cos(th);
        const float shift = 2 * i < half ? off : (2 * i > half ? -off : off);
        prof.push_back({b.radius * std::sin(th), y + shift, std::sin(th), std::cos(th)});
        if (2 * i == half && off > 0) prof.push_back({b.radius, y - off, 1.0f, 0.0f});
      }
      revolve(prof, segments, rot, t, out, tris);
      break;
    }
    case BodyShapeKind::Cylinder: {
      const float h = 0.5f * b.height, r = b.radius;
      revolve({{0, h, 0, 1}, {r, h, 0, 1}, {r, h, 1, 0}, {r, -h, 1, 0}, {r, -h, 0, -1}, {0, -h, 0, -1}}, segments, rot, t,
              out, tris);
      break;
    }
    case BodyShapeKind::Box: {
      const Eigen::Vector3f e = b.half_extents;
      for (int axis = 0; axis < 3; ++axis)
        for (int sign : {-1, 1}) {
          const int u = (axis + 1) % 3, v = (axis + 2) % 3;
          Eigen::Vector3f n = Eigen::Vector3f::Zero();
          n[axis] = float(sign);
          auto corner = [&](float su, float sv) {
            Eigen::Vector3f p;
            p[axis] = float(sign) * e[axis];
            p[u] = su * e[u];
            p[v] = sv * e[v];
            return BodyVertex{rot * p + t, rot * n};
          };
          const BodyVertex a = corner(-1, -1), bb = corner(1, -1), c = corner(1, 1), d = corner(-1, 1);
          out.insert(out.end(), {a, bb, c, a, c, d});
          tris += 2;
        }
      break;
    }
    case BodyShapeKind::Mesh:
      for (const auto& tri : b.triangles) {
        const Eigen::Vector3f p0 = b.vertices[std::size_t(tri[0])], p1 = b.vertices[std::size_t(tri[1])],
                              p2 = b.vertices[std::size_t(tri[2])];
        const Eigen::Vector3f n = (p1 - p0).cross(p2 - p0);
        const float len = n.norm();
        if (!(len > 0) || !std::isfinite(len)) continue;  // degenerate: nothing to draw, no NaN normal
        const Eigen::Vector3f nw = rot * (n / len);
        out.insert(out.end(), {BodyVertex{rot * p0 + t, nw}, BodyVertex{rot * p1 + t, nw}, BodyVertex{rot * p2 + t, nw}});
        ++tris;
      }
      break;
  }
  return tris;
}

}  // namespace sandpatch::render
