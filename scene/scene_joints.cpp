// Scene files' joints: parsing and checks (see scene_joints.hpp, docs/scene-format.md "joints").
#include "scene/scene_joints.hpp"

#include <Eigen/Geometry>
#include <cmath>
#include <map>
#include <optional>
#include <set>

#include "scene/vehicle.hpp"

namespace sandpatch {

namespace {
const std::vector<std::string> kJointTypes = {"fixed", "hinge", "slider"};
const std::vector<std::string> kDriveWheels = {"rear", "front", "all"};
}  // namespace

const char* to_string(JointType t) { return kJointTypes[static_cast<int>(t)].c_str(); }
const char* to_string(api::DriveWheels d) { return kDriveWheels[static_cast<int>(d)].c_str(); }

namespace scene_json {
namespace {

constexpr double kMaxSpeed = 1e4;        // rad/s or m/s: velocity targets, servo speeds (as the library's)
constexpr double kMaxForce = 1e9;        // N m or N: a motor's most
constexpr double kMaxSpring = 1e12;      // N/m or N m/rad, N s/m or N m s/rad

// The phases at `key` of `o` (a joint's motor, a vehicle's throttle or steering): an array
// of at most kMaxMotorPhases elements, each given to `each(element, its path)`.
template <class F>
void for_each_phase(Ctx& c, Obj& o, const char* key, F&& each) {
  const json* pj = o.get(key);
  if (!pj) return;
  if (pj->is_array() && pj->size() > std::size_t(kMaxMotorPhases))
    c.error(o.at(key), std::to_string(pj->size()) + " phases", "at most " + std::to_string(kMaxMotorPhases) + " phases");
  else
    for_each_element(c, *pj, o.at(key), each);
}

// One motor phase of a joint of type `type` (docs/scene-format.md "joints").
MotorPhaseDef parse_phase(Ctx& c, const json& j, const std::string& path, JointType type) {
  MotorPhaseDef m;
  Obj o(c, j, path);
  const bool hinge = type == JointType::Hinge;
  o.number("from", m.from, closed(0.0, 1e6, "s"));
  m.until = o.number_opt("until", positive(1e6, "s"));
  if (m.until && !(*m.until > m.from))
    c.error(o.at("until"), show(*o.get("until")), "must be greater than 'from' (" + fmt_num(m.from) + " s)",
            "a phase drives the joint for from <= t < until");
  if (!o.both("target_velocity", "target_position")) {
    m.target_velocity = o.number_opt("target_velocity", closed(-kMaxSpeed, kMaxSpeed, hinge ? "rad/s" : "m/s"));
    m.target_position = o.number_opt("target_position", hinge ? closed(-kPi, kPi, "rad") : closed(-1e4, 1e4, "m"));
    if (o.valid() && !o.has("target_velocity") && !o.has("target_position"))
      c.missing(o.at("target_velocity"), hinge ? "'target_velocity' (rad/s) or 'target_position' (rad)"
                                               : "'target_velocity' (m/s) or 'target_position' (m)");
  }
  // A hinge's motor gives a torque, a slider's a force: the key says which.
  const char* key = hinge ? "max_torque" : "max_force";
  const char* other = hinge ? "max_force" : "max_torque";
  if (o.has(other))
    c.error(o.at(other), show(*o.get(other)),
            std::string("a ") + to_string(type) + "'s motor takes '" + key + "' (" + (hinge ? "N m" : "N") + ")");
  if (o.valid()) o.number_req(key, m.max_force, closed(0.0, kMaxForce, hinge ? "N m" : "N"));
  o.number("servo_speed", m.servo_speed, {0.0, kMaxSpeed, true, false, hinge ? "rad/s" : "m/s"});
  if (o.has("servo_speed") && !o.has("target_position"))
    c.error(o.at("servo_speed"), show(*o.get("servo_speed")), "only a servo (target_position) has a speed");
  o.finish();
  return m;
}

JointDef parse_joint(Ctx& c, const json& j, const std::string& path) {
  JointDef d;
  Obj o(c, j, path);
  o.string_req("name", d.name, "a unique name");
  o.enumeration_req("type", d.type, kJointTypes);
  o.string_req("body_a", d.body_a, "the name of a body");
  o.string("body_b", d.body_b);
  o.vec3_req("anchor", d.anchor, closed(-1e7, 1e7, "m"));
  const bool fixed = d.type == JointType::Fixed, hinge = d.type == JointType::Hinge;
  if (fixed) {
    for (const char* key : {"axis", "limits", "spring", "motor"})
      if (o.has(key)) c.error(o.at(key), show(*o.get(key)), "leave it out: a fixed joint does not move");
    o.finish();
    return d;
  }
  if (o.has("axis")) {
    o.vec3("axis", d.axis, closed(-1e6, 1e6, ""));
    if (o.valid() && std::sqrt(d.axis[0] * d.axis[0] + d.axis[1] * d.axis[1] + d.axis[2] * d.axis[2]) < 1e-6)
      c.error(o.at("axis"), show(*o.get("axis")), "must be a non-zero direction (world)");
  }
  if (const json* l = o.get("limits")) {
    const Range r = hinge ? closed(-kPi, kPi, "rad") : closed(-1e4, 1e4, "m");
    if (auto v = read_numbers<2>(c, *l, o.at("limits"), r)) {
      if ((*v)[0] > (*v)[1])
        c.error(o.at("limits"), show(*l), "[lower, upper] with lower <= upper", "the lower limit is above the upper");
      else
        d.limits = *v;
    }
  }
  if (const json* sj = o.get("spring")) {
    Obj sp(c, *sj, o.at("spring"));
    sp.number("stiffness", d.spring_stiffness, closed(0.0, kMaxSpring, hinge ? "N m/rad" : "N/m"));
    sp.number("damping", d.spring_damping, closed(0.0, kMaxSpring, hinge ? "N m s/rad" : "N s/m"));
    sp.finish();
  }
  for_each_phase(c, o, "motor", [&](const json& e, const std::string& p) { d.motor.push_back(parse_phase(c, e, p, d.type)); });
  o.finish();
  return d;
}

}  // namespace

std::vector<JointDef> parse_joints(Ctx& c, const json& j) {
  std::vector<JointDef> out;
  if (j.is_array() && j.size() > std::size_t(kMaxJoints)) {
    c.error("joints", std::to_string(j.size()) + " joints", "at most " + std::to_string(kMaxJoints) + " joints");
    return out;
  }
  for_each_element(c, j, "joints", [&](const json& e, const std::string& p) { out.push_back(parse_joint(c, e, p)); });
  return out;
}

namespace {

// The orientation of `o`: "orientation" (a unit quaternion [w, x, y, z]) or "euler_deg"
// [α, β, γ] (R = Rz(γ)·Ry(β)·Rx(α)), as a body's pose.
api::Quat read_orientation(Ctx& c, Obj& o) {
  api::Quat q = {1, 0, 0, 0};
  if (o.both("orientation", "euler_deg")) return q;
  if (const json* j = o.get("orientation")) {
    if (auto v = read_numbers<4>(c, *j, o.at("orientation"), closed(-1.0 - 1e-3, 1.0 + 1e-3, ""))) {
      const double n = std::sqrt((*v)[0] * (*v)[0] + (*v)[1] * (*v)[1] + (*v)[2] * (*v)[2] + (*v)[3] * (*v)[3]);
      if (std::abs(n - 1.0) > 1e-3)
        c.error(o.at("orientation"), show(*j), "must be a unit quaternion [w, x, y, z] (|q| = 1 ± 0.001)", "|q| = " + fmt_num(n));
      else
        q = {float((*v)[0] / n), float((*v)[1] / n), float((*v)[2] / n), float((*v)[3] / n)};
    }
  }
  if (const json* j = o.get("euler_deg")) {
    if (auto e = read_numbers<3>(c, *j, o.at("euler_deg"), closed(-720.0, 720.0, "deg"))) {
      const double r = kPi / 180.0;
      const Eigen::Quaterniond e_q = Eigen::AngleAxisd((*e)[2] * r, Eigen::Vector3d::UnitZ()) *
                                     Eigen::AngleAxisd((*e)[1] * r, Eigen::Vector3d::UnitY()) *
                                     Eigen::AngleAxisd((*e)[0] * r, Eigen::Vector3d::UnitX());
      q = {float(e_q.w()), float(e_q.x()), float(e_q.y()), float(e_q.z())};
    }
  }
  return q;
}

// from / until of a phase (as a load's).
void read_span(Ctx& c, Obj& o, double& from, std::optional<double>& until) {
  o.number("from", from, closed(0.0, 1e6, "s"));
  until = o.number_opt("until", positive(1e6, "s"));
  if (until && !(*until > from))
    c.error(o.at("until"), show(*o.get("until")), "must be greater than 'from' (" + fmt_num(from) + " s)",
            "a phase holds for from <= t < until");
}

VehicleSceneDef parse_vehicle(Ctx& c, const json& j, const std::string& path) {
  VehicleSceneDef s;
  api::VehicleDef& v = s.def;
  Obj o(c, j, path);
  o.string_req("name", v.name, "a unique name");
  Vec3d p = {v.position[0], v.position[1], v.position[2]};
  if (o.vec3_req("position", p, closed(-1e7, 1e7, "m"))) v.position = {p[0], p[1], p[2]};
  v.orientation = read_orientation(c, o);
  // Numbers are read as any finite value here; check_vehicle (the library's check) names the
  // ranges.
  const Range any = closed(-1e300, 1e300, "");
  Vec3d h = v.chassis_half_extents;
  o.vec3("chassis_half_extents", h, any);
  v.chassis_half_extents = h;
  for (auto [key, field] : {std::pair{"chassis_mass", &v.chassis_mass}, {"wheel_radius", &v.wheel_radius},
                            {"wheel_width", &v.wheel_width}, {"wheel_mass", &v.wheel_mass},
                            {"wheel_friction", &v.wheel_friction}, {"wheel_rolling_friction", &v.wheel_rolling_friction},
                            {"wheelbase", &v.wheelbase}, {"track", &v.track}, {"axle_height", &v.axle_height},
                            {"wheel_speed", &v.wheel_speed}, {"max_torque", &v.max_torque},
                            {"steering_angle", &v.steering_angle}, {"max_steering_angle", &v.max_steering_angle},
                            {"steering_speed", &v.steering_speed},
                            {"suspension_stiffness", &v.suspension_stiffness}, {"suspension_damping", &v.suspension_damping},
                            {"suspension_travel", &v.suspension_travel}})
    o.number(key, *field, any);
  o.enumeration("drive", v.drive, kDriveWheels);
  for_each_phase(c, o, "throttle", [&](const json& e, const std::string& pp) {
    ThrottlePhaseDef t;
    Obj po(c, e, pp);
    read_span(c, po, t.from, t.until);
    po.number_req("wheel_speed", t.wheel_speed, closed(-1e4, 1e4, "rad/s"));
    po.number_req("max_torque", t.max_torque, closed(0.0, 1e9, "N m"));
    po.finish();
    s.throttle.push_back(t);
  });
  for_each_phase(c, o, "steering", [&](const json& e, const std::string& pp) {
    SteeringPhaseDef t;
    Obj po(c, e, pp);
    read_span(c, po, t.from, t.until);
    po.number_req("angle", t.angle, closed(-1.2, 1.2, "rad"));
    po.finish();
    s.steering.push_back(t);
  });
  o.finish();
  if (o.valid()) {
    for (Error& e : check_vehicle(v, path + ".")) c.error(e.field, e.value, e.allowed, e.detail);
    for (std::size_t k = 0; k < s.steering.size(); ++k)
      if (std::isfinite(v.max_steering_angle) && std::abs(s.steering[k].angle) > v.max_steering_angle)
        c.error(path + ".steering[" + std::to_string(k) + "].angle", fmt_num(s.steering[k].angle),
                "must be within ±max_steering_angle (" + fmt_num(v.max_steering_angle) + " rad)");
  }
  return s;
}

}  // namespace

std::vector<VehicleSceneDef> parse_vehicles(Ctx& c, const json& j) {
  std::vector<VehicleSceneDef> out;
  if (j.is_array() && j.size() > 256) {
    c.error("vehicles", std::to_string(j.size()) + " vehicles", "at most 256 vehicles");
    return out;
  }
  for_each_element(c, j, "vehicles", [&](const json& e, const std::string& p) { out.push_back(parse_vehicle(c, e, p)); });
  return out;
}

void check_joints(Ctx& c, const SceneDef& s) {
  // Every body by name: the scene's, then the vehicles' parts (dynamic), each name once.
  std::vector<std::string> names;
  std::map<std::string, MotionKind> motion;
  for (const BodyDef& b : s.bodies) {
    names.push_back(b.name);
    motion.emplace(b.name, b.motion);
  }
  std::set<std::string> vehicle_names;
  for (std::size_t i = 0; i < s.vehicles.size(); ++i) {
    const std::string at = "vehicles[" + std::to_string(i) + "].name";
    if (!vehicle_names.insert(s.vehicles[i].def.name).second)
      c.error(at, json_quote(s.vehicles[i].def.name), "must be unique among vehicles");
    for (const std::string& n : vehicle_body_names(s.vehicles[i].def.name)) {
      if (motion.count(n)) c.error(at, json_quote(s.vehicles[i].def.name), "its part '" + n + "' has the name of a body: rename one");
      names.push_back(n);
      motion.emplace(n, MotionKind::Dynamic);
    }
  }
  struct Found {
    MotionKind motion;
  };
  auto find = [&](const std::string& n) -> std::optional<Found> {
    const auto it = motion.find(n);
    if (it == motion.end()) return std::nullopt;
    return Found{it->second};
  };
  std::set<std::string> seen;
  for (std::size_t i = 0; i < s.joints.size(); ++i) {
    const JointDef& j = s.joints[i];
    const std::string at = "joints[" + std::to_string(i) + "]";
    if (!j.name.empty() && !seen.insert(j.name).second)
      c.error(at + ".name", json_quote(j.name), "must be unique among joints");
    const auto a = j.body_a.empty() ? std::nullopt : find(j.body_a);
    const auto b = j.body_b.empty() ? std::nullopt : find(j.body_b);
    if (!j.body_a.empty() && !a)
      c.error(at + ".body_a", json_quote(j.body_a), "must name a body: " + join(names), did_you_mean(j.body_a, names));
    if (!j.body_b.empty() && !b)
      c.error(at + ".body_b", json_quote(j.body_b), "must name a body (or be left out: the world): " + join(names),
              did_you_mean(j.body_b, names));
    if (!j.body_b.empty() && j.body_a == j.body_b)
      c.error(at + ".body_b", json_quote(j.body_b),
              "must not be body_a: a joint connects two bodies (or body_a and the world: leave body_b out)");
    else if (a && (j.body_b.empty() || b) && a->motion != MotionKind::Dynamic && (!b || b->motion != MotionKind::Dynamic))
      c.error(at + (b ? ".body_b" : ".body_a"), json_quote(b ? j.body_b : j.body_a),
              "at least one side of a joint must be a dynamic body: nothing a joint does moves a kinematic or static body",
              "'" + j.body_a + "' is " + to_string(a->motion) + (b ? ", '" + j.body_b + "' is " + to_string(b->motion) : ", the other side the world"));
  }
}

}  // namespace scene_json
}  // namespace sandpatch
