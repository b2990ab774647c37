// tests manager/mesh_sdf.cpp: the signed distance of a closed mesh by FCL queries against
// analytic shapes (a cube and a tessellated sphere, read from OBJ files), the mesh shells
// sampled from it (on the offset surface, no holes, deterministic), the mesh's mass properties
// in Bullet, and bad meshes refused naming the file.
#include <gtest/gtest.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>

#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/mesh_sdf.hpp"
#include "manager/shell.hpp"
#include "scene/mesh.hpp"

using namespace sandpatch;

namespace {

constexpr double kPi = 3.14159265358979323846;

// One folder per test: ctest runs the tests of this file as parallel processes.
std::string temp_path(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / "sandpatch_mesh_sdf_test" /
                   ::testing::UnitTest::GetInstance()->current_test_info()->name();
  std::filesystem::create_directories(dir);
  return (dir / name).string();
}

void write_obj(const std::string& path, const std::vector<Eigen::Vector3d>& v, const std::vector<std::array<int, 3>>& t) {
  std::ofstream f(path);
  f.precision(17);
  for (const auto& p : v) f << "v " << p.x() << " " << p.y() << " " << p.z() << "\n";
  for (const auto& k : t) f << "f " << k[0] + 1 << " " << k[1] + 1 << " " << k[2] + 1 << "\n";
}

// A cube of side `a` centred on the origin, 12 triangles wound counter-clockwise from outside.
void cube(double a, std::vector<Eigen::Vector3d>& v, std::vector<std::array<int, 3>>& t) {
  v.clear();
  for (int i = 0; i < 8; ++i) v.push_back(0.5 * a * Eigen::Vector3d(i & 1 ? 1 : -1, i & 2 ? 1 : -1, i & 4 ? 1 : -1));
  t = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
       {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
}

// An icosphere of radius R: the icosahedron with every triangle split in four `levels` times,
// new vertices pushed onto the sphere. Outward, counter-clockwise.
void icosphere(double R, int levels, std::vector<Eigen::Vector3d>& v, std::vector<std::array<int, 3>>& t) {
  const double g = (1 + std::sqrt(5.0)) / 2;
  v = {{-1, g, 0}, {1, g, 0}, {-1, -g, 0}, {1, -g, 0}, {0, -1, g}, {0, 1, g},
       {0, -1, -g}, {0, 1, -g}, {g, 0, -1}, {g, 0, 1}, {-g, 0, -1}, {-g, 0, 1}};
  for (auto& p : v) p.normalize();
  t = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
       {11, 10, 2}, {10, 7, 6}, {7, 1, 8}, {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8},
       {3, 8, 9}, {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto m = [&](int a, int b) {
      auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      return mid[key] = int(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> next;
    for (const auto& f : t) {
      const int ab = m(f[0], f[1]), bc = m(f[1], f[2]), ca = m(f[2], f[0]);
      next.push_back({f[0], ab, ca});
      next.push_back({f[1], bc, ab});
      next.push_back({f[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    t = std::move(next);
  }
  for (auto& p : v) p *= R;
}

// The same mesh through the OBJ loader, re-centred on its centroid as bodies are.
RigidShape load_body(const std::string& path) {
  auto m = load_obj_mesh(path);
  EXPECT_TRUE(m.ok()) << m.message();
  EXPECT_TRUE(check_solid_mesh(*m, path, "shape").empty());
  RigidShape s;
  s.kind = RigidShapeKind::Mesh;
  const Eigen::Vector3f c = m->centroid().cast<float>();
  for (const auto& p : m->vertices) s.vertices.push_back(p - c);
  s.triangles = m->triangles;
  return s;
}

double box_sdf(const Eigen::Vector3d& p, double h) {
  const Eigen::Vector3d q = p.cwiseAbs() - Eigen::Vector3d::Constant(h);
  return q.cwiseMax(0.0).norm() + std::min(q.maxCoeff(), 0.0);
}

// Generalised winding number (solid angles, Van Oosterom & Strackee 1983): 1 inside a closed
// outward mesh, 0 outside; an independent inside test for the pseudo-normal sign.
double winding(const RigidShape& s, const Eigen::Vector3d& p) {
  double w = 0;
  for (const auto& f : s.triangles) {
    const Eigen::Vector3d a = s.vertices[f[0]].cast<double>() - p, b = s.vertices[f[1]].cast<double>() - p,
                          c = s.vertices[f[2]].cast<double>() - p;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    w += 2 * std::atan2(a.dot(b.cross(c)), la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb);
  }
  return w / (4 * kPi);
}

// Surface points of the analytic shape: on the 6 faces of a cube (n × n each) or on a
// sphere (Fibonacci, n² · 6 points).
std::vector<Eigen::Vector3d> cube_surface(double a, int n) {
  std::vector<Eigen::Vector3d> out;
  for (int ax = 0; ax < 3; ++ax)
    for (int side = -1; side <= 1; side += 2)
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          Eigen::Vector3d p;
          p[ax] = side * 0.5 * a;
          p[(ax + 1) % 3] = a * (double(i) / (n - 1) - 0.5);
          p[(ax + 2) % 3] = a * (double(j) / (n - 1) - 0.5);
          out.push_back(p);
        }
  return out;
}
std::vector<Eigen::Vector3d> sphere_surface(double R, int n) {
  std::vector<Eigen::Vector3d> out;
  const int N = 6 * n * n;
  for (int i = 0; i < N; ++i) {
    const double y = 1 - 2 * (i + 0.5) / N, rho = std::sqrt(1 - y * y), phi = 2.39996322972865332 * i;
    out.push_back(R * Eigen::Vector3d(rho * std::cos(phi), y, rho * std::sin(phi)));
  }
  return out;
}

// Largest distance from a surface point to its nearest shell centre (brute force).
double coverage(const std::vector<Eigen::Vector3d>& surface, const std::vector<Eigen::Vector3f>& pts) {
  double worst = 0;
  for (const auto& x : surface) {
    double best = 1e30;
    for (const auto& p : pts) best = std::min(best, (p.cast<double>() - x).squaredNorm());
    worst = std::max(worst, std::sqrt(best));
  }
  return worst;
}

double min_neighbour(const std::vector<Eigen::Vector3f>& pts) {
  double lo = 1e30;
  for (std::size_t i = 0; i < pts.size(); ++i)
    for (std::size_t j = i + 1; j < pts.size(); ++j) lo = std::min(lo, double((pts[i] - pts[j]).norm()));
  return lo;
}

// The terrain manager's sizes: granule sphere radius r, shell spacing 1.5 r.
constexpr float kR = 0.025f, kSpacing = 1.5f * kR;

}  // namespace

// The SDF of the cube OBJ equals the analytic box SDF (to 1e-9 m) at random points in and
// around it, including points near edges and corners; the sign agrees with the winding number.
TEST(MeshSdf, CubeDistanceAndSignMatchTheBox) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  cube(0.5, v, t);
  const std::string path = temp_path("cube.obj");
  write_obj(path, v, t);
  const RigidShape s = load_body(path);
  auto sdf = MeshSdf::create(s.vertices, s.triangles, path);
  ASSERT_TRUE(sdf.ok()) << sdf.message();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int k = 0; k < 4000; ++k) {
    Eigen::Vector3d p(u(rng), u(rng), u(rng));
    if (k % 4 == 1) p.x() = std::copysign(0.25, p.x());                      // on a face plane
    if (k % 4 == 2) p.x() = std::copysign(0.25, p.x()), p.y() = std::copysign(0.25 + 1e-4, p.y());  // near an edge
    const auto q = sdf->query(p);
    ASSERT_NEAR(q.distance, box_sdf(p, 0.25), 1e-9) << p.transpose();
    if (std::abs(q.distance) > 1e-6) {
      ASSERT_EQ(q.distance < 0, winding(s, p) > 0.5) << p.transpose();
    }
  }
}

// The icosphere OBJ (5120 triangles, R = 0.3 m): |sdf − (|p| − R)| stays below the largest
// gap between the sphere and the mesh (its sagitta, 0.19 mm here); the sign agrees with the
// winding number.
TEST(MeshSdf, SphereDistanceWithinTheTessellationError) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  icosphere(0.3, 4, v, t);
  const std::string path = temp_path("sphere.obj");
  write_obj(path, v, t);
  const RigidShape s = load_body(path);
  ASSERT_EQ(s.triangles.size(), 5120u);
  double sagitta = 0;
  for (const auto& f : t) sagitta = std::max(sagitta, 0.3 - ((v[f[0]] + v[f[1]] + v[f[2]]) / 3).norm());
  auto sdf = MeshSdf::create(s.vertices, s.triangles, path);
  ASSERT_TRUE(sdf.ok()) << sdf.message();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-0.45, 0.45);
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    const auto q = sdf->query(p);
    ASSERT_NEAR(q.distance, p.norm() - 0.3, sagitta + 1e-6) << p.transpose();
    if (std::abs(q.distance) > 1e-6 && k % 10 == 0) {
      ASSERT_EQ(q.distance < 0, winding(s, p) > 0.5) << p.transpose();
    }
  }
}

// Cube shell at the manager's sizes (r = 2.5 cm, spacing 1.5 r): every centre r inside the
// surface (box SDF = −r within 1e-5 m), centres at least 0.75 spacing apart, every point of
// the cube's surface within one granule diameter (2 r) of a centre, and the count near a
// hexagonal layer's on the inner box.
TEST(MeshSdf, CubeShellOnTheInsetSurfaceWithoutHoles) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  cube(0.5, v, t);
  const std::string path = temp_path("cube.obj");
  write_obj(path, v, t);
  const RigidShape s = load_body(path);
  auto sdf = MeshSdf::create(s.vertices, s.triangles, path);
  ASSERT_TRUE(sdf.ok());
  MeshShellStats st;
  const auto t0 = std::chrono::steady_clock::now();
  auto pts = sample_mesh_shell(*sdf, kSpacing, kR, 100000, &st);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(pts.ok()) << pts.message();
  double worst_depth = 0;
  for (const auto& p : *pts) worst_depth = std::max(worst_depth, std::abs(box_sdf(p.cast<double>(), 0.25) + kR));
  EXPECT_LT(worst_depth, 1e-5);
  EXPECT_EQ(st.thin, 0);
  const double cover = coverage(cube_surface(0.5, 60), *pts);
  const double gap = min_neighbour(*pts);
  EXPECT_LT(cover, 2 * kR);
  EXPECT_GT(gap, 0.75 * kSpacing - 1e-6);
  const double inner = 6 * std::pow(0.5 - 2 * kR, 2), hex = inner / (kSpacing * kSpacing * 0.8660254);
  EXPECT_GT(pts->size(), 0.7 * hex);
  EXPECT_LT(pts->size(), 1.3 * hex);
  std::printf("cube shell: %zu spheres (hexagonal layer: %.0f), coverage %.3f r, nearest %.3f spacing, depth error %.2g m,"
              " %lld of %lld grid nodes queried, %.0f ms\n",
              pts->size(), hex, cover / kR, gap / kSpacing, worst_depth, st.queried, st.grid_nodes, ms);
}

// Sphere shell: every centre at R − r from the centre within the tessellation sagitta, the
// sphere's surface covered within 2 r, centres at least 0.75 spacing apart; the same points
// with 1 and 2 threads.
TEST(MeshSdf, SphereShellOnTheInsetSurfaceWithoutHoles) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  icosphere(0.3, 4, v, t);
  const std::string path = temp_path("sphere.obj");
  write_obj(path, v, t);
  const RigidShape s = load_body(path);
  double sagitta = 0;
  for (const auto& f : t) sagitta = std::max(sagitta, 0.3 - ((v[f[0]] + v[f[1]] + v[f[2]]) / 3).norm());
  auto sdf = MeshSdf::create(s.vertices, s.triangles, path);
  ASSERT_TRUE(sdf.ok());
  omp_set_num_threads(1);
  auto one = sample_mesh_shell(*sdf, kSpacing, kR, 100000);
  omp_set_num_threads(2);
  const auto t0 = std::chrono::steady_clock::now();
  auto pts = sample_mesh_shell(*sdf, kSpacing, kR, 100000);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(pts.ok() && one.ok());
  ASSERT_EQ(one->size(), pts->size());
  for (std::size_t i = 0; i < pts->size(); ++i) ASSERT_EQ((*one)[i], (*pts)[i]);
  double worst = 0;
  for (const auto& p : *pts) worst = std::max(worst, std::abs(double(p.norm()) - (0.3 - kR)));
  EXPECT_LT(worst, sagitta + 1e-5);
  const double cover = coverage(sphere_surface(0.3, 40), *pts);
  EXPECT_LT(cover, 2 * kR);
  EXPECT_GT(min_neighbour(*pts), 0.75 * kSpacing - 1e-6);
  const double hex = 4 * kPi * std::pow(0.3 - kR, 2) / (kSpacing * kSpacing * 0.8660254);
  EXPECT_GT(pts->size(), 0.7 * hex);
  EXPECT_LT(pts->size(), 1.3 * hex);
  std::printf("sphere shell: %zu spheres (hexagonal layer: %.0f), coverage %.3f r, radius error %.2g m (sagitta %.2g m), %.0f ms\n",
              pts->size(), hex, cover / kR, worst, sagitta, ms);
}

// A plate thinner than 2 r: the centres sit at half its thickness (flagged thin), inside it.
TEST(MeshSdf, ThinPlateCentresAtHalfThickness) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  cube(1.0, v, t);
  for (auto& p : v) p = Eigen::Vector3d(0.4 * p.x(), 0.03 * p.y(), 0.4 * p.z());  // 0.4 × 0.03 × 0.4 m
  RigidShape s;
  for (const auto& p : v) s.vertices.push_back(p.cast<float>());
  s.triangles = t;
  auto sdf = MeshSdf::create(s.vertices, s.triangles);
  ASSERT_TRUE(sdf.ok()) << sdf.message();
  MeshShellStats st;
  auto pts = sample_mesh_shell(*sdf, kSpacing, kR, 100000, &st);
  ASSERT_TRUE(pts.ok());
  EXPECT_GT(st.thin, 0);
  for (const auto& p : *pts) ASSERT_LE(std::abs(p.y()), 0.015f + 1e-5f) << p.transpose();
}

// Mass properties: the cube's tensor is m a²/6 on the diagonal (1e-9 relative), the
// icosphere's 2/5 m R² within 1 % (tessellation); Bullet gets them for mesh bodies (its own
// hull inertia would be the bounding box's, 2/3 m R² for the sphere).
TEST(MeshSdf, MeshMassPropertiesInBullet) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  cube(0.5, v, t);
  TriangleMesh c;
  for (const auto& p : v) c.vertices.push_back(p.cast<float>());
  c.triangles = t;
  const Eigen::Matrix3d Ic = c.inertia(10.0);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(Ic(i, j), i == j ? 10.0 * 0.25 / 6 : 0.0, 1e-9);

  icosphere(0.3, 4, v, t);
  TriangleMesh sm;
  for (const auto& p : v) sm.vertices.push_back(p.cast<float>());
  sm.triangles = t;
  const Eigen::Matrix3d Is = sm.inertia(10.0);
  const double ref = 0.4 * 10.0 * 0.09;
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(Is(i, i), ref, 0.01 * ref);

  HeightfieldDef hd;
  hd.samples_x = hd.samples_z = 9;
  hd.spacing = 1.0f;
  auto hf = Heightfield::create(hd);
  ASSERT_TRUE(hf.ok());
  auto world = BulletWorld::create(*hf, {0, -9.81f, 0});
  ASSERT_TRUE(world.ok());
  RigidBodyDef b;
  b.shape.kind = RigidShapeKind::Mesh;
  b.shape.vertices = sm.vertices;
  b.shape.triangles = sm.triangles;
  b.mass = 10.0f;
  b.position = {4, 2, 4};
  auto id = (*world)->add_body(b);
  ASSERT_TRUE(id.ok()) << id.message();
  EXPECT_FLOAT_EQ((*world)->mass(*id), 10.0f);
  const Eigen::Vector3f I = (*world)->principal_inertia(*id);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(I[i], Is(i, i), 1e-5 * ref);
  std::printf("icosphere inertia %.5f kg m^2 (solid sphere 2/5 m R^2 = %.5f)\n", Is(0, 0), ref);
}

// Bad meshes are refused naming the file and what is wrong: an open mesh (inside and outside
// undefined), a zero-area triangle, a NaN vertex (loader and direct), an inside-out mesh.
TEST(MeshSdf, BadMeshesNameTheFileAndTheProblem) {
  std::vector<Eigen::Vector3d> v;
  std::vector<std::array<int, 3>> t;
  cube(0.5, v, t);

  auto open = t;
  open.pop_back();
  const std::string open_path = temp_path("open_cube.obj");
  write_obj(open_path, v, open);
  auto m = load_obj_mesh(open_path);
  ASSERT_TRUE(m.ok());
  auto e = MeshSdf::create(m->vertices, m->triangles, open_path, "bodies[0].shape.file");
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().file, open_path);
  EXPECT_NE(e.message().find("not closed: 3 open edges"), std::string::npos) << e.message();

  // A sliver: the cube plus a vertex on the middle of an edge used by a zero-area triangle.
  auto dv = v;
  auto dt = t;
  dv.push_back(0.5 * (v[0] + v[1]));
  dt.push_back({0, 1, 8});
  const std::string deg_path = temp_path("sliver.obj");
  write_obj(deg_path, dv, dt);
  m = load_obj_mesh(deg_path);
  ASSERT_TRUE(m.ok());
  e = MeshSdf::create(m->vertices, m->triangles, deg_path);
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().file, deg_path);
  EXPECT_EQ(e.error().value, "triangle 13");
  EXPECT_NE(e.message().find("degenerate"), std::string::npos) << e.message();

  const std::string nan_path = temp_path("nan.obj");
  {
    std::ofstream f(nan_path);
    f << "v 0 0 0\nv 1 0 0\nv 0 1e999 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  }
  auto nm = load_obj_mesh(nan_path);
  ASSERT_FALSE(nm.ok());
  EXPECT_EQ(nm.error().file, nan_path);
  std::vector<Eigen::Vector3f> fv;
  for (const auto& p : v) fv.push_back(p.cast<float>());
  fv[3].y() = std::nanf("");
  e = MeshSdf::create(fv, t, "game.obj");
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.error().file, "game.obj");
  EXPECT_NE(e.message().find("vertex 4 is NaN"), std::string::npos) << e.message();

  auto flipped = t;
  for (auto& f : flipped) std::swap(f[1], f[2]);
  fv.clear();
  for (const auto& p : v) fv.push_back(p.cast<float>());
  e = MeshSdf::create(fv, flipped, "inside_out.obj");
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.message().find("inside out"), std::string::npos) << e.message();

  // Through sample_shell (no file known there): the field names the mesh.
  RigidShape s;
  s.kind = RigidShapeKind::Mesh;
  s.vertices = fv;
  s.triangles = open;
  auto sh = sample_shell(s, kSpacing, kR, 100000);
  ASSERT_FALSE(sh.ok());
  EXPECT_EQ(sh.error().field, "shape.mesh");
}
