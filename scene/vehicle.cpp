// The four-wheeled vehicle's one check and one expansion (see vehicle.hpp).
#include "scene/vehicle.hpp"

#include <Eigen/Geometry>
#include <cmath>

#include "common/knobs.hpp"
#include "common/limits.hpp"

namespace sandpatch {
namespace {

std::string num(double v) { return format_number(v); }

Eigen::Quaterniond quat(const api::Quat& q) {
  return Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized();
}

}  // namespace

std::vector<std::string> vehicle_body_names(const std::string& vehicle) {
  std::vector<std::string> out = {vehicle + ".chassis"};
  for (const char* t : kWheelTags) out.push_back(vehicle + ".wheel_" + t);
  return out;
}

std::vector<Error> check_vehicle(const api::VehicleDef& v, const std::string& prefix) {
  std::vector<Error> es;
  auto add = [&](const std::string& field, double value, const std::string& allowed, const std::string& detail = "") {
    es.push_back({"", prefix + field, num(value), allowed, detail});
  };
  // [lo, hi] (or (lo, hi] with open_lo); NaN and infinities fail.
  auto range = [&](const char* field, double x, double lo, double hi, bool open_lo, const char* unit) {
    const bool ok = std::isfinite(x) && (open_lo ? x > lo : x >= lo) && x <= hi;
    if (!ok) add(field, x, std::string("must be in ") + (open_lo ? "(" : "[") + num(lo) + ", " + num(hi) + "]" + (*unit ? " " : "") + unit);
    return ok;
  };
  for (int k = 0; k < 3; ++k)
    if (!std::isfinite(v.position[k]) || std::abs(v.position[k]) > 1e7) {
      es.push_back({"", prefix + "position", "[" + num(v.position[0]) + ", " + num(v.position[1]) + ", " + num(v.position[2]) + "]",
                    "must be finite, each coordinate within 1e7 (m, world)"});
      break;
    }
  const double qn = std::sqrt(double(v.orientation[0]) * v.orientation[0] + double(v.orientation[1]) * v.orientation[1] +
                              double(v.orientation[2]) * v.orientation[2] + double(v.orientation[3]) * v.orientation[3]);
  if (!std::isfinite(qn) || !(qn > 1e-6))
    es.push_back({"", prefix + "orientation",
                  "[" + num(v.orientation[0]) + ", " + num(v.orientation[1]) + ", " + num(v.orientation[2]) + ", " + num(v.orientation[3]) + "]",
                  "must be a finite, non-zero quaternion [w, x, y, z]"});
  bool sizes = true;
  for (int k = 0; k < 3; ++k)
    sizes &= range(("chassis_half_extents[" + std::to_string(k) + "]").c_str(), v.chassis_half_extents[k], 0, 1e4, true, "m");
  range("chassis_mass", v.chassis_mass, limits::kMinBodyMass, limits::kMaxBodyMass, false, "kg");
  sizes &= range("wheel_radius", v.wheel_radius, 0, 1e4, true, "m");
  sizes &= range("wheel_width", v.wheel_width, 0, 1e4, true, "m");
  range("wheel_mass", v.wheel_mass, limits::kMinBodyMass, limits::kMaxBodyMass, false, "kg");
  if (!knobs::kBodyFriction.allows(v.wheel_friction)) add("wheel_friction", v.wheel_friction, "must be in " + knobs::describe_range(knobs::kBodyFriction));
  if (!knobs::kBodyRollingFriction.allows(v.wheel_rolling_friction))
    add("wheel_rolling_friction", v.wheel_rolling_friction, "must be in " + knobs::describe_range(knobs::kBodyRollingFriction));
  sizes &= range("wheelbase", v.wheelbase, 0, 1e4, true, "m");
  sizes &= range("track", v.track, 0, 1e4, true, "m");
  sizes &= range("axle_height", v.axle_height, -1e4, 1e4, false, "m");
  if (v.drive != api::DriveWheels::Rear && v.drive != api::DriveWheels::Front && v.drive != api::DriveWheels::All)
    es.push_back({"", prefix + "drive", std::to_string(int(v.drive)), "must be rear, front or all"});
  range("wheel_speed", v.wheel_speed, -1e4, 1e4, false, "rad/s");
  range("max_torque", v.max_torque, 0, 1e9, false, "N m");
  const bool steer_ok = range("max_steering_angle", v.max_steering_angle, 0, 1.2, false, "rad");
  if (steer_ok && std::isfinite(v.steering_angle) && std::abs(v.steering_angle) > v.max_steering_angle)
    add("steering_angle", v.steering_angle, "must be within ±max_steering_angle (" + num(v.max_steering_angle) + " rad)");
  else if (!std::isfinite(v.steering_angle))
    add("steering_angle", v.steering_angle, "must be finite (rad)");
  range("steering_speed", v.steering_speed, 0, 1e4, true, "rad/s");
  range("suspension_stiffness", v.suspension_stiffness, 0, 1e12, false, "N/m");
  range("suspension_damping", v.suspension_damping, 0, 1e12, false, "N s/m");
  sizes &= range("suspension_travel", v.suspension_travel, 0, 10, false, "m");
  if (!sizes || !steer_ok) return es;
  // The wheels must clear the chassis (Bullet does not collide a wheel with its chassis, the
  // joint between them says so, but a patch's DEM would see their shells overlap): beside it
  // at full lock, or wholly below it at full travel.
  const double th = v.max_steering_angle;
  const double inner = 0.5 * v.wheel_width * std::cos(th) + v.wheel_radius * std::sin(th);  // m, from the wheel's centre
  const double travel = v.suspension_stiffness > 0 ? v.suspension_travel : 0.0;
  const bool beside = 0.5 * v.track - inner >= v.chassis_half_extents[2];
  const bool below = v.axle_height + v.wheel_radius + travel <= -v.chassis_half_extents[1];
  if (!beside && !below)
    add("track", v.track,
        "the wheels must clear the chassis: track / 2 − (wheel_width / 2 · cos(max_steering_angle) + wheel_radius · "
        "sin(max_steering_angle)) >= chassis_half_extents[2], or axle_height + wheel_radius + suspension_travel <= "
        "−chassis_half_extents[1]",
        "the inner face reaches " + num(0.5 * v.track - inner) + " m from the centre line, the chassis " +
            num(v.chassis_half_extents[2]) + " m");
  const double reach = v.wheel_radius * std::cos(th) + 0.5 * v.wheel_width * std::sin(th);  // m, fore and aft
  if (v.wheelbase < 2 * reach)
    add("wheelbase", v.wheelbase, "the front and rear wheels must not touch at full lock: at least " + num(2 * reach) + " m");
  return es;
}

VehicleParts expand_vehicle(const api::VehicleDef& v) {
  VehicleParts p;
  const Eigen::Quaterniond q = quat(v.orientation);
  const Eigen::Vector3d origin(v.position[0], v.position[1], v.position[2]);
  auto world = [&](const Eigen::Vector3d& local) {
    const Eigen::Vector3d w = origin + q * local;
    return api::Vec3{w.x(), w.y(), w.z()};
  };
  auto dir = [&](const Eigen::Vector3d& local) {
    const Eigen::Vector3d w = (q * local).normalized();
    return api::Vec3{w.x(), w.y(), w.z()};
  };
  auto as_quat = [](const Eigen::Quaterniond& r) {
    return api::Quat{float(r.w()), float(r.x()), float(r.y()), float(r.z())};
  };
  const std::vector<std::string> names = vehicle_body_names(v.name);
  api::BodyDef chassis;
  chassis.name = names[0];
  chassis.shape.kind = api::ShapeKind::Box;
  chassis.shape.half_extents = v.chassis_half_extents;
  chassis.mass = v.chassis_mass;
  chassis.position = v.position;
  chassis.orientation = as_quat(q);
  p.bodies.push_back(chassis);
  // A cylinder's axis is its local y: turned onto the vehicle's z (across it).
  const Eigen::Quaterniond across = q * Eigen::Quaterniond(Eigen::AngleAxisd(0.5 * M_PI, Eigen::Vector3d::UnitX()));
  const bool suspended = v.suspension_stiffness > 0;
  for (int k = 0; k < 4; ++k) {
    // The wheel's centre in the vehicle frame: front +x, left −z.
    const Eigen::Vector3d centre((k < 2 ? 0.5 : -0.5) * v.wheelbase, v.axle_height, (k % 2 == 0 ? -0.5 : 0.5) * v.track);
    api::BodyDef w;
    w.name = names[std::size_t(1 + k)];
    w.shape.kind = api::ShapeKind::Cylinder;
    w.shape.radius = v.wheel_radius;
    w.shape.height = v.wheel_width;
    w.mass = v.wheel_mass;
    w.position = world(centre);
    w.orientation = as_quat(across);
    w.friction = v.wheel_friction;
    w.rolling_friction = v.wheel_rolling_friction;
    p.bodies.push_back(w);
    p.steered[std::size_t(k)] = k < 2;
    p.driven[std::size_t(k)] = v.drive == api::DriveWheels::All || (v.drive == api::DriveWheels::Front) == (k < 2);
    VehicleJoint j;
    j.name = v.name + ".axle_" + kWheelTags[std::size_t(k)];
    j.a = 0;
    j.b = 1 + k;
    j.anchor = w.position;
    j.axis = dir(-Eigen::Vector3d::UnitZ());  // the left: a positive speed rolls forward
    j.up = dir(Eigen::Vector3d::UnitY());
    j.max_steer = p.steered[std::size_t(k)] ? v.max_steering_angle : 0.0;
    if (p.driven[std::size_t(k)]) j.drive = drive_motor(v.wheel_speed, v.max_torque);
    j.slide_limited = true;
    j.slide_lower = suspended ? -v.suspension_travel : 0.0;
    j.slide_upper = suspended ? v.suspension_travel : 0.0;
    j.stiffness = suspended ? v.suspension_stiffness : 0.0;
    j.damping = suspended ? v.suspension_damping : 0.0;
    p.joints.push_back(j);
  }
  return p;
}

api::JointMotor drive_motor(double wheel_speed, double max_torque) {
  api::JointMotor m;
  m.mode = max_torque > 0 ? api::MotorMode::Velocity : api::MotorMode::Off;
  m.target = wheel_speed;
  m.max_force = max_torque;
  return m;
}

}  // namespace sandpatch
