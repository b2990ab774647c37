// push_box: a 60 Hz game loop that pushes a body across sand (docs/api.md "Driving bodies").
//
// A 40 kg box is pushed at 300 N across flat sand of 4 cm granules while a 30 kg ball is
// dropped beside its path, through the public API only: Terrain::apply_force before every
// step, one step of 1/60 s a frame. It prints the frames' wall times (median, 99th percentile,
// longest), where the box went, how far it rose above its resting height and its fastest
// upward speed (a patch appearing under it, or one it reaches, must not throw it up), and the
// frame budget's report.
//
//   push_box [frame_budget_ms | off | default] [regions | no-regions]
//     frame budget: default the library's, half of each step's dt; regions: whether the still
//     parts of an awake patch sleep (TerrainDef::sleep_regions, default on)
//
// Exit code: 0 when the loop ran, 1 on a failure, 2 on bad input.
#include <sandpatch/sandpatch.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <string>
#include <vector>

namespace sp = sandpatch::api;

int main(int argc, char** argv) {
  sp::TerrainDef def;
  def.procedural = "flat";
  def.samples_x = def.samples_z = 121;  // 12 m x 12 m at 10 cm
  def.spacing = 0.1;
  def.base_height = 1.0f;
  def.material.granule_radius = 0.04;   // m
  if (argc > 1) {
    const std::string a = argv[1];
    char* end = nullptr;
    const double v = std::strtod(a.c_str(), &end);
    if (a == "off") def.frame_budget_ms = std::numeric_limits<double>::infinity();
    else if (end && *end == '\0' && v > 0) def.frame_budget_ms = v;
    else if (a != "default") {
      std::fprintf(stderr, "push_box: frame budget '%s': must be a number of ms > 0, off or default\n", a.c_str());
      return 2;
    }
  }
  if (argc > 2) {
    const std::string a = argv[2];
    if (a != "regions" && a != "no-regions") {
      std::fprintf(stderr, "push_box: '%s': must be regions or no-regions\n", a.c_str());
      return 2;
    }
    def.sleep_regions = a == "regions";
  }
  auto terrain = sp::Terrain::create(def);
  if (!terrain) {
    std::fprintf(stderr, "push_box: %s", terrain.message().c_str());
    return 2;
  }
  sp::BodyDef box;
  box.name = "box";
  box.shape.kind = sp::ShapeKind::Box;
  box.shape.half_extents = {0.3, 0.2, 0.3};  // m
  box.mass = 40.0;
  box.position = {2.0, 1.2, 6.0};            // resting on the sand
  sp::BodyDef ball;
  ball.name = "ball";
  ball.shape.radius = 0.2;
  ball.mass = 30.0;
  ball.position = {5.0, 3.0, 5.0};           // dropped beside the box's path
  auto hb = terrain->add_body(box);
  auto hl = terrain->add_body(ball);
  if (!hb || !hl) {
    std::fprintf(stderr, "push_box: %s", (!hb ? hb.message() : hl.message()).c_str());
    return 2;
  }
  const double dt = 1.0 / 60.0;
  std::vector<double> ms;
  double rest_y = 0, top_y = -1e9, vy_max = 0, vy_max_x = 0;
  for (int f = 0; f < 360; ++f) {  // 6 s; the push starts after 0.5 s at rest
    if (f >= 30)
      if (sp::Status s = terrain->apply_force(*hb, {300.0f, 0.0f, 0.0f}); !s) {
        std::fprintf(stderr, "push_box: %s", s.message().c_str());
        return 1;
      }
    const auto t0 = std::chrono::steady_clock::now();
    if (sp::Status s = terrain->step(dt); !s) {
      std::fprintf(stderr, "push_box: %s", s.message().c_str());
      return 1;
    }
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    const auto st = terrain->body_state(*hb);
    if (f == 29) rest_y = st->position[1];
    if (f >= 30) top_y = std::max(top_y, st->position[1]);
    if (f >= 30 && st->linear_velocity[1] > vy_max) vy_max = st->linear_velocity[1], vy_max_x = st->position[0];
  }
  const auto st = terrain->body_state(*hb);
  std::vector<double> s = ms;
  std::sort(s.begin(), s.end());
  std::printf("push_box: 360 frames of 1/60 s: median %.2f ms, 99th percentile %.2f ms, longest %.2f ms\n", s[s.size() / 2],
              s[s.size() * 99 / 100], s.back());
  std::printf("box: x %.2f m, vx %.2f m/s at the end; rose at most %.3f m above its resting height; fastest upward "
              "%.2f m/s (at x %.2f m)\n",
              st->position[0], st->linear_velocity[0], top_y - rest_y, vy_max, vy_max_x);
  const std::string rep = terrain->report_json();
  const auto b = rep.find("\"budget\"");
  std::printf("report (budget): %s\n", b == std::string::npos ? "none" : rep.substr(b, 400).c_str());
  return 0;
}
