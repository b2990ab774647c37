// Scene files' joints: parsing and checks (see scene_joints.hpp, docs/scene-format.md "joints").
#include "scene/scene_joints.hpp"

#include <cmath>
#include <map>
#include <optional>
#include <set>


namespace sandpatch {

namespace {
const std::vector<std::string> kJointTypes = {"fixed", "hinge", "slider"};
}  // namespace

const char* to_string(JointType t) { return kJointTypes[static_cast<int>(t)].c_str(); }

namespace scene_json {
namespace {

constexpr double kMaxSpeed = 1e4;        // rad/s or m/s: velocity targets, servo speeds (as the library's)
constexpr double kMaxForce = 1e9;        // N m or N: a motor's most
constexpr double kMaxSpring = 1e12;      // N/m or N m/rad, N s/m or N m s/rad

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
  if (const json* mj = o.get("motor")) {
    if (mj->is_array() && mj->size() > std::size_t(kMaxMotorPhases))
      c.error(o.at("motor"), std::to_string(mj->size()) + " phases", "at most " + std::to_string(kMaxMotorPhases) + " phases");
    else
      for_each_element(c, *mj, o.at("motor"),
                       [&](const json& e, const std::string& p) { d.motor.push_back(parse_phase(c, e, p, d.type)); });
  }
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

void check_joints(Ctx& c, const SceneDef& s) {
  // Every body by name.
  std::vector<std::string> names;
  std::map<std::string, MotionKind> motion;
  for (const BodyDef& b : s.bodies) {
    names.push_back(b.name);
    motion.emplace(b.name, b.motion);
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
