// tests api/sandpatch.cpp through the public header only (include/sandpatch/sandpatch.hpp):
// bad definitions give errors naming the field, value and allowed range; heights and normals
// against the documented formulas; a body falling onto the terrain rests at the right height;
// patch events arrive in order.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>
#include <sandpatch/sandpatch.hpp>

#include "tests/api/terrain_defs.hpp"

namespace sp = sandpatch::api;
using sp::test::flat_def;  // 10 m flat, no granular patches
using sp::test::sand_def;  // 4 m flat, coarse granules (5 cm), k_n = 1e5 N/m

namespace {

// The first error of `r` (which must have failed) for messages.
template <class T>
sp::Error first_error(const sp::Result<T>& r) {
  EXPECT_FALSE(r.ok());
  return r.errors().empty() ? sp::Error{} : r.errors().front();
}

bool has_field(const std::vector<sp::Error>& es, const std::string& field) {
  return std::any_of(es.begin(), es.end(), [&](const sp::Error& e) { return e.field == field; });
}

}  // namespace

// Every bad TerrainDef field is named with its value and the allowed range, and all of them
// (six here) are reported at once.
TEST(Api, BadTerrainDefNamesTheField) {
  sp::TerrainDef d = flat_def();
  d.slots = 0;
  d.material.granule_radius = -1;
  d.spacing = std::nan("");
  d.backend = "vulkan";
  d.particle_scale = 0;
  d.lod_horizon = -1;
  auto t = sp::Terrain::create(d);
  ASSERT_FALSE(t.ok());
  const auto& es = t.errors();
  EXPECT_EQ(es.size(), 6u) << t.message();
  for (const char* f : {"TerrainDef.slots", "TerrainDef.material.granule_radius", "TerrainDef.spacing",
                        "TerrainDef.backend", "TerrainDef.particle_scale", "TerrainDef.lod_horizon"})
    EXPECT_TRUE(has_field(es, f)) << f << " missing in:\n" << t.message();
  EXPECT_NE(t.message().find("TerrainDef.slots = 0: must be in [1, 1024]"), std::string::npos) << t.message();
  EXPECT_NE(t.message().find("TerrainDef.material.granule_radius = -1: must be in [1e-05, 10] m"), std::string::npos)
      << t.message();
  EXPECT_NE(t.message().find("TerrainDef.backend = \"vulkan\": must be cpu or gl"), std::string::npos) << t.message();
}

TEST(Api, BadHeightSourcesAreRefused) {
  sp::TerrainDef none = flat_def();
  none.procedural.clear();
  EXPECT_EQ(first_error(sp::Terrain::create(none)).field, "TerrainDef.heights");

  sp::TerrainDef two = flat_def();
  two.heights.assign(41 * 41, 0.0f);
  EXPECT_EQ(first_error(sp::Terrain::create(two)).field, "TerrainDef.heights");

  sp::TerrainDef short_array = flat_def();
  short_array.procedural.clear();
  short_array.heights.assign(10, 0.0f);
  const sp::Error e = first_error(sp::Terrain::create(short_array));
  EXPECT_EQ(e.field, "TerrainDef.heights");
  EXPECT_EQ(e.value, "10 values");

  sp::TerrainDef nan_sample = flat_def();
  nan_sample.procedural.clear();
  nan_sample.heights.assign(41 * 41, 0.0f);
  nan_sample.heights[7] = INFINITY;
  EXPECT_EQ(first_error(sp::Terrain::create(nan_sample)).field, "TerrainDef.heights[7]");

  sp::TerrainDef bad_ext = flat_def();
  bad_ext.procedural.clear();
  bad_ext.file = "terrain.tiff";
  EXPECT_EQ(first_error(sp::Terrain::create(bad_ext)).field, "TerrainDef.file");

  // A missing heightmap file: the error names the file (and nothing crashes).
  sp::TerrainDef missing = flat_def();
  missing.procedural.clear();
  missing.file = "/nonexistent/terrain.png";
  auto m = sp::Terrain::create(missing);
  ASSERT_FALSE(m.ok());
  EXPECT_NE(m.message().find("/nonexistent/terrain.png"), std::string::npos) << m.message();

  sp::TerrainDef kind = flat_def();
  kind.procedural = "mountains";
  EXPECT_EQ(first_error(sp::Terrain::create(kind)).field, "TerrainDef.procedural");
}

// Bodies, handles and steps: bad input is an error naming the field, never a crash.
TEST(Api, BadBodiesHandlesAndStepsAreRefused) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();

  sp::BodyDef b;
  b.name = "crate";
  b.position = {5.0, 3.0, 5.0};
  b.mass = 0;
  sp::Error e = first_error(t->add_body(b));
  EXPECT_EQ(e.field, "BodyDef.mass");
  EXPECT_EQ(e.value, "0");
  EXPECT_EQ(e.allowed, "must be in [1e-06, 1e+09] kg");
  EXPECT_EQ(e.detail, "body 'crate'");

  b.mass = 1;
  b.shape.kind = sp::ShapeKind::Box;
  b.shape.half_extents = {0.5, -0.5, 0.5};
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.shape.half_extents[1]");

  b.shape.kind = sp::ShapeKind::Mesh;  // neither a file nor vertices
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.shape.mesh_file");
  b.shape.mesh_file = "/nonexistent/barrel.obj";
  auto missing_mesh = t->add_body(b);
  ASSERT_FALSE(missing_mesh.ok());
  EXPECT_NE(missing_mesh.message().find("/nonexistent/barrel.obj"), std::string::npos) << missing_mesh.message();

  // A tetrahedron with one face missing: open, refused naming the shape.
  b.shape.mesh_file.clear();
  b.shape.vertices = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  b.shape.triangles = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
  auto closed = t->add_body(b);
  EXPECT_TRUE(closed.ok()) << closed.message();
  b.shape.triangles.resize(9);
  b.shape.triangles.insert(b.shape.triangles.end(), {0, 1, 2});  // a face repeated, one missing
  auto open = t->add_body(b);
  ASSERT_FALSE(open.ok());
  EXPECT_EQ(open.errors().front().field.rfind("BodyDef.shape", 0), 0u) << open.message();
  ASSERT_TRUE(t->remove_body(*closed).ok());

  b.shape = {};
  b.orientation = {0, 0, 0, 0};
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.orientation");
  b.orientation = {1, 0, 0, 0};
  b.linear_velocity = {0, NAN, 0};
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.linear_velocity");
  b.linear_velocity = {0, 0, 0};

  // Below the bedrock (surface 1 m, soil_depth 2 m: bedrock at y = -1 m).
  b.position = {5.0, -3.0, 5.0};
  e = first_error(t->add_body(b));
  EXPECT_EQ(e.field, "BodyDef.position");
  EXPECT_EQ(t->bodies().size(), 0u) << "a refused body is not left in the world";

  b.position = {5.0, 3.0, 5.0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();
  EXPECT_TRUE(t->alive(*h));

  EXPECT_EQ(first_error(t->step(0.0)).field, "step.dt");
  EXPECT_EQ(first_error(t->step(0.5)).field, "step.dt");
  EXPECT_EQ(first_error(t->step(NAN)).field, "step.dt");
  EXPECT_EQ(first_error(t->step(1.0 / 60, 0)).field, "step.substeps");
  EXPECT_EQ(t->time(), 0.0) << "a refused step does not advance time";

  EXPECT_EQ(first_error(t->set_body_velocity(*h, {INFINITY, 0, 0}, {0, 0, 0})).field, "set_body_velocity.linear");
  ASSERT_TRUE(t->remove_body(*h).ok());
  EXPECT_FALSE(t->alive(*h));
  EXPECT_EQ(first_error(t->body_state(*h)).field, "BodyHandle");
  EXPECT_EQ(first_error(t->remove_body(*h)).field, "BodyHandle");
  // A new body reuses the slot with a new generation: the old handle stays stale.
  auto h2 = t->add_body(b);
  ASSERT_TRUE(h2.ok());
  EXPECT_EQ(h2->index, h->index);
  EXPECT_NE(h2->generation, h->generation);
  EXPECT_FALSE(t->alive(*h));

  std::vector<float> heights;
  EXPECT_EQ(first_error(t->read_heights({40, 0, 2, 1}, heights)).field, "GridRegion");
  sp::ClipmapSelection sel;
  sp::ClipmapDef cd;
  cd.n = 100;
  EXPECT_EQ(first_error(t->select_clipmap(cd, {}, sel)).field, "ClipmapDef.n");
  EXPECT_EQ(first_error(t->request_patch(0, 0, 1, 1)).field, "TerrainDef.granular_patches");
}

// Heights from an array and from a raw float32 file land where the layout says: sample (i, j)
// = heights[j * samples_x + i] at world (origin_x + i spacing, origin_z + j spacing).
// A body whose particle shell does not fit a slot is refused by add_body, naming the
// capacity (TerrainDef.shell_spheres_per_slot) and how many spheres it needs.
TEST(Api, ABodyTooBigForTheShellCapacityIsRefused) {
  sp::TerrainDef d = sand_def();
  d.shell_spheres_per_slot = 64;
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b;
  b.name = "crate";
  b.shape.kind = sp::ShapeKind::Box;
  b.shape.half_extents = {0.5, 0.2, 0.5};  // 1.8 m² of surface: ~800 shell spheres at 7.5 cm
  b.mass = 20;
  b.position = {2.0, 1.5, 2.0};
  sp::Error e = first_error(t->add_body(b));
  EXPECT_EQ(e.field, "TerrainDef.shell_spheres_per_slot");
  EXPECT_EQ(e.value, "64");
  EXPECT_NE(e.allowed.find("too small for a body shell of"), std::string::npos) << e.message();
  EXPECT_TRUE(t->bodies().empty());
  b.shape.half_extents = {0.05, 0.05, 0.05};  // a small one fits
  EXPECT_TRUE(t->add_body(b).ok());
}

TEST(Api, HeightsFromAnArrayAndAFile) {
  sp::TerrainDef d = flat_def();
  d.procedural.clear();
  d.samples_x = 3;
  d.samples_z = 2;
  d.spacing = 2.0;
  d.origin = {100.0, 10.0, 200.0};
  d.heights = {0, 1, 2, 3, 4, 5};
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  EXPECT_NEAR(t->height_at(102.0, 200.0), 11.0, 1e-6);   // (1, 0)
  EXPECT_NEAR(t->height_at(100.0, 202.0), 13.0, 1e-6);   // (0, 1)
  EXPECT_NEAR(t->height_at(103.0, 201.0), 10.0 + 3.0, 1e-6);  // bilinear: mean of 1, 2, 4, 5 at the cell centre

  const std::string path = testing::TempDir() + "/api_heights.raw";
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(std::fwrite(d.heights.data(), sizeof(float), 6, f), 6u);
    std::fclose(f);
  }
  sp::TerrainDef fd = d;
  fd.heights.clear();
  fd.file = path;
  fd.vertical_scale = 2.0;
  auto tf = sp::Terrain::create(fd);
  ASSERT_TRUE(tf.ok()) << tf.message();
  EXPECT_NEAR(tf->height_at(104.0, 202.0), 10.0 + 2.0 * 5.0, 1e-5);  // (2, 1)
  fd.samples_x = 4;  // the file holds 6 values, not 8
  auto bad = sp::Terrain::create(fd);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find(path), std::string::npos) << bad.message();
  std::remove(path.c_str());
}

// Heights and normals follow the documented formulas (docs/heightfield.md) on a plane far
// from the world origin: h = origin_y + base + sx x + sz z, n = normalize(-sx, 1, -sz).
TEST(Api, HeightAndNormalOnAPlane) {
  sp::TerrainDef d = flat_def();
  d.procedural = "plane";
  d.slope_x = 0.1f;
  d.slope_z = -0.05f;
  d.origin = {10000.0, 50.0, -20000.0};
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  for (auto [lx, lz] : {std::pair{0.0, 0.0}, {3.3, 7.1}, {9.99, 0.4}, {5.125, 5.875}}) {
    const double x = d.origin[0] + lx, z = d.origin[2] + lz;
    EXPECT_NEAR(t->height_at(x, z), 50.0 + 1.0 + 0.1 * lx - 0.05 * lz, 1e-4) << lx << ", " << lz;
    const sp::Vec3f n = t->normal_at(x, z);
    const double len = std::sqrt(0.1 * 0.1 + 1.0 + 0.05 * 0.05);
    EXPECT_NEAR(n[0], -0.1 / len, 1e-5);
    EXPECT_NEAR(n[1], 1.0 / len, 1e-5);
    EXPECT_NEAR(n[2], 0.05 / len, 1e-5);
  }
  // read_heights returns the local heights (relative to origin[1]) row by row, x fastest.
  std::vector<float> h;
  ASSERT_TRUE(t->read_heights({2, 3, 4, 2}, h).ok());
  ASSERT_EQ(h.size(), 8u);
  EXPECT_NEAR(h[1], 1.0 + 0.1 * (3 * 0.25) - 0.05 * (3 * 0.25), 1e-5);
  EXPECT_NEAR(h[4], 1.0 + 0.1 * (2 * 0.25) - 0.05 * (4 * 0.25), 1e-5);
  const sp::HeightfieldInfo info = t->heightfield();
  EXPECT_EQ(info.samples_x, 41);
  EXPECT_EQ(info.spacing, 0.25);
  EXPECT_EQ(info.origin[2], -20000.0);

  sp::ClipmapDef cd;
  cd.n = 31;
  cd.levels = 3;
  cd.base_spacing = 0.25f;
  cd.height_factor = 0;
  sp::ClipmapView view;
  view.viewer = {d.origin[0] + 5, 60.0, d.origin[2] + 5};
  sp::ClipmapSelection sel;
  ASSERT_TRUE(t->select_clipmap(cd, view, sel).ok());
  ASSERT_EQ(sel.levels.size(), 3u);
  EXPECT_TRUE(sel.levels[0].finest);
  EXPECT_FLOAT_EQ(sel.levels[2].spacing, 1.0f);
  EXPECT_GT(sel.triangles, 0);
}

// Without patches a sphere dropped on a flat terrain rests on the heightfield: its centre ends
// within 1 cm of surface + radius, at rest (< 1 cm/s), after 3 s.
TEST(Api, SphereRestsOnTheHeightfield) {
  sp::TerrainDef d = flat_def();
  d.origin = {500.0, 20.0, -300.0};
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b;
  b.name = "ball";
  b.shape.radius = 0.4;
  b.mass = 10;
  b.position = {505.0, 24.0, -295.0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();
  for (int k = 0; k < 180; ++k) ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_NEAR(t->time(), 3.0, 1e-9);
  auto s = t->body_state(*h);
  ASSERT_TRUE(s.ok());
  EXPECT_NEAR(s->position[1], t->height_at(s->position[0], s->position[2]) + 0.4, 0.01);
  EXPECT_NEAR(t->height_at(505.0, -295.0), 21.0, 1e-6);
  EXPECT_LT(std::hypot(s->linear_velocity[0], s->linear_velocity[1], s->linear_velocity[2]), 0.01);
  EXPECT_TRUE(t->poll_events().empty()) << "no patches without granular_patches";
  // Teleport and set a velocity: the next state starts from them.
  ASSERT_TRUE(t->set_body_transform(*h, {502.0, 25.0, -298.0}, {1, 0, 0, 0}).ok());
  ASSERT_TRUE(t->set_body_velocity(*h, {1.0f, 0, 0}, {0, 0, 0}).ok());
  ASSERT_TRUE(t->step(1.0 / 60.0, 4).ok());
  s = t->body_state(*h);
  EXPECT_NEAR(s->position[0], 502.0 + 1.0 / 60.0, 1e-3);
  EXPECT_NEAR(s->linear_velocity[1], -9.81 / 60.0, 1e-3);
}

// A sphere dropped onto sand: a patch is requested and promoted before the sphere lands
// (free fall over 0.3 m takes 0.247 s), then ready; the sphere comes to rest on the granules
// with its centre within 1 d of surface + radius (measured 2026-11-22: −0.13 d; +0.54 d with
// k_n = 2e4 before the manager's fill changed: it rests on the granules' tops, which stand up
// to about d above the cut surface) and within 3 d of where it fell (measured 0.01 m; 0.21 m
// with k_n = 2e4, when it rolled off the granule it landed on); removing the sphere makes its
// handle stale at once and the patch steps on; demote_all() turns the patch back into
// heightfield: a Demoted event comes last and the patch's region is reported dirty, covering
// where the sphere was.
TEST(Api, SphereOnSandEventsInOrderAndRestHeight) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b;
  b.name = "ball";
  b.shape.radius = 0.15;
  b.mass = 20;
  b.position = {2.0, 1.0 + 0.15 + 0.3, 2.0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();

  std::vector<sp::Event> events;
  const double dt = 1.0 / 60.0;
  bool saw_particles = false;
  for (int k = 0; k < 150; ++k) {  // 2.5 s
    auto st = t->step(dt);
    ASSERT_TRUE(st.ok()) << st.message();
    for (const auto& e : t->poll_events()) events.push_back(e);
    if (!saw_particles && t->active_patches() > 0) {
      std::vector<float> xyzr;
      t->particles(xyzr);
      const auto groups = t->particle_groups();
      if (!xyzr.empty()) {
        saw_particles = true;
        ASSERT_EQ(groups.size(), 1u);
        EXPECT_EQ(groups[0].count * 4, xyzr.size());
        EXPECT_NEAR(xyzr[3], 0.05f, 1e-6f) << "sphere radius = granule_radius at particle_scale 1";
      }
    }
  }
  EXPECT_TRUE(saw_particles);
  EXPECT_EQ(t->active_patches(), 1);
  auto s = t->body_state(*h);
  ASSERT_TRUE(s.ok());
  const double d = 0.1;  // granule sphere diameter (m)
  EXPECT_NEAR(s->position[1], 1.0 + 0.15, 1.0 * d);
  // It may roll off the granule it lands on, but stays on the patch.
  EXPECT_LT(std::hypot(s->position[0] - 2.0, s->position[2] - 2.0), 3.0 * d);
  EXPECT_LT(std::hypot(s->linear_velocity[0], s->linear_velocity[1], s->linear_velocity[2]), 0.05);
  EXPECT_NE(t->report_json().find("\"ball\""), std::string::npos);

  // Removing a body the patch carries: gone for the game at once, and the patch steps on.
  ASSERT_TRUE(t->remove_body(*h).ok());
  EXPECT_FALSE(t->alive(*h));
  EXPECT_TRUE(t->bodies().empty());
  EXPECT_EQ(first_error(t->body_state(*h)).field, "BodyHandle");
  for (int k = 0; k < 6; ++k) ASSERT_TRUE(t->step(dt).ok());
  for (const auto& e : t->poll_events()) events.push_back(e);
  EXPECT_EQ(t->report_json().find("\"ball\""), std::string::npos);

  ASSERT_TRUE(t->demote_all().ok());
  for (const auto& e : t->poll_events()) events.push_back(e);
  EXPECT_EQ(t->active_patches(), 0);
  std::string seq;
  for (const auto& e : events) seq += std::string(sp::to_string(e.kind)) + " @" + std::to_string(e.time) + "\n";
  auto first = [&](sp::EventKind k) {
    return std::find_if(events.begin(), events.end(), [&](const sp::Event& e) { return e.kind == k; }) - events.begin();
  };
  const long n = long(events.size());
  ASSERT_GE(n, 4) << seq;
  EXPECT_EQ(first(sp::EventKind::Requested), 0) << seq;
  EXPECT_LT(first(sp::EventKind::Promoted), first(sp::EventKind::Ready)) << seq;
  EXPECT_LT(first(sp::EventKind::Ready), n) << seq;
  EXPECT_EQ(events.back().kind, sp::EventKind::Demoted) << seq;
  for (long k = 1; k < n; ++k) EXPECT_GE(events[k].time, events[k - 1].time) << seq;
  const sp::Event& promoted = events[first(sp::EventKind::Promoted)];
  EXPECT_LT(promoted.time, 0.247) << seq;
  EXPECT_GT(promoted.granules, 100) << seq;
  EXPECT_EQ(promoted.patch, events.back().patch);
  EXPECT_NEAR(events.back().time, 2.6, 1e-9);

  const auto dirty = t->take_dirty_regions();
  ASSERT_EQ(dirty.size(), 1u);
  EXPECT_LE(dirty[0].i0, 20);  // sample (20, 20) is under the sphere (x = z = 2 m)
  EXPECT_GT(dirty[0].i0 + dirty[0].ni, 20);
  EXPECT_LE(dirty[0].j0, 20);
  EXPECT_GT(dirty[0].j0 + dirty[0].nj, 20);
  EXPECT_TRUE(t->take_dirty_regions().empty()) << "taken once";

  EXPECT_NE(t->report_json().find("\"ledger\""), std::string::npos);
}

// Two terrains made and driven the same way end in the same state (habit 8: determinism is a
// test): 0.5 s of a sphere landing on sand, granules included; a different seed differs.
TEST(Api, SameInputsSameStateHash) {
  auto run = [](std::uint64_t seed) -> std::uint64_t {
    sp::TerrainDef d = sand_def();
    d.seed = seed;
    auto t = sp::Terrain::create(d);
    EXPECT_TRUE(t.ok()) << t.message();
    if (!t) return 0;
    sp::BodyDef b;
    b.shape.radius = 0.15;
    b.mass = 20;
    b.position = {2.0, 1.0 + 0.15 + 0.3, 2.0};
    EXPECT_TRUE(t->add_body(b).ok());
    for (int k = 0; k < 30; ++k) EXPECT_TRUE(t->step(1.0 / 60.0).ok());
    EXPECT_GT(t->granules(), 0);
    return t->state_hash();
  };
  const std::uint64_t a = run(1), b = run(1);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, run(2));
}

// A patch nothing touches goes requested → promoted → ready → asleep → demoted by itself
// (idle_timeout after falling asleep). sleep_speed is 3 m/s here because a fresh patch's
// granules keep moving (measured 2026-11-22: it slept at 0.5 and 1 m/s, not at 0.1 m/s within
// 1.5 s, and the threshold moved with the manager's changes that day; docs/api.md "Not done
// yet"); this test checks the event plumbing, not the sleep criterion.
// prepare() refuses a dt the step would refuse, naming the field and the range, and does
// nothing after the first step.
TEST(Api, PrepareRefusesABadDt) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  for (const double dt : {0.0, -1.0, 0.5, std::numeric_limits<double>::quiet_NaN()}) {
    const sp::Status s = t->prepare(dt);
    ASSERT_FALSE(s.ok()) << dt;
    EXPECT_NE(s.message().find("prepare.dt"), std::string::npos) << s.message();
  }
  ASSERT_TRUE(t->prepare(1.0 / 60.0).ok());
  ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_TRUE(t->prepare(1.0 / 60.0).ok());  // after the first step: nothing to do
}

TEST(Api, UntouchedPatchSleepsAndIsDemoted) {
  sp::TerrainDef d = sand_def();
  d.sleep_speed = 3.0;
  d.sleep_time = 0.2;
  d.idle_timeout = 0.1;
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  ASSERT_TRUE(t->request_patch(1.5, 1.5, 2.5, 2.5).ok());
  std::vector<sp::Event> events;
  for (int k = 0; k < 90 && (events.empty() || events.back().kind != sp::EventKind::Demoted); ++k) {
    ASSERT_TRUE(t->step(1.0 / 60.0).ok());
    for (const auto& e : t->poll_events()) events.push_back(e);
  }
  std::string seq;
  for (const auto& e : events) seq += std::string(sp::to_string(e.kind)) + " @" + std::to_string(e.time) + "\n";
  const std::vector<sp::EventKind> want = {sp::EventKind::Requested, sp::EventKind::Promoted, sp::EventKind::Ready,
                                           sp::EventKind::Asleep, sp::EventKind::Demoted};
  ASSERT_EQ(events.size(), want.size()) << seq;
  for (std::size_t k = 0; k < want.size(); ++k) EXPECT_EQ(events[k].kind, want[k]) << seq;
  // Asleep after at least sleep_time of simulation; demoted idle_timeout (0.1 s) later, within
  // a frame, plus the frames its demotion is spread over (one part a frame: the two renders,
  // on the CPU in bands of 64 rows of at most depth_resolution = 1024, and the write).
  EXPECT_GE(events[3].time, 0.2 - 1e-9) << seq;
  const double spread = events[4].time - events[3].time - 0.1;
  EXPECT_GE(spread, 1.0 / 60.0 - 1e-9) << seq;
  EXPECT_LE(spread, (2 * 1024 / 64 + 1) / 60.0 + 1e-9) << seq;
  EXPECT_EQ(t->active_patches(), 0);
  EXPECT_EQ(t->take_dirty_regions().size(), 1u);
}

// ---- driving bodies: apply_force, apply_torque, apply_impulse, granular_force ----

namespace {

// A body of `def` in the air over the flat terrain (no patches).
sp::BodyDef air_body(sp::ShapeKind kind, double mass) {
  sp::BodyDef b;
  b.name = "driven";
  b.shape.kind = kind;
  b.shape.radius = 0.5;
  b.shape.half_extents = {0.2, 0.3, 0.4};
  b.mass = mass;
  b.position = {5.0, 6.0, 5.0};  // 5 m above the surface
  return b;
}

}  // namespace

// F = m a in free fall: a 2 kg sphere under gravity and a force F held for 12 steps (4
// substeps each) has v = (F / m + g) t, within 1 %; a force given once acts over one step
// only (cleared after it).
TEST(ApiDrive, ForceGivesMassTimesAcceleration) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  auto h = t->add_body(air_body(sp::ShapeKind::Sphere, 2.0));
  ASSERT_TRUE(h.ok()) << h.message();
  const sp::Vec3f F = {6.0f, 30.0f, -4.0f};  // N
  const double dt = 1.0 / 60.0, m = 2.0, g = -9.81;
  for (int k = 0; k < 12; ++k) {
    ASSERT_TRUE(t->apply_force(*h, F).ok());
    ASSERT_TRUE(t->step(dt, 4).ok());
  }
  const double time = 12 * dt;
  auto s = t->body_state(*h);
  ASSERT_TRUE(s.ok());
  const double expect[3] = {F[0] / m * time, (F[1] / m + g) * time, F[2] / m * time};  // m/s
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s->linear_velocity[i], expect[i], 0.01 * std::abs(expect[i])) << "axis " << i;
  EXPECT_NEAR(s->angular_velocity[0], 0.0f, 1e-6f);
  // Not given again: the next step feels gravity only.
  ASSERT_TRUE(t->step(dt, 4).ok());
  auto s2 = t->body_state(*h);
  EXPECT_NEAR(s2->linear_velocity[0], s->linear_velocity[0], 1e-5);
  EXPECT_NEAR(s2->linear_velocity[1] - s->linear_velocity[1], g * dt, 1e-4);
}

// F = m a on the heightfield: a 10 kg box with zero friction, pushed along x by 20 N for 1 s,
// reaches v = F t / m = 2 m/s, within 1 %.
TEST(ApiDrive, FrictionlessBoxOnFlatHeightfield) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b = air_body(sp::ShapeKind::Box, 10.0);
  b.position = {2.0, 1.0 + 0.3, 5.0};  // resting on the surface (y = 1 m)
  b.friction = 0.0;
  b.rolling_friction = 0.0;
  b.restitution = 0.0;
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();
  const double dt = 1.0 / 60.0;
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(t->step(dt).ok());  // settle on the contact
  const double v0 = t->body_state(*h)->linear_velocity[0];
  for (int k = 0; k < 60; ++k) {
    ASSERT_TRUE(t->apply_force(*h, {20.0f, 0.0f, 0.0f}).ok());
    ASSERT_TRUE(t->step(dt).ok());
  }
  auto s = t->body_state(*h);
  EXPECT_NEAR(s->linear_velocity[0] - v0, 2.0, 0.02);
  EXPECT_NEAR(s->position[1], 1.3, 0.05) << "still on the surface";
}

// τ = I α about a principal axis: a 3 kg box of half extents (0.2, 0.3, 0.4) m has
// I_y = m (a² + c²) / 3 = 0.2 kg m²; 0.5 N m for 6 steps gives ω_y = τ t / I_y = 0.25 rad/s.
TEST(ApiDrive, TorqueGivesInertiaTimesAngularAcceleration) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  auto h = t->add_body(air_body(sp::ShapeKind::Box, 3.0));
  ASSERT_TRUE(h.ok());
  const double dt = 1.0 / 60.0, I_y = 3.0 * (0.2 * 0.2 + 0.4 * 0.4) / 3.0;
  for (int k = 0; k < 6; ++k) {
    ASSERT_TRUE(t->apply_torque(*h, {0.0f, 0.5f, 0.0f}).ok());
    ASSERT_TRUE(t->step(dt, 2).ok());
  }
  auto s = t->body_state(*h);
  EXPECT_NEAR(s->angular_velocity[1], 0.5 * 6 * dt / I_y, 0.01 * 0.25);
  EXPECT_NEAR(s->linear_velocity[0], 0.0f, 1e-6f);
}

// A force at a world point adds r × F: 2 N along z at 0.5 m above a 2 kg sphere's centre
// (I = 2/5 m r² = 0.2 kg m²) gives τ_x = 1 N m, so ω_x = τ t / I after t; the same as the
// force at the centre plus apply_torque(r × F), to the bit.
TEST(ApiDrive, ForceAtAPointAddsTheTorque) {
  auto run = [](bool at_point) {
    auto t = sp::Terrain::create(flat_def());
    EXPECT_TRUE(t.ok());
    auto h = t->add_body(air_body(sp::ShapeKind::Sphere, 2.0));
    const double dt = 1.0 / 60.0;
    for (int k = 0; k < 6; ++k) {
      const auto p = t->body_state(*h)->position;
      const sp::Vec3 top = {p[0], p[1] + 0.5, p[2]};
      if (at_point) {
        EXPECT_TRUE(t->apply_force(*h, {0.0f, 0.0f, 2.0f}, &top).ok());
      } else {
        EXPECT_TRUE(t->apply_force(*h, {0.0f, 0.0f, 2.0f}).ok());
        EXPECT_TRUE(t->apply_torque(*h, {1.0f, 0.0f, 0.0f}).ok());
      }
      EXPECT_TRUE(t->step(dt).ok());
    }
    return std::make_pair(*t->body_state(*h), t->state_hash());
  };
  const auto [s, hash] = run(true);
  const double I = 0.4 * 2.0 * 0.25, time = 6.0 / 60.0;
  EXPECT_NEAR(s.angular_velocity[0], 1.0 * time / I, 0.01 * time / I);
  EXPECT_NEAR(s.linear_velocity[2], 2.0 / 2.0 * time, 0.01 * time);
  EXPECT_EQ(hash, run(false).second);
}

// An impulse changes the velocities at once: Δv = J / m and, at a point, Δω = I⁻¹ (r × J).
TEST(ApiDrive, ImpulseGivesVelocityChange) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  auto h = t->add_body(air_body(sp::ShapeKind::Sphere, 2.0));
  ASSERT_TRUE(h.ok());
  ASSERT_TRUE(t->apply_impulse(*h, {4.0f, 0.0f, 0.0f}).ok());
  auto s = t->body_state(*h);
  EXPECT_FLOAT_EQ(s->linear_velocity[0], 2.0f);
  EXPECT_FLOAT_EQ(s->angular_velocity[2], 0.0f);
  const sp::Vec3 top = {s->position[0], s->position[1] + 0.5, s->position[2]};
  ASSERT_TRUE(t->apply_impulse(*h, {0.0f, 0.0f, 3.0f}, &top).ok());  // r × J = (1.5, 0, 0) N m s
  s = t->body_state(*h);
  EXPECT_FLOAT_EQ(s->linear_velocity[2], 1.5f);
  EXPECT_NEAR(s->angular_velocity[0], 1.5 / 0.2, 1e-5);  // I = 2/5 m r² = 0.2 kg m²
  // And it carries on through a step (free flight: x velocity unchanged).
  ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_NEAR(t->body_state(*h)->linear_velocity[0], 2.0f, 1e-5f);
}

// Bad loads are refused naming the argument and its value; a stale handle names BodyHandle.
TEST(ApiDrive, BadLoadsAreRefusedNamingTheArgument) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  auto h = t->add_body(air_body(sp::ShapeKind::Sphere, 2.0));
  ASSERT_TRUE(h.ok());
  const float nan = std::nanf(""), inf = INFINITY;
  auto e = first_error(t->apply_force(*h, {nan, 0.0f, 0.0f}));
  EXPECT_EQ(e.field, "apply_force.force");
  EXPECT_NE(e.value.find("nan"), std::string::npos) << e.message();
  e = first_error(t->apply_force(*h, {2e9f, 0.0f, 0.0f}));
  EXPECT_EQ(e.field, "apply_force.force");
  EXPECT_NE(e.allowed.find("1e+09"), std::string::npos) << e.message();
  const sp::Vec3 far = {5.0, 6.0, 2e4}, bad = {5.0, std::nan(""), 5.0};
  EXPECT_EQ(first_error(t->apply_force(*h, {1.0f, 0.0f, 0.0f}, &far)).field, "apply_force.world_point");
  EXPECT_EQ(first_error(t->apply_force(*h, {1.0f, 0.0f, 0.0f}, &bad)).field, "apply_force.world_point");
  EXPECT_EQ(first_error(t->apply_torque(*h, {0.0f, inf, 0.0f})).field, "apply_torque.torque");
  EXPECT_EQ(first_error(t->apply_torque(*h, {0.0f, 1.5e9f, 0.0f})).field, "apply_torque.torque");
  EXPECT_EQ(first_error(t->apply_impulse(*h, {0.0f, -3e9f, 0.0f})).field, "apply_impulse.impulse");
  EXPECT_EQ(first_error(t->apply_impulse(*h, {1.0f, 0.0f, 0.0f}, &bad)).field, "apply_impulse.world_point");
  // Nothing refused was kept: the body is in free fall.
  ASSERT_TRUE(t->step(1.0 / 60.0).ok());
  EXPECT_NEAR(t->body_state(*h)->linear_velocity[0], 0.0f, 1e-6f);
  EXPECT_NEAR(t->body_state(*h)->angular_velocity[1], 0.0f, 1e-6f);
  ASSERT_TRUE(t->remove_body(*h).ok());
  EXPECT_EQ(first_error(t->apply_force(*h, {1.0f, 0.0f, 0.0f})).field, "BodyHandle");
  EXPECT_EQ(first_error(t->apply_torque(*h, {1.0f, 0.0f, 0.0f})).field, "BodyHandle");
  EXPECT_EQ(first_error(t->apply_impulse(*h, {1.0f, 0.0f, 0.0f})).field, "BodyHandle");
  EXPECT_EQ(first_error(t->granular_force(*h)).field, "BodyHandle");
}

// The soil's force on a 20 kg sphere resting on a live patch is its weight, m g = 196.2 N up,
// within 10 % (mean over the steps of its last half second); in the air no granule pushes it,
// and on a terrain without patches no patch ever carries it (zeros).
TEST(ApiDrive, GranularForceOnARestingBodyIsItsWeight) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b;
  b.name = "ball";
  b.shape.radius = 0.15;
  b.mass = 20;
  b.position = {2.0, 1.0 + 0.15 + 0.3, 2.0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();
  auto f0 = t->granular_force(*h);
  ASSERT_TRUE(f0.ok());
  EXPECT_FALSE(f0->carried);
  const double dt = 1.0 / 60.0;
  const double weight = 20 * 9.81;  // N
  ASSERT_TRUE(t->step(dt).ok());
  // Still 0.3 m up: a patch may already hold its shell, but no granule touches it.
  EXPECT_NEAR(t->granular_force(*h)->force[1], 0.0, 0.01 * weight) << "in the air";
  // From 1.5 s it rests; the mean over the steps while the patch is awake is the DEM's
  // contact force (once the patch sleeps, the manager holds the body up with its weight).
  double sum[3] = {0, 0, 0};
  int n = 0;
  bool asleep = false;
  for (int k = 1; k < 150; ++k) {  // 2.5 s
    ASSERT_TRUE(t->step(dt).ok());
    for (const auto& e : t->poll_events()) asleep = asleep || e.kind == sp::EventKind::Asleep;
    if (k < 90) continue;
    auto f = t->granular_force(*h);
    ASSERT_TRUE(f.ok());
    EXPECT_TRUE(f->carried) << "step " << k;
    if (asleep) {
      EXPECT_NEAR(f->force[1], weight, 1e-3 * weight) << "asleep: the weight held up, step " << k;
      continue;
    }
    for (int i = 0; i < 3; ++i) sum[i] += f->force[i];
    ++n;
  }
  ASSERT_GE(n, 10) << "too few steps with the patch awake";
  EXPECT_NEAR(sum[1] / n, weight, 0.1 * weight);
  EXPECT_NEAR(sum[0] / n, 0.0, 0.05 * weight);
  EXPECT_NEAR(sum[2] / n, 0.0, 0.05 * weight);
  EXPECT_NE(t->report_json().find("\"granular_force_N\""), std::string::npos);

  auto hard = sp::Terrain::create(flat_def());
  auto hb = hard->add_body(b);
  for (int k = 0; k < 30; ++k) ASSERT_TRUE(hard->step(dt).ok());
  auto f = hard->granular_force(*hb);
  ASSERT_TRUE(f.ok());
  EXPECT_FALSE(f->carried);
  EXPECT_EQ(f->force[1], 0.0f);
}

// ---- hostile input (docs/reliability.md) ----

TEST(ApiReliability, HugeOrientationIsNormalisedInDouble) {
  // 1e30 per component: the float norm² overflows; the body must still get the identity.
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef b;
  b.position = {5, 3, 5};
  b.orientation = {1e30f, 0, 0, 0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok()) << h.message();
  const auto st = t->body_state(*h);
  ASSERT_TRUE(st.ok());
  EXPECT_NEAR(st->orientation[0], 1.0f, 1e-6f);
  b.orientation = {3e38f, 3e38f, -3e38f, 3e38f};  // each finite, the norm not in float
  auto h2 = t->add_body(b);
  ASSERT_TRUE(h2.ok()) << h2.message();
  EXPECT_NEAR(std::abs(t->body_state(*h2)->orientation[0]), 0.5f, 1e-6f);
  b.orientation = {std::nanf(""), 0, 0, 0};
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.orientation");
}

TEST(ApiReliability, OutOfRangeShapeKindIsRefused) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  sp::BodyDef b;
  b.position = {5, 3, 5};
  for (int k : {-1, 5, 1000}) {
    b.shape.kind = static_cast<sp::ShapeKind>(k);
    const sp::Error e = first_error(t->add_body(b));
    EXPECT_EQ(e.field, "BodyDef.shape.kind") << e.message();
    EXPECT_EQ(e.value, std::to_string(k));
  }
}

TEST(ApiReliability, BodyInsideTheTerrainIsRefusedAsInSceneFiles) {
  auto t = sp::Terrain::create(flat_def());  // surface at y = 1 m, bedrock at -1 m
  ASSERT_TRUE(t.ok());
  sp::BodyDef b;
  b.shape.radius = 0.5;
  b.position = {5, 0.8, 5};  // above the bedrock, centre below the surface
  const sp::Error e = first_error(t->add_body(b));
  EXPECT_EQ(e.field, "BodyDef.position");
  EXPECT_NE(e.message().find("inside the terrain"), std::string::npos) << e.message();
  EXPECT_TRUE(t->bodies().empty());
  b.position = {5, 1.2, 5};  // centre above, lowest point in the ground: allowed
  EXPECT_TRUE(t->add_body(b).ok());
  b.position = {50, -0.5, 50};  // off the terrain: nothing under it to be inside of
  EXPECT_TRUE(t->add_body(b).ok());
}

TEST(ApiReliability, VelocitiesAreCappedAsInSceneFiles) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  sp::BodyDef b;
  b.position = {5, 3, 5};
  b.linear_velocity = {-1e30f, 0, 0};
  sp::Error e = first_error(t->add_body(b));
  EXPECT_EQ(e.field, "BodyDef.linear_velocity");
  EXPECT_NE(e.message().find("at most 1000 m/s"), std::string::npos) << e.message();
  b.linear_velocity = {800, 0, 800};  // each component allowed, the speed not
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.linear_velocity");
  b.linear_velocity = {0, 0, 0};
  b.angular_velocity = {0, 2e4f, 0};
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.angular_velocity");
  b.angular_velocity = {0, 0, 0};
  auto h = t->add_body(b);
  ASSERT_TRUE(h.ok());
  EXPECT_EQ(first_error(t->set_body_velocity(*h, {0, -1e30f, 0}, {0, 0, 0})).field, "set_body_velocity.linear");
  b.mass = 1e-30;  // a float 0 in Bullet
  EXPECT_EQ(first_error(t->add_body(b)).field, "BodyDef.mass");
}

TEST(ApiReliability, ReadHeightsNearIntMaxIsAnError) {
  auto t = sp::Terrain::create(flat_def());
  ASSERT_TRUE(t.ok());
  std::vector<float> out;
  const int big = 2147483647;
  EXPECT_FALSE(t->read_heights({1, 0, big, 1}, out).ok());
  EXPECT_FALSE(t->read_heights({0, 1, 1, big}, out).ok());
  EXPECT_FALSE(t->read_heights({big, big, big, big}, out).ok());
  EXPECT_FALSE(t->read_heights({-big, 0, big, 1}, out).ok());
  EXPECT_TRUE(out.empty());
  ASSERT_TRUE(t->read_heights({40, 40, 1, 1}, out).ok());
  EXPECT_FLOAT_EQ(out.at(0), 1.0f);
}

TEST(ApiReliability, GridAndPoolOverTheirCapsAreRefusedBeforeAllocating) {
  sp::TerrainDef d = flat_def();
  d.samples_x = d.samples_z = 65536;  // 16 GiB of heights
  auto t = sp::Terrain::create(d);
  ASSERT_FALSE(t.ok());
  EXPECT_NE(t.message().find("at most 268435456 samples"), std::string::npos) << t.message();
  sp::TerrainDef p = sand_def();
  p.slots = 1024;
  p.granules_per_slot = 16777216;
  auto u = sp::Terrain::create(p);
  ASSERT_FALSE(u.ok());
  EXPECT_EQ(u.errors()[0].field, "TerrainDef.slots") << u.message();
  EXPECT_NE(u.message().find("at most 4194304 granules"), std::string::npos) << u.message();
}

// The frame budget: unset (half of each step's dt), a number of ms > 0, or +infinity (none); 0,
// a negative number and NaN are refused naming the field.
TEST(Api, FrameBudgetMustBePositive) {
  for (double v : {0.0, -4.0, std::nan("")}) {
    sp::TerrainDef d = sand_def();
    d.frame_budget_ms = v;
    auto t = sp::Terrain::create(d);
    ASSERT_FALSE(t.ok()) << v;
    EXPECT_TRUE(has_field(t.errors(), "TerrainDef.frame_budget_ms")) << t.message();
  }
  sp::TerrainDef d = sand_def();
  d.frame_budget_ms.reset();
  auto t = sp::Terrain::create(d);
  ASSERT_TRUE(t.ok()) << t.message();
  const std::string rep = t->report_json();
  const auto at = rep.find("\"frame_budget_fraction\"");
  ASSERT_NE(at, std::string::npos) << "half of each step's dt";
  EXPECT_NE(rep.substr(at, 40).find("0.5"), std::string::npos) << rep.substr(at, 40);
}

// A body that crosses more than the LOD apron in one frame is reported in the report's warnings
// to API users as to scene runs (World keeps them), naming it; a slow one is not.
TEST(ApiReliability, BodiesFasterThanThePatchesCanFollowAreWarnedOf) {
  auto t = sp::Terrain::create(sand_def());
  ASSERT_TRUE(t.ok()) << t.message();
  sp::BodyDef fast;
  fast.name = "bullet";
  fast.position = {0.5, 1.4, 2.0};  // 0.4 m over the sand (surface at y = 1 m)
  fast.linear_velocity = {400, 0, 0};  // 400 m/s: 1.7 m a frame at 1/240 s, over the 1 m apron
  auto f = t->add_body(fast);
  ASSERT_TRUE(f.ok()) << f.message();
  sp::BodyDef slow = fast;
  slow.name = "pebble";
  slow.position = {2.0, 1.4, 1.0};
  slow.linear_velocity = {0, 0, 0};
  ASSERT_TRUE(t->add_body(slow).ok());
  auto st = t->step(1.0 / 240.0);
  ASSERT_TRUE(st.ok()) << st.message();
  const std::string r = t->report_json();
  EXPECT_NE(r.find("bodies.bullet: reached"), std::string::npos) << r.substr(r.find("\"warnings\""), 400);
  EXPECT_NE(r.find("faster than the patches can follow"), std::string::npos);
  EXPECT_EQ(r.find("bodies.pebble"), std::string::npos);
}
