// Small float vector and quaternion helpers for the granule DEM (simulation units).
// Header-only and branch-free so the inner loops inline them.
#pragma once

#include <cmath>

namespace sandpatch {

struct Vec3 {
  float x = 0, y = 0, z = 0;
#if defined(__clang__) && __clang_major__ < 16
  // clang before 16 lacks parenthesised aggregate initialisation (P0960), which the GLSL the
  // DEM shares with C++ writes as vec3(x, y, z): the constructors it stands for (the sanitizer
  // and fuzzing build uses clang 14, docs/reliability.md).
  constexpr Vec3() = default;
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
#endif
};

inline Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
inline Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
inline Vec3 operator*(float s, Vec3 a) { return a * s; }
inline float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(Vec3 a) { return std::sqrt(dot(a, a)); }

// Unit quaternion (x, y, z, w) rotating body frame -> world frame.
struct Quat {
  float x = 0, y = 0, z = 0, w = 1;
};

inline Quat operator*(Quat a, Quat b) {
  return {a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y, a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
          a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w, a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z};
}
inline Quat normalized(Quat q) {
  float n = std::sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
  float s = n > 0 ? 1.0f / n : 0.0f;
  return n > 0 ? Quat{q.x * s, q.y * s, q.z * s, q.w * s} : Quat{};
}
// v rotated by q: v + 2w (u x v) + 2 u x (u x v), u = (x, y, z).
inline Vec3 rotate(Quat q, Vec3 v) {
  Vec3 u{q.x, q.y, q.z};
  Vec3 t = 2.0f * cross(u, v);
  return v + q.w * t + cross(u, t);
}
inline Vec3 rotate_inv(Quat q, Vec3 v) { return rotate(Quat{-q.x, -q.y, -q.z, q.w}, v); }
// Rotation of `angle` radians about the unit `axis`.
inline Quat axis_angle(Vec3 axis, float angle) {
  float s = std::sin(0.5f * angle);
  return {axis.x * s, axis.y * s, axis.z * s, std::cos(0.5f * angle)};
}

}  // namespace sandpatch
