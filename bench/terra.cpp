// The DEM tests of bench/terra.hpp: plate sinkage, grousered shear plate, driven wheel, each
// through the World on the bed of scenes/wheel_on_sand.json.
#include "bench/terra.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "manager/scene_world.hpp"
#include "manager/world.hpp"
#include "scene/scene.hpp"

namespace sandpatch::terra {

namespace {

constexpr double kG = 9.81;          // m/s^2
constexpr double kMargin = 0.5;      // m of bed beyond a test body's travel on every side
constexpr double kRigApron = 0.25;   // m, the LOD apron in the rig (the requested bed covers it)
constexpr double kFillWait = 0.1;    // s after the patch is ready before a test starts
constexpr long long kMaxFrames = 20000;

Error setup_error(const std::string& field, double v, const std::string& allowed) {
  return Error{"", field, std::to_string(v), allowed, ""};
}

// A World over the scene's terrain with no scene bodies, and a patch requested over the
// rectangle [x0, x1] x [z0, z1] (m, world): the bed every test runs in.
struct Rig {
  SceneDef scene;
  std::unique_ptr<World> world;
  double rs = 0;       // m, shell sphere radius (the granule sphere radius: particle scale 1)
  double dt = 0;       // s, frame
  std::chrono::steady_clock::time_point wall0;
  double wall() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count(); }
};

Result<SceneDef> load_base(const RigSetup& s) {
  if (!(s.bed_depth == 0 || (s.bed_depth >= 0.1 && s.bed_depth <= 2.0)))
    return setup_error("RigSetup.bed_depth", s.bed_depth, "0 (the scene's) or in [0.1, 2] m");
  auto sc = load_scene_file(s.scene);
  if (!sc) return sc.errors();
  return sc;
}

Result<Rig> make_rig(SceneDef scene, const RigSetup& s, double x0, double z0, double x1, double z1) {
  Rig rig;
  rig.wall0 = std::chrono::steady_clock::now();
  scene.bodies.clear();
  scene.joints.clear();  // the tests add their own bodies and joints
  scene.terrain.lod_apron = kRigApron;
  scene.terrain.threads = s.threads;
  if (s.bed_depth > 0) {
    scene.terrain.patch_depth = s.bed_depth;
    scene.terrain.soil_depth = std::max(scene.terrain.soil_depth, s.bed_depth + 0.5);
  }
  const MaterialDef* mat = scene.find_material(scene.terrain.material_name);
  if (!mat && !scene.materials.empty()) mat = &scene.materials.front();
  if (!mat) return Error{s.scene, "materials", "none", "the bed's material", ""};
  rig.rs = mat->granule_radius;
  rig.dt = scene.simulation.dt;
  rig.scene = scene;
  auto w = make_world(rig.scene, s.threads, "cpu");
  if (!w) return w.errors();
  rig.world = std::move(w.value());
  if (!rig.world->manager()) return Error{s.scene, "simulation", "patches off", "granular patches on", ""};
  rig.world->manager()->request_patch(x0, z0, x1, z1, 0.0);
  return rig;
}

bool patch_ready(const Rig& r) { return r.world->manager()->ready_patches() > 0; }

// The grousered plate: the profile (x, y) of a bar [-L/2, L/2] x [0, t] with `blades` blades
// [x_k, x_k + g] x [-h, 0] under it (the outer ones flush with the ends), extruded over z in
// [-w/2, w/2]; ear-clipped caps. A closed, outward-oriented mesh, centred on its centroid.
RigidShape comb_mesh(double L, double w, double t, int blades, double h, double g) {
  std::vector<Eigen::Vector2d> poly;  // counter-clockwise seen from +z
  poly.push_back({-L / 2, t});
  for (int k = 0; k < blades; ++k) {
    const double xl = -L / 2 + (L - g) * double(k) / double(blades - 1);
    if (k > 0) poly.push_back({xl, 0});
    poly.push_back({xl, -h});
    poly.push_back({xl + g, -h});
    if (k + 1 < blades) poly.push_back({xl + g, 0});
  }
  poly.push_back({L / 2, t});
  // centroid of the polygon
  double A = 0, cx = 0, cy = 0;
  for (std::size_t i = 0; i < poly.size(); ++i) {
    const auto& p = poly[i];
    const auto& q = poly[(i + 1) % poly.size()];
    const double cr = p.x() * q.y() - q.x() * p.y();
    A += cr;
    cx += (p.x() + q.x()) * cr;
    cy += (p.y() + q.y()) * cr;
  }
  A *= 0.5;
  cx /= 6 * A;
  cy /= 6 * A;
  for (auto& p : poly) p -= Eigen::Vector2d(cx, cy);
  // ear clipping
  auto cross = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
    return (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
  };
  std::vector<int> idx(poly.size());
  for (std::size_t i = 0; i < poly.size(); ++i) idx[i] = int(i);
  std::vector<std::array<int, 3>> cap;
  while (idx.size() > 3) {
    bool clipped = false;
    for (std::size_t i = 0; i < idx.size(); ++i) {
      const int a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i], c = idx[(i + 1) % idx.size()];
      if (cross(poly[a], poly[b], poly[c]) <= 1e-12) continue;  // reflex or flat
      bool inside = false;
      for (int k : idx) {
        if (k == a || k == b || k == c) continue;
        if (cross(poly[a], poly[b], poly[k]) >= 0 && cross(poly[b], poly[c], poly[k]) >= 0 &&
            cross(poly[c], poly[a], poly[k]) >= 0) {
          inside = true;
          break;
        }
      }
      if (inside) continue;
      cap.push_back({a, b, c});
      idx.erase(idx.begin() + long(i));
      clipped = true;
      break;
    }
    if (!clipped) break;  // cannot happen for a simple polygon
  }
  if (idx.size() == 3) cap.push_back({idx[0], idx[1], idx[2]});
  RigidShape s;
  s.kind = RigidShapeKind::Mesh;
  const int n = int(poly.size());
  for (const auto& p : poly) s.vertices.push_back(Eigen::Vector3f(float(p.x()), float(p.y()), float(0.5 * w)));
  for (const auto& p : poly) s.vertices.push_back(Eigen::Vector3f(float(p.x()), float(p.y()), float(-0.5 * w)));
  for (const auto& tri : cap) {
    s.triangles.push_back({tri[0], tri[1], tri[2]});              // front (+z)
    s.triangles.push_back({n + tri[0], n + tri[2], n + tri[1]});  // back (-z)
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    s.triangles.push_back({i, n + i, n + j});
    s.triangles.push_back({i, n + j, j});
  }
  return s;
}

// Holds a dynamic body's z, tilt and spin before a frame; x velocity `vx` and spin `wz` about
// z (rad/s) set, y and its velocity free. `q` the orientation to set.
void hold(World& w, RigidBodyId id, double z, const Eigen::Quaternionf& q, double vx, double wz) {
  BodyState st = w.bullet().state(id);
  st.position.z() = z;
  st.orientation = q;
  st.linear_velocity = Eigen::Vector3f(float(vx), st.linear_velocity.y(), 0.0f);
  st.angular_velocity = Eigen::Vector3f(0.0f, 0.0f, float(wz));
  w.bullet().set_state(id, st);
}

// Holds a dynamic body at `pos` until its patch carries it: a body lying still on the
// heightfield is not taken up by a new patch (manager/coupling.cpp), so it is given a downward
// velocity faster than that rule's 10 sleep speeds and put back every frame.
void hold_for_patch(World& w, RigidBodyId id, const Eigen::Vector3d& pos, const Eigen::Quaternionf& q) {
  BodyState st = w.bullet().state(id);
  st.position = pos;
  st.orientation = q;
  st.linear_velocity = Eigen::Vector3f(0, -0.15f, 0);
  st.angular_velocity.setZero();
  w.bullet().set_state(id, st);
}

// Zeroes a body's velocities (the first frame after hold_for_patch).
void stop(World& w, RigidBodyId id) {
  BodyState st = w.bullet().state(id);
  st.linear_velocity.setZero();
  st.angular_velocity.setZero();
  w.bullet().set_state(id, st);
}

}  // namespace

Result<PlateRun> run_plate(const RigSetup& s, const PlateDef& d) {
  if (!(d.width >= 0.1 && d.width <= 1.5)) return setup_error("PlateDef.width", d.width, "in [0.1, 1.5] m");
  if (!(d.speed > 0 && d.speed <= 0.5)) return setup_error("PlateDef.speed", d.speed, "in (0, 0.5] m/s");
  if (!(d.depth > 0 && d.depth <= 0.4)) return setup_error("PlateDef.depth", d.depth, "in (0, 0.4] m");
  auto base = load_base(s);
  if (!base) return base.errors();
  const double half = 0.5 * d.width + kMargin;
  auto rr = make_rig(base.value(), s, -half, -half, half, half);
  if (!rr) return rr.errors();
  Rig& rig = rr.value();
  World& w = *rig.world;
  const double rs = rig.rs, dt = rig.dt;
  const double b_box = d.width - 2 * rs;  // the soil sees the box grown by one shell sphere radius
  if (!(b_box > 0)) return setup_error("PlateDef.width", d.width, "wider than two granule sphere radii");
  const double ht = 0.03, gap = 0.02;     // m: half thickness, soil-seen bottom above the surface at the start
  RigidBodyDef bd;
  bd.name = "plate";
  bd.motion = RigidMotion::Kinematic;
  bd.shape.kind = RigidShapeKind::Box;
  bd.shape.half_extents = Eigen::Vector3f(float(0.5 * b_box), float(ht), float(0.5 * b_box));
  const double surface = w.original_height(0, 0);
  const double y0 = surface + gap + rs + ht;
  bd.position = Eigen::Vector3d(0, y0, 0);
  auto id = w.add_body(bd);
  if (!id) return id.errors();
  PlateRun out;
  out.curve.width = d.width;
  double t_press = -1, y = y0;
  for (long long f = 0; f < kMaxFrames; ++f) {
    const double t = w.time();
    if (t_press < 0 && patch_ready(rig) && t > kFillWait) t_press = t + kFillWait;
    if (t_press >= 0 && t + dt > t_press) y = y0 - d.speed * (t + dt - t_press);
    if (Status st = w.set_kinematic_target(id.value(), Eigen::Vector3d(0, y, 0), Eigen::Quaternionf::Identity()); !st)
      return st.errors();
    if (Status st = w.step(dt); !st) return st.errors();
    const World::Contact c = w.contact(id.value());
    const double z_mid = c.sinkage + rs - 0.5 * d.speed * dt * (t_press >= 0 ? 1 : 0);
    if (t_press >= 0 && c.granular.carried && w.time() > t_press) {
      out.t.push_back(w.time());
      out.curve.z.push_back(z_mid);
      out.curve.p.push_back(double(c.granular.force.y()) / (d.width * d.width));
    }
    if (t_press >= 0 && c.sinkage + rs >= d.depth) break;
  }
  out.granules = w.peak_granules();
  out.simulated_s = w.time();
  out.wall_s = rig.wall();
  return out;
}

Result<ShearRun> run_shear(const RigSetup& s, const ShearDef& d) {
  if (!(d.sigma >= 100 && d.sigma <= 1e5)) return setup_error("ShearDef.sigma", d.sigma, "in [100, 1e5] Pa");
  if (!(d.length >= 0.2 && d.length <= 1.5)) return setup_error("ShearDef.length", d.length, "in [0.2, 1.5] m");
  if (!(d.width >= 0.1 && d.width <= 1.5)) return setup_error("ShearDef.width", d.width, "in [0.1, 1.5] m");
  if (d.blades < 2 || d.blades > 16) return setup_error("ShearDef.blades", d.blades, "in [2, 16]");
  if (!(d.blade_depth > 0 && d.blade_depth <= 0.2)) return setup_error("ShearDef.blade_depth", d.blade_depth, "in (0, 0.2] m");
  if (!(d.blade_thickness > 0 && d.blade_thickness * d.blades < d.length))
    return setup_error("ShearDef.blade_thickness", d.blade_thickness, "> 0 m, blades x thickness < length");
  if (!(d.speed > 0 && d.speed <= 1)) return setup_error("ShearDef.speed", d.speed, "in (0, 1] m/s");
  if (!(d.travel > 0 && d.travel <= 1)) return setup_error("ShearDef.travel", d.travel, "in (0, 1] m");
  if (!(d.settle >= 0 && d.settle <= 5)) return setup_error("ShearDef.settle", d.settle, "in [0, 5] s");
  auto base = load_base(s);
  if (!base) return base.errors();
  const double x_start = -0.5 * d.travel;
  auto rr = make_rig(base.value(), s, x_start - 0.5 * d.length - kMargin, -0.5 * d.width - kMargin,
                     x_start + 0.5 * d.length + d.travel + kMargin, 0.5 * d.width + kMargin);
  if (!rr) return rr.errors();
  Rig& rig = rr.value();
  World& w = *rig.world;
  const double dt = rig.dt, area = d.length * d.width;
  const double bar = 0.04;  // m, bar thickness
  RigidBodyDef bd;
  bd.name = "shear_plate";
  bd.shape = comb_mesh(d.length, d.width, bar, d.blades, d.blade_depth, d.blade_thickness);
  bd.mass = float(d.sigma * area / kG);
  // the bar's underside on the surface, the blades in the soil (the fill leaves room for them)
  float ymin = 1e9f;
  for (const auto& v : bd.shape.vertices) ymin = std::min(ymin, v.y());
  const double surface = w.original_height(x_start, 0);
  const double y0 = surface - d.blade_depth - double(ymin);
  bd.position = Eigen::Vector3d(x_start, y0, 0);
  auto id = w.add_body(bd);
  if (!id) return id.errors();
  const Eigen::Quaternionf q = Eigen::Quaternionf::Identity();
  ShearRun out;
  out.curve.sigma = d.sigma;
  double t_release = -1, t_drag = -1, x0 = 0, fy = 0;
  int nfy = 0;
  for (long long f = 0; f < kMaxFrames; ++f) {
    const double t = w.time();
    if (t_release < 0) {
      hold_for_patch(w, id.value(), Eigen::Vector3d(x_start, y0, 0), q);
      if (patch_ready(rig) && w.contact(id.value()).granular.carried) {
        t_release = t;
        stop(w, id.value());
      }
    } else if (t < t_release + d.settle) {
      hold(w, id.value(), 0, q, 0, 0);
    } else {
      if (t_drag < 0) {
        t_drag = t;
        x0 = w.bullet().state(id.value()).position.x();
        out.blade_sinkage = w.contact(id.value()).sinkage;
      }
      hold(w, id.value(), 0, q, d.speed, 0);
    }
    if (Status st = w.step(dt); !st) return st.errors();
    if (t_drag >= 0) {
      const World::Contact c = w.contact(id.value());
      const double x = w.bullet().state(id.value()).position.x();
      out.t.push_back(w.time());
      out.curve.j.push_back(x - x0);
      out.curve.tau.push_back(-double(c.granular.force.x()) / area);
      out.sink.push_back(c.sinkage);
      fy += c.granular.force.y();
      ++nfy;
      if (x - x0 >= d.travel) break;
    }
  }
  if (nfy > 0) out.curve.sigma = fy / nfy / area;
  out.granules = w.peak_granules();
  out.simulated_s = w.time();
  out.wall_s = rig.wall();
  return out;
}

Result<WheelRun> run_wheel(const RigSetup& s, const WheelDef& d) {
  if (!(d.slip >= 0 && d.slip <= 0.9)) return setup_error("WheelDef.slip", d.slip, "in [0, 0.9]");
  if (!(d.speed > 0 && d.speed <= 2)) return setup_error("WheelDef.speed", d.speed, "in (0, 2] m/s");
  if (!(d.settle >= 0 && d.settle <= 5)) return setup_error("WheelDef.settle", d.settle, "in [0, 5] s");
  if (!(d.drive > 0 && d.drive <= 10)) return setup_error("WheelDef.drive", d.drive, "in (0, 10] s");
  if (!(d.window_from >= 0 && d.window_from < d.drive))
    return setup_error("WheelDef.window_from", d.window_from, "in [0, drive) s");
  auto base = load_base(s);
  if (!base) return base.errors();
  const SceneDef& sc = base.value();
  std::size_t wi = sc.bodies.size();
  for (std::size_t i = 0; i < sc.bodies.size(); ++i)
    if (sc.bodies[i].name == "wheel") wi = i;
  if (wi == sc.bodies.size()) return Error{s.scene, "bodies", "no body named 'wheel'", "the rig's wheel", ""};
  if (sc.bodies[wi].shape.kind != ShapeKind::Cylinder || sc.bodies[wi].motion != MotionKind::Dynamic)
    return Error{s.scene, "bodies[" + std::to_string(wi) + "]", sc.bodies[wi].name, "a dynamic cylinder", ""};
  auto bd = to_rigid_body(sc, wi);
  if (!bd) return bd.errors();
  // The jointed rig (scenes/wheel_on_sand.json): a kinematic "carriage", a vertical "slider"
  // joint to a dynamic "hub", a hinge "axle" from the hub to the wheel with a velocity motor.
  // Without them the wheel alone, its velocities set before every frame.
  auto body_index = [&](const std::string& name) {
    for (std::size_t i = 0; i < sc.bodies.size(); ++i)
      if (sc.bodies[i].name == name) return i;
    return sc.bodies.size();
  };
  auto joint_index = [&](const std::string& name) {
    for (std::size_t i = 0; i < sc.joints.size(); ++i)
      if (sc.joints[i].name == name) return i;
    return sc.joints.size();
  };
  const std::size_t ci = body_index("carriage"), hi = body_index("hub");
  const std::size_t si = joint_index("slider"), ai = joint_index("axle");
  const bool jointed = ci < sc.bodies.size() && hi < sc.bodies.size() && si < sc.joints.size() && ai < sc.joints.size();
  const Eigen::Vector3d p0 = bd.value().position;
  const double travel = d.speed * d.drive;
  const double R = sc.bodies[wi].shape.radius, half_w = 0.5 * sc.bodies[wi].shape.height;
  auto rr = make_rig(sc, s, p0.x() - R - kMargin, p0.z() - half_w - kMargin, p0.x() + R + travel + kMargin,
                     p0.z() + half_w + kMargin);
  if (!rr) return rr.errors();
  Rig& rig = rr.value();
  World& w = *rig.world;
  const double dt = rig.dt, rs = rig.rs;
  const double r_eff = R + rs;  // the soil sees the rim one shell sphere radius out
  const double omega = d.speed / (r_eff * (1.0 - d.slip));
  auto id = w.add_body(bd.value());
  if (!id) return id.errors();
  const Eigen::Quaternionf q0 = bd.value().orientation.normalized();
  WheelRun out;
  out.slip_cmd = d.slip;
  out.load = double(bd.value().mass) * kG;
  out.soil_seen.radius = r_eff;
  out.soil_seen.width = 2 * half_w + 2 * rs;
  out.jointed = jointed;
  RigidBodyId carriage, hub;
  JointId axle;
  Eigen::Vector3d c0 = Eigen::Vector3d::Zero(), h0 = Eigen::Vector3d::Zero();
  Eigen::Quaternionf hq = Eigen::Quaternionf::Identity();
  float spin_sign = -1.0f;  // the motor's target for rolling towards +x
  if (jointed) {
    auto cd = to_rigid_body(sc, ci);
    if (!cd) return cd.errors();
    if (cd.value().motion != RigidMotion::Kinematic)
      return Error{s.scene, "bodies[" + std::to_string(ci) + "].motion", "not kinematic", "the carriage is kinematic", ""};
    if (!sc.bodies[ci].keyframes.empty()) {
      const auto& k = sc.bodies[ci].keyframes.front().position;
      cd.value().position = Eigen::Vector3d(k[0], k[1], k[2]);
    }
    c0 = cd.value().position;
    auto hd = to_rigid_body(sc, hi);
    if (!hd) return hd.errors();
    h0 = hd.value().position;
    hq = hd.value().orientation.normalized();
    auto cid = w.add_body(cd.value());
    if (!cid) return cid.errors();
    auto hid = w.add_body(hd.value());
    if (!hid) return hid.errors();
    carriage = cid.value();
    hub = hid.value();
    out.load += double(hd.value().mass) * kG;  // the slider carries no weight
    for (std::size_t j : {si, ai}) {
      RigidJointDef jd = to_rigid_joint(sc.joints[j]);
      jd.turn.motor = JointMotor{};
      jd.slide.motor = JointMotor{};
      auto idof = [&](const std::string& n) {
        return n == sc.bodies[ci].name ? carriage : n == sc.bodies[hi].name ? hub : n == sc.bodies[wi].name ? id.value() : RigidBodyId{};
      };
      jd.a = idof(sc.joints[j].body_a);
      jd.b = idof(sc.joints[j].body_b);
      if (!jd.a.valid() || (!sc.joints[j].body_b.empty() && !jd.b.valid()))
        return Error{s.scene, "joints[" + std::to_string(j) + "]", sc.joints[j].name, "joins carriage, hub and wheel", ""};
      auto jid = w.add_joint(jd);
      if (!jid) return jid.errors();
      if (j == ai) axle = jid.value();
    }
    // the hinge's axis along -z turns the wheel forward with a positive target
    spin_sign = sc.joints[ai].axis[2] < 0 ? 1.0f : -1.0f;
  }
  auto set_motor = [&](double target) -> Status {
    JointMotor m;
    m.mode = MotorMode::Velocity;
    m.target = float(target);
    m.max_force = 1e6f;  // N m: the motor holds its rate whatever the soil does
    return w.set_joint_motor(axle, true, m);
  };
  double t_release = -1, t_drive = -1, angle = 0;
  double sdp = 0, sdp2 = 0, ssk = 0, ssk2 = 0, stq = 0, sfy = 0, sx = 0, sw = 0;
  int n = 0;
  for (long long f = 0; f < kMaxFrames; ++f) {
    const double t = w.time();
    double wz = 0;
    if (t_release < 0) {
      hold_for_patch(w, id.value(), p0, q0);
      if (jointed) {
        hold_for_patch(w, hub, h0, hq);
        if (Status st = set_motor(0); !st) return st.errors();
      }
      if (patch_ready(rig) && w.contact(id.value()).granular.carried) {
        t_release = t;
        stop(w, id.value());
        if (jointed) stop(w, hub);
      }
    } else if (t < t_release + d.settle) {
      if (!jointed) hold(w, id.value(), p0.z(), q0, 0, 0);
    } else {
      if (t_drive < 0) {
        t_drive = t;
        if (jointed)
          if (Status st = set_motor(spin_sign * omega); !st) return st.errors();
      }
      wz = -omega;  // rolling towards +x about +z
      angle += wz * dt;
      if (!jointed)
        hold(w, id.value(), p0.z(), Eigen::Quaternionf(Eigen::AngleAxisf(float(angle - wz * dt), Eigen::Vector3f::UnitZ())) * q0,
             d.speed, wz);
    }
    if (jointed) {
      const double xc = c0.x() + (t_drive >= 0 ? d.speed * (t + dt - t_drive) : 0.0);
      if (Status st = w.set_kinematic_target(carriage, Eigen::Vector3d(xc, c0.y(), c0.z()), Eigen::Quaternionf::Identity()); !st)
        return st.errors();
    }
    const BodyState before = w.bullet().state(id.value());
    const double x_before = before.position.x(), w_before = std::abs(double(before.angular_velocity.z()));
    if (Status st = w.step(dt); !st) return st.errors();
    if (t_drive < 0) continue;
    const BodyState st = w.bullet().state(id.value());
    const World::Contact c = w.contact(id.value());
    const double td = w.time() - t_drive;
    out.t.push_back(td);
    out.x.push_back(st.position.x());
    out.dp.push_back(c.granular.force.x());
    out.sink.push_back(c.sinkage + rs);
    out.fy.push_back(c.granular.force.y());
    out.hf_fy.push_back(c.heightfield_force.y());
    if (td > d.window_from) {
      const double dp = c.granular.force.x(), sk = c.sinkage + rs;
      sdp += dp;
      sdp2 += dp * dp;
      ssk += sk;
      ssk2 += sk * sk;
      stq += c.granular.torque.z();  // about +z: the wheel spins about -z, so a resisting torque is > 0
      sfy += c.granular.force.y();
      sx += st.position.x() - x_before;
      sw += 0.5 * (w_before + std::abs(double(st.angular_velocity.z())));
      ++n;
    }
    if (td >= d.drive - 1e-9) break;
  }
  if (n < 2) return Error{s.scene, "WheelDef.drive", std::to_string(d.drive), "long enough for a window of frames", ""};
  out.drawbar_pull = sdp / n;
  out.drawbar_pull_sd = std::sqrt(std::max(0.0, sdp2 / n - out.drawbar_pull * out.drawbar_pull));
  out.sinkage = ssk / n;
  out.sinkage_sd = std::sqrt(std::max(0.0, ssk2 / n - out.sinkage * out.sinkage));
  out.torque = stq / n;  // the soil's torque about +z; with the wheel spinning at -omega a resisting torque is > 0
  out.vertical = sfy / n;
  out.slip = 1.0 - (sx / (n * dt)) / ((sw / n) * r_eff);
  out.granules = w.peak_granules();
  out.simulated_s = w.time();
  out.wall_s = rig.wall();
  return out;
}

}  // namespace sandpatch::terra
