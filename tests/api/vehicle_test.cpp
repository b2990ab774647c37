// tests the public API's vehicles (Terrain::add_vehicle, drive_vehicle), through
// include/sandpatch/sandpatch.hpp only: on the heightfield a vehicle driven at a wheel speed ω
// rolls at ω r; steered left it turns left; its suspension sags by its weight over the
// springs' stiffness; bad vehicles are refused naming the field, and nothing is added.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>
#include <sandpatch/sandpatch.hpp>

namespace sp = sandpatch::api;

namespace {

// A flat heightfield 80 m × 20 m at y = 1 m, no granular patches.
sp::TerrainDef flat() {
  sp::TerrainDef d;
  d.procedural = "flat";
  d.samples_x = 161;
  d.samples_z = 41;
  d.spacing = 0.5;
  d.base_height = 1.0f;
  d.granular_patches = false;
  return d;
}

// The default vehicle (1500 kg chassis, 0.4 m wheels 0.3 m below its centre) resting on the
// surface at x = 5 m, z = 10 m, all wheels driven.
sp::VehicleDef car() {
  sp::VehicleDef v;
  v.name = "car";
  v.position = {5.0, 1.0 + 0.4 + 0.3 + 0.005, 10.0};
  v.drive = sp::DriveWheels::All;
  return v;
}

bool has_field(const std::vector<sp::Error>& es, const std::string& field) {
  return std::any_of(es.begin(), es.end(), [&](const sp::Error& e) { return e.field == field; });
}

// Yaw (rad, about +y) of a [w, x, y, z] orientation: the heading of its x axis.
double yaw(const sp::Quat& q) {
  const double w = q[0], x = q[1], y = q[2], z = q[3];
  const double fx = 1 - 2 * (y * y + z * z), fz = 2 * (x * z - w * y);  // R · (1, 0, 0)
  return std::atan2(-fz, fx);
}

}  // namespace

// Driven at 5 rad/s with up to 600 N·m a wheel, the vehicle rolls at ω r = 2 m/s within 3 %
// (4 s after starting), its wheels turn at 5 rad/s within 1 % and it runs straight (heading
// within 0.02 rad, sideways within 5 cm). Steered 0.2 rad left it turns left: its heading
// grows towards +y, and it moves towards −z.
TEST(ApiVehicle, DrivenOnTheHeightfieldItRollsAtOmegaR) {
  auto t = sp::Terrain::create(flat());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::VehicleDef v = car();
  v.wheel_speed = 5.0;
  v.max_torque = 600.0;
  auto h = t->add_vehicle(v);
  ASSERT_TRUE(h.ok()) << h.message();
  EXPECT_EQ(t->bodies().size(), 5u);
  const double dt = 1.0 / 60.0;
  for (int k = 0; k < 240; ++k) ASSERT_TRUE(t->step(dt).ok());
  auto c = t->body_state(h->chassis);
  ASSERT_TRUE(c.ok());
  EXPECT_NEAR(c->linear_velocity[0], 5.0 * 0.4, 0.03 * 2.0) << "m/s: ω r";
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(t->joint_state(h->axles[std::size_t(k)])->rate, 5.0, 0.05) << "wheel " << k;
  EXPECT_NEAR(yaw(c->orientation), 0.0, 0.02);
  EXPECT_NEAR(c->position[2], 10.0, 0.05);
  EXPECT_NEAR(c->position[1], v.position[1], 0.02) << "on its wheels";
  ASSERT_TRUE(t->drive_vehicle(*h, 5.0, 600.0, 0.2).ok());
  for (int k = 0; k < 180; ++k) ASSERT_TRUE(t->step(dt).ok());
  c = t->body_state(h->chassis);
  EXPECT_GT(yaw(c->orientation), 0.1) << "rad: turned left";
  EXPECT_LT(c->position[2], 10.0 - 0.2) << "m: moved left";
  // Stopped: a wheel speed of 0 brakes it.
  ASSERT_TRUE(t->drive_vehicle(*h, 0.0, 600.0, 0.0).ok());
  for (int k = 0; k < 180; ++k) ASSERT_TRUE(t->step(dt).ok());
  c = t->body_state(h->chassis);
  EXPECT_LT(std::hypot(c->linear_velocity[0], c->linear_velocity[2]), 0.05);
}

// Springs of k = 40000 N/m a wheel under a 1500 kg chassis: resting on its wheels the
// chassis sits lower than unloaded by m g / (4 k) = 9.2 cm within 5 % (240 Hz, so Bullet does
// not soften the spring: its frequency on a 30 kg wheel, 37 rad/s, is a tenth of the rate).
TEST(ApiVehicle, SuspensionSagsByWeightOverStiffness) {
  auto t = sp::Terrain::create(flat());
  ASSERT_TRUE(t.ok());
  sp::VehicleDef v = car();
  v.suspension_stiffness = 40000.0;
  v.suspension_damping = 4000.0;
  v.suspension_travel = 0.2;
  auto h = t->add_vehicle(v);
  ASSERT_TRUE(h.ok()) << h.message();
  for (int k = 0; k < 3 * 240; ++k) ASSERT_TRUE(t->step(1.0 / 240.0).ok());
  const double sag = 1500.0 * 9.81 / (4 * 40000.0);
  EXPECT_NEAR(v.position[1] - 0.005 - t->body_state(h->chassis)->position[1], sag, 0.05 * sag);
  EXPECT_NEAR(t->body_state(h->wheels[0])->position[1], 1.4, 0.01) << "the wheels on the ground";
}

// Each refused naming the field; nothing is added.
TEST(ApiVehicle, BadVehiclesAreRefusedNamingTheField) {
  auto t = sp::Terrain::create(flat());
  ASSERT_TRUE(t.ok());
  auto refused = [&](sp::VehicleDef v, const std::string& field) {
    auto r = t->add_vehicle(v);
    ASSERT_FALSE(r.ok()) << field;
    EXPECT_TRUE(has_field(r.errors(), field)) << r.message();
    EXPECT_TRUE(t->bodies().empty()) << field << ": nothing added";
  };
  sp::VehicleDef v = car();
  v.wheel_radius = 0;
  refused(v, "VehicleDef.wheel_radius");
  v = car();
  v.wheel_width = -0.3;
  refused(v, "VehicleDef.wheel_width");
  v = car();
  v.chassis_mass = std::nan("");
  refused(v, "VehicleDef.chassis_mass");
  v = car();
  v.chassis_half_extents = {2.0, 0.3, 0.9};  // the wheels (inner faces 0.8 m out) would touch it
  refused(v, "VehicleDef.track");
  v = car();
  v.wheelbase = 0.5;
  refused(v, "VehicleDef.wheelbase");
  v = car();
  v.steering_angle = 0.6;  // beyond max_steering_angle 0.5
  refused(v, "VehicleDef.steering_angle");
  v = car();
  v.max_torque = -1;
  refused(v, "VehicleDef.max_torque");
  v = car();
  v.position[1] = 0.5;  // the chassis' centre under the surface
  refused(v, "VehicleDef.position");
  // And a bad drive command.
  auto h = t->add_vehicle(car());
  ASSERT_TRUE(h.ok());
  auto r = t->drive_vehicle(*h, std::nan(""), 100, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors().front().field, "drive_vehicle.wheel_speed");
  r = t->drive_vehicle(*h, 1, 100, 0.7);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors().front().field, "drive_vehicle.steering_angle");
}
