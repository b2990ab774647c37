// drive_vehicle: a 60 Hz game loop that drives a four-wheeled vehicle across sand
// (docs/api.md "Vehicles").
//
// A 1500 kg vehicle (a chassis on four 0.4 m wheels, all driven) starts at rest on flat sand
// of 4 cm granules and is driven forward, then steered left, through the public API only:
// Terrain::add_vehicle once, drive_vehicle when the driver's input changes, one step of
// 1/60 s a frame. It prints the frames' wall times (median, 99th percentile, longest), how far
// the vehicle went and how fast, how many wheel-frames the sand (not the heightfield) carried,
// and the deepest sinkage of a wheel below the original surface.
//
//   drive_vehicle [frame_budget_ms | off | default] [seconds] [report.json]
//   (defaults: the library's budget, 8 s, no report file)
//
// Exit code: 0 when the loop ran, 1 on a failure, 2 on bad input.
#include <sandpatch/sandpatch.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

namespace sp = sandpatch::api;

int main(int argc, char** argv) {
  sp::TerrainDef def;
  def.procedural = "flat";
  def.samples_x = 241;  // 48 m x 16 m at 0.2 m
  def.samples_z = 81;
  def.spacing = 0.2;
  def.origin = {-24.0, 0.0, -8.0};
  def.soil_depth = 1.0;
  def.material.granule_radius = 0.04;  // m
  def.material.stiffness = 1.0e5;      // N/m: firm enough for a 3.7 kN wheel load
  // Four simulations: the car (4.4 m over its wheels) spans two patches of this 0.2 m grid's
  // size, and the patch ahead of it needs a third while the one behind still holds the rear
  // wheels (with three the front wheels ran onto the heightfield in a third of the frames).
  def.slots = 4;
  def.granules_per_slot = 65536;
  double seconds = 8.0;
  if (argc > 1) {
    const std::string a = argv[1];
    char* end = nullptr;
    const double v = std::strtod(a.c_str(), &end);
    if (a == "default") {
    } else if (a == "off") def.frame_budget_ms = std::numeric_limits<double>::infinity();
    else if (end && *end == '\0' && v > 0) def.frame_budget_ms = v;
    else {
      std::fprintf(stderr, "drive_vehicle: frame budget '%s': must be a number of ms > 0, off or default\n", a.c_str());
      return 2;
    }
  }
  if (argc > 2) {
    char* end = nullptr;
    seconds = std::strtod(argv[2], &end);
    if (!(end && *end == '\0' && seconds > 0 && seconds <= 600)) {
      std::fprintf(stderr, "drive_vehicle: seconds '%s': must be a number in (0, 600]\n", argv[2]);
      return 2;
    }
  }
  auto terrain = sp::Terrain::create(def);
  if (!terrain) {
    std::fprintf(stderr, "drive_vehicle: %s", terrain.message().c_str());
    return 2;
  }
  sp::VehicleDef car;
  car.name = "car";
  car.position = {-16.0, 0.75, 0.0};
  car.chassis_half_extents = {1.8, 0.3, 0.5};
  car.chassis_mass = 1380.0;
  car.wheel_radius = 0.4;
  car.wheel_width = 0.3;
  car.wheel_mass = 30.0;
  car.wheelbase = 2.8;
  car.track = 2.2;  // 0.4 m between each wheel and the chassis' side (docs/api.md "Vehicles")
  car.axle_height = -0.3;
  car.drive = sp::DriveWheels::All;
  car.max_torque = 700.0;  // N m per wheel
  auto handles = terrain->add_vehicle(car);
  if (!handles) {
    std::fprintf(stderr, "drive_vehicle: %s", handles.message().c_str());
    return 2;
  }
  const double dt = 1.0 / 60.0;
  const int frames = int(std::lround(seconds / dt));
  std::vector<double> ms;
  int carried = 0, wheel_frames = 0;
  double deepest = 0;
  const double x0 = terrain->body_state(handles->chassis)->position[0];
  for (int f = 0; f < frames; ++f) {
    // The driver: full throttle after half a second, a left turn from 5 s to 6 s.
    if (f == 30 || f == 300 || f == 360) {
      const double steer = (f == 300) ? 0.2 : 0.0;
      if (sp::Status s = terrain->drive_vehicle(*handles, 8.0, 700.0, steer); !s) {
        std::fprintf(stderr, "drive_vehicle: %s", s.message().c_str());
        return 1;
      }
    }
    const auto t0 = std::chrono::steady_clock::now();
    if (sp::Status s = terrain->step(dt); !s) {
      std::fprintf(stderr, "drive_vehicle: %s", s.message().c_str());
      return 1;
    }
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    for (const sp::BodyHandle w : handles->wheels) {
      const auto c = terrain->body_contact(w);
      if (!c) continue;
      ++wheel_frames;
      carried += c->on_particles ? 1 : 0;
      deepest = std::max(deepest, c->sinkage);
    }
  }
  const auto st = terrain->body_state(handles->chassis);
  std::vector<double> s = ms;
  std::sort(s.begin(), s.end());
  double wall = 0;
  for (double m : ms) wall += m;
  std::printf("drive_vehicle: %d frames of 1/60 s: median %.2f ms, 99th percentile %.2f ms, longest %.2f ms; %.2f x real time\n",
              frames, s[s.size() / 2], s[s.size() * 99 / 100], s.back(), seconds / (wall / 1000.0));
  std::printf("car: %.2f m along x, %.2f m sideways, speed %.2f m/s at the end; wheels on the sand %d of %d wheel-frames, "
              "deepest sinkage %.3f m\n",
              st->position[0] - x0, st->position[2], std::hypot(st->linear_velocity[0], st->linear_velocity[2]), carried,
              wheel_frames, deepest);
  const std::string rep = terrain->report_json();
  if (argc > 3) {
    if (std::FILE* out = std::fopen(argv[3], "w")) {
      std::fputs(rep.c_str(), out);
      std::fclose(out);
    } else {
      std::fprintf(stderr, "drive_vehicle: cannot write '%s'\n", argv[3]);
      return 1;
    }
  }
  const auto b = rep.find("\"budget\"");
  std::printf("report (budget): %s\n", b == std::string::npos ? "none" : rep.substr(b, 300).c_str());
  return 0;
}
