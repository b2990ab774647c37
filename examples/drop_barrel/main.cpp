// drop_barrel: the smallest game loop on Sandpatch (docs/api.md).
//
// A barrel falls onto sandy hills. Before it lands the terrain manager turns the ground under
// it into granules (a patch); the barrel settles into them; at the end the patch is turned
// back into heightfield. The loop steps at a fixed 1/60 s, prints the patch events as
// they arrive and, at the end, the barrel's height above the terrain.
//
//   drop_barrel [seconds]      (default 2 s of simulated time)
//
// Exit code: 0 when the barrel ended on the terrain, 1 on a failure, 2 on bad input.
#include <sandpatch/sandpatch.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace sp = sandpatch::api;

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::atof(argv[1]) : 2.0;
  if (!(seconds > 0 && seconds <= 600)) {
    std::fprintf(stderr, "drop_barrel: seconds = %s: must be in (0, 600]\n", argc > 1 ? argv[1] : "");
    return 2;
  }

  // Terrain: 6 m x 6 m of gentle hills at 10 cm spacing; coarse granules (spheres of 5 cm
  // radius, gravel rather than the default 2.5 cm sand) so a patch holds a few hundred granules
  // and the example runs in seconds on two cores.
  sp::TerrainDef def;
  def.procedural = "hills";
  def.samples_x = def.samples_z = 61;
  def.spacing = 0.1;
  def.base_height = 1.0f;
  def.amplitude = 0.05f;
  def.wavelength = 4.0f;
  def.material.granule_radius = 0.05;
  def.material.stiffness = 1.0e5;  // N/m: stiff enough for a 20 kg barrel landing at 3 m/s
  def.slots = 1;
  def.granules_per_slot = 8000;
  def.patch_depth = 0.3;
  auto terrain = sp::Terrain::create(def);
  if (!terrain) {
    std::fprintf(stderr, "drop_barrel: %s", terrain.message().c_str());
    return 2;
  }

  // A barrel: an upright cylinder, 0.3 m across, 0.4 m tall, 20 kg, 0.5 m above the ground.
  sp::BodyDef barrel;
  barrel.name = "barrel";
  barrel.shape.kind = sp::ShapeKind::Cylinder;
  barrel.shape.radius = 0.15;
  barrel.shape.height = 0.4;
  barrel.mass = 20.0;
  const double x = 3.0, z = 3.0;
  barrel.position = {x, terrain->height_at(x, z) + 0.2 + 0.5, z};
  auto body = terrain->add_body(barrel);
  if (!body) {
    std::fprintf(stderr, "drop_barrel: %s", body.message().c_str());
    return 2;
  }

  // The game loop: a fixed step, no accumulator.
  const double dt = 1.0 / 60.0;
  const long steps = std::lround(seconds / dt);
  for (long k = 0; k < steps; ++k) {
    if (auto s = terrain->step(dt); !s) {
      std::fprintf(stderr, "drop_barrel: %s", s.message().c_str());
      return 1;
    }
    for (const sp::Event& e : terrain->poll_events())
      std::printf("t = %6.3f s  patch %d %-9s %6d granules  %.1f ms\n", e.time, e.patch, sp::to_string(e.kind),
                  e.granules, e.wall_ms);
    // A renderer would redraw these heightfield regions and draw terrain->particles() here.
    for (const sp::GridRegion& r : terrain->take_dirty_regions())
      std::printf("            heightfield changed: samples [%d, %d) x [%d, %d)\n", r.i0, r.i0 + r.ni, r.j0,
                  r.j0 + r.nj);
  }

  auto state = terrain->body_state(*body);
  if (!state) {
    std::fprintf(stderr, "drop_barrel: %s", state.message().c_str());
    return 1;
  }
  const auto& p = state->position;
  const double surface = terrain->height_at(p[0], p[2]);  // the heightfield (the patch's granules are not in it yet)
  const double bottom = p[1] - 0.5 * barrel.shape.height;
  std::printf("after %.2f s: barrel centre at (%.3f, %.3f, %.3f) m, bottom %.3f m = original surface %+.3f m, "
              "speed %.3f m/s\n",
              terrain->time(), p[0], p[1], p[2], bottom, bottom - surface,
              std::hypot(state->linear_velocity[0], state->linear_velocity[1], state->linear_velocity[2]));

  // End of the level: every live patch goes back into the heightfield (a game would save it).
  if (auto s = terrain->demote_all(); !s) {
    std::fprintf(stderr, "drop_barrel: %s", s.message().c_str());
    return 1;
  }
  for (const sp::Event& e : terrain->poll_events())
    std::printf("t = %6.3f s  patch %d %-9s %6d granules  %.1f ms\n", e.time, e.patch, sp::to_string(e.kind), e.granules,
                e.wall_ms);
  std::printf("terrain under the barrel now at y = %.3f m, %d patch(es) live\n", terrain->height_at(p[0], p[2]),
              terrain->active_patches());
  // On the terrain: neither fallen through (bottom far below the surface) nor still in the air.
  if (!std::isfinite(p[1]) || bottom < surface - 0.3 || bottom > surface + 0.3) {
    std::fprintf(stderr, "drop_barrel: the barrel did not end on the terrain\n");
    return 1;
  }
  return 0;
}
