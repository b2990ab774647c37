// The four-wheeled vehicle (docs/api.md "Vehicles", docs/scene-format.md "vehicles"): the one
// expansion of a VehicleDef into bodies and joints that both doors use (Terrain::add_vehicle
// and a scene file's `vehicles`), and the one check of its fields.
//
// Vehicle frame: x forward, y up, z to the right; the chassis' centre at VehicleDef.position.
// Each wheel hangs on the chassis by one wheel joint (BulletWorld's JointKind::Wheel): it
// turns about the vehicle's left axis (so that a positive wheel speed rolls the vehicle
// forward), slides along the vehicle's up axis on the suspension's spring (locked without
// one), and the front wheels' axles are steered about the up axis.
#pragma once

#include <array>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "sandpatch/sandpatch.hpp"

namespace sandpatch {

// Wheel order everywhere: front left, front right, rear left, rear right.
inline constexpr std::array<const char*, 4> kWheelTags = {"fl", "fr", "rl", "rr"};

struct VehicleJoint {
  std::string name;
  int a = 0, b = 0;            // indices into VehicleParts::bodies (a the chassis, b a wheel)
  api::Vec3 anchor{};          // m, world: the wheel's centre
  api::Vec3 axis{};            // world, unit: the axle (the vehicle's left)
  api::Vec3 up{};              // world, unit: the suspension's and the steering's axis
  double max_steer = 0;        // rad (0: not steered)
  api::JointMotor drive;       // the axle's motor
  bool slide_limited = true;
  double slide_lower = 0, slide_upper = 0;  // m along `up`
  double stiffness = 0, damping = 0;        // N/m, N s/m
};

struct VehicleParts {
  std::vector<api::BodyDef> bodies;   // 0 the chassis, 1-4 the wheels (kWheelTags order)
  std::vector<VehicleJoint> joints;   // 0-3 the wheels' joints (kWheelTags order)
  std::array<bool, 4> driven{};       // wheels the drive turns
  std::array<bool, 4> steered{};      // wheels the steering turns (the front ones)
};

// Part names: "<vehicle>.chassis", "<vehicle>.wheel_fl", ...; joints "<vehicle>.axle_fl", ...
std::vector<std::string> vehicle_body_names(const std::string& vehicle);

// Every field of `v`, errors naming prefix + field ("VehicleDef.wheel_radius").
std::vector<Error> check_vehicle(const api::VehicleDef& v, const std::string& prefix);

// The bodies and joints of a checked vehicle, at its pose.
VehicleParts expand_vehicle(const api::VehicleDef& v);

// The axle motor for a drive command (rad/s, N m per driven wheel; a torque of 0: no motor).
api::JointMotor drive_motor(double wheel_speed, double max_torque);

}  // namespace sandpatch
