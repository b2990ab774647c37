// Tests scene/scene.cpp: every documented field parsed, every class of bad input reported
// with its file, field path and value, the embedded default, the scene hash.
#include "scene/scene.hpp"
#include "particles/material.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

namespace sandpatch {
namespace {

namespace fs = std::filesystem;
const std::string kScenes = SANDPATCH_SOURCE_DIR "/scenes";
const std::string kData = SANDPATCH_TEST_DATA_DIR "/data";
constexpr double kPi = 3.14159265358979323846;

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The messages of a failed result, for assertion output.
std::string all(const Result<SceneDef>& r) { return r.ok() ? std::string("(no errors)") : r.message(); }

// True when some error's message names `field` and shows `value` (and `extra`, if given).
bool has_error(const Result<SceneDef>& r, const std::string& field, const std::string& value,
               const std::string& extra = "") {
  if (r.ok()) return false;
  for (const auto& e : r.errors()) {
    const std::string m = e.message();
    if (e.field == field && m.find(value) != std::string::npos && m.find(extra) != std::string::npos) return true;
  }
  return false;
}

// A minimal valid scene with `patch` merged in (RFC 7386 merge patch).
std::string scene_with(const nlohmann::json& patch) {
  nlohmann::json j = {
      {"terrain", {{"source", {{"type", "procedural"}, {"kind", "flat"}}}, {"spacing", 0.5}}},
      {"materials", {{{"name", "sand"}, {"restitution", 0.3}}}},
  };
  j.merge_patch(patch);
  return j.dump(2);
}

Result<SceneDef> parse(const std::string& text) { return parse_scene(text, "test.json", kData); }

// ---- valid scenes ----

TEST(Scene, EveryFieldOfTheFullSceneIsParsed) {
  const auto r = load_scene_file(kData + "/full.json");
  ASSERT_TRUE(r.ok()) << all(r);
  const SceneDef& s = *r;
  EXPECT_EQ(s.name, "full");
  EXPECT_NE(s.description.find("Every field"), std::string::npos);
  EXPECT_EQ(s.source_path, kData + "/full.json");
  EXPECT_EQ(s.hash.size(), 16u);

  const auto& t = s.terrain;
  EXPECT_EQ(t.source_kind(), TerrainSourceKind::EsriAscii);
  EXPECT_EQ(t.file_type, "esri_ascii");
  EXPECT_EQ(t.file, (fs::path(kData) / "tiny.asc").lexically_normal().string());
  ASSERT_TRUE(t.size.has_value());
  EXPECT_EQ((*t.size)[0], 40.0);
  EXPECT_EQ((*t.size)[1], 20.0);
  EXPECT_EQ(t.spacing_xz(3, 2)[0], 20.0);
  EXPECT_EQ(t.spacing_xz(3, 2)[1], 20.0);
  EXPECT_FALSE(t.spacing_overrides_file);
  EXPECT_EQ(t.vertical_scale, 2.5);
  EXPECT_EQ(t.vertical_offset, -1.25);
  EXPECT_EQ(t.origin, (Vec3d{1000000.5, -3.0, -2000000.25}));
  EXPECT_EQ(t.soil_depth, knobs::kSoilDepth.def);  // the library's default: the flat bedrock bounds the patches
  EXPECT_EQ(t.bedrock_height, -4.0);
  EXPECT_EQ(t.material_name, "gravel");
  ASSERT_EQ(s.materials.size(), 2u);
  EXPECT_EQ(t.material.granule_radius, s.materials[1].granule_radius) << "the named material, as the library takes it";
  EXPECT_EQ(t.material.restitution, s.materials[1].restitution);

  ASSERT_EQ(s.materials.size(), 2u);
  const auto& sand = s.materials[0];
  EXPECT_EQ(sand.name, "sand");
  EXPECT_EQ(sand.density, 2600.0);
  EXPECT_EQ(sand.friction, 0.55);
  EXPECT_EQ(sand.restitution, 0.35);
  EXPECT_FALSE(sand.damping_ratio.has_value());
  EXPECT_EQ(sand.stiffness, 150000.0);
  EXPECT_EQ(sand.tangential_stiffness_ratio, 0.3);
  EXPECT_EQ(sand.granule_radius, 0.02);
  EXPECT_EQ(sand.packing_fraction, 0.62);
  // e and ζ are two views of one damping, through the clamped law the DEM integrates
  // (particles/material.hpp): the round trip returns e.
  const double z = sand.damping_ratio_value();
  EXPECT_NEAR(clamped_restitution(z), 0.35, 1e-9);
  EXPECT_GT(z, -std::log(0.35) / std::sqrt(kPi * kPi + std::log(0.35) * std::log(0.35)))
      << "the clamp needs more damping than the textbook formula for the same e";
  const auto& gravel = s.materials[1];
  EXPECT_EQ(gravel.damping_ratio, 0.4);
  EXPECT_EQ(gravel.stiffness, 2.0e6);
  EXPECT_EQ(gravel.tangential_stiffness_ratio, 0.25);
  EXPECT_EQ(gravel.granule_radius, 0.05);
  EXPECT_EQ(gravel.packing_fraction, 0.58);
  EXPECT_EQ(gravel.density, 2700.0);
  EXPECT_EQ(gravel.friction, 0.8);
  // The library's restitution holds the e that ζ gives.
  EXPECT_NEAR(gravel.restitution, clamped_restitution(0.4), 1e-12);
  EXPECT_GT(gravel.restitution, std::exp(-kPi * 0.4 / std::sqrt(1 - 0.16)))
      << "the contact ends before the overlap closes: more rebound than the textbook law";

  ASSERT_EQ(s.bodies.size(), 5u);
  const auto& ball = s.bodies[0];
  EXPECT_EQ(ball.name, "ball");
  EXPECT_EQ(ball.shape.kind, ShapeKind::Sphere);
  EXPECT_EQ(ball.shape.radius, 0.4);
  EXPECT_EQ(ball.mass, 12.5);
  EXPECT_FALSE(ball.density.has_value());
  EXPECT_EQ(ball.position, (Vec3d{1000001.0, 5.0, -2000000.0}));
  EXPECT_EQ(ball.orientation, (api::Quat{0.0f, 1.0f, 0.0f, 0.0f}));
  EXPECT_EQ(ball.linear_velocity, (api::Vec3f{1.0f, -2.0f, 3.0f}));  // as the library takes them (float)
  EXPECT_EQ(ball.angular_velocity, (api::Vec3f{0.1f, 0.2f, 0.3f}));
  EXPECT_EQ(ball.spawn_time, 0.75);
  EXPECT_EQ(ball.friction, 0.45);
  EXPECT_EQ(ball.restitution, 0.65);

  const auto& crate = s.bodies[1];
  EXPECT_EQ(crate.shape.kind, ShapeKind::Box);
  EXPECT_EQ(crate.shape.half_extents, (Vec3d{0.5, 0.25, 0.125}));
  EXPECT_EQ(crate.density, 800.0);
  EXPECT_NEAR(crate.mass, 800.0 * 8 * 0.5 * 0.25 * 0.125, 1e-9);
  // euler_deg [0, 90, 0]: a quarter turn about y (a float quaternion, as the library's).
  const float h = float(std::sqrt(0.5));
  EXPECT_EQ(crate.orientation[0], h);
  EXPECT_EQ(crate.orientation[2], h);
  EXPECT_EQ(crate.friction, 0.5);  // defaults
  EXPECT_EQ(crate.restitution, knobs::kBodyRestitution.def);
  EXPECT_EQ(crate.rolling_friction, knobs::kBodyRollingFriction.def);
  EXPECT_EQ(crate.spawn_time, 0.0);

  const auto& can = s.bodies[2];
  EXPECT_EQ(can.shape.kind, ShapeKind::Cylinder);
  EXPECT_EQ(can.shape.radius, 0.3);
  EXPECT_EQ(can.shape.height, 0.9);
  EXPECT_NEAR(can.volume(), kPi * 0.09 * 0.9, 1e-12);

  const auto& pill = s.bodies[3];
  EXPECT_EQ(pill.shape.kind, ShapeKind::Capsule);
  EXPECT_EQ(pill.shape.radius, 0.2);
  EXPECT_EQ(pill.shape.height, 0.6);
  EXPECT_NEAR(pill.mass, 1000.0 * (kPi * 0.04 * 0.6 + 4.0 / 3.0 * kPi * 0.008), 1e-9);

  const auto& barrel = s.bodies[4];
  EXPECT_EQ(barrel.shape.kind, ShapeKind::Mesh);
  EXPECT_EQ(barrel.shape.mesh_file, (fs::path(kScenes) / "meshes/barrel.obj").lexically_normal().string());
  EXPECT_EQ(barrel.shape.mesh_scale, 2.0);
  EXPECT_TRUE(barrel.shape.solid);
  // Scale 2: 8 × the barrel's volume (within the 0.16 % tessellation deficit).
  EXPECT_NEAR(barrel.mesh_volume, 8 * kPi * 0.09 * 0.9, 0.002 * 8 * kPi * 0.09 * 0.9);
  EXPECT_NEAR(body_extent_below(barrel), 0.9, 1e-6);

  const auto& sim = s.simulation;
  EXPECT_EQ(sim.dt, 0.005);
  EXPECT_EQ(sim.substeps, 4);
  EXPECT_EQ(sim.duration, 12.5);
  EXPECT_EQ(t.backend, "gl");
  EXPECT_EQ(t.threads, 2);
  EXPECT_EQ(t.slots, 8);
  EXPECT_EQ(t.granules_per_slot, 100000);
  EXPECT_EQ(t.particle_scale, 4.0);
  EXPECT_EQ(t.steps_per_contact, 30);
  EXPECT_EQ(t.sleep_speed, 0.02);
  EXPECT_EQ(t.sleep_time, 2.5);
  EXPECT_EQ(t.idle_timeout, 60.0);
  EXPECT_EQ(t.granular_patches, false);
  EXPECT_EQ(t.gravity, (Vec3d{0.0, -1.62, 0.0}));
  EXPECT_EQ(t.seed, 12345678901234u);

  ASSERT_EQ(s.cameras.size(), 2u);
  const auto& fixed = s.cameras[0];
  EXPECT_EQ(fixed.name, "fixed");
  EXPECT_EQ(fixed.position, (Vec3d{10.0, 5.0, 10.0}));
  EXPECT_EQ(fixed.target, (Vec3d{0.0, 1.0, 0.0}));
  EXPECT_EQ(fixed.fov_deg, 50.0);
  EXPECT_EQ(fixed.width, 320);
  EXPECT_EQ(fixed.height, 240);
  EXPECT_TRUE(fixed.path.empty());
  const auto& flyby = s.cameras[1];
  ASSERT_EQ(flyby.path.size(), 2u);
  EXPECT_EQ(flyby.path[1].time, 5.0);
  EXPECT_EQ(flyby.path[1].position, (Vec3d{10.0, 5.0, 0.0}));
  EXPECT_EQ(flyby.path[1].target, (Vec3d{1.0, 0.0, 0.0}));
  EXPECT_EQ(flyby.fov_deg, 60.0);

  const auto& out = s.outputs;
  ASSERT_EQ(out.frames.size(), 2u);
  EXPECT_EQ(out.frames[0].camera, "fixed");
  EXPECT_EQ(out.frames[0].times, (std::vector<double>{0.5, 1.0}));
  EXPECT_EQ(out.frames[0].file, "fixed_{time_ms}.png");
  EXPECT_EQ(out.frames[1].camera, "flyby");
  EXPECT_EQ(out.frames[1].every_k_frames, 10);
  EXPECT_EQ(out.frames[1].file, "{camera}_{frame}.png");
  ASSERT_EQ(out.heightfields.size(), 1u);
  EXPECT_EQ(out.heightfields[0].format, HeightfieldFormat::RawF32);
  EXPECT_EQ(out.heightfields[0].times, (std::vector<double>{2.0}));
  EXPECT_TRUE(out.heightfields[0].at_end);
  EXPECT_EQ(out.heightfields[0].file, "hf/{frame}.{ext}");
  EXPECT_FALSE(out.report);
}

TEST(Scene, ProceduralFieldsAndDefaults) {
  const auto r = parse(scene_with({{"terrain",
                                    {{"source",
                                      {{"kind", "plane"}, {"height", 1.5}, {"slope_x", 0.1}, {"slope_z", -0.2},
                                       {"amplitude", 2.0}, {"wavelength", 8.0}, {"seed", 99}, {"octaves", 2},
                                       {"samples_x", 33}, {"samples_z", 17}}}}}}));
  ASSERT_TRUE(r.ok()) << all(r);
  const auto& p = r->terrain;  // the generator's parameters as the library takes them (float)
  EXPECT_EQ(p.procedural, "plane");
  EXPECT_EQ(p.base_height, 1.5f);
  EXPECT_EQ(p.slope_x, 0.1f);
  EXPECT_EQ(p.slope_z, -0.2f);
  EXPECT_EQ(p.amplitude, 2.0f);
  EXPECT_EQ(p.wavelength, 8.0f);
  EXPECT_EQ(p.noise_seed, 99u);
  EXPECT_EQ(p.octaves, 2);
  EXPECT_EQ(p.samples_x, 33);
  EXPECT_EQ(p.samples_z, 17);
  // Defaults of everything left out.
  EXPECT_EQ(r->name, "test");
  EXPECT_EQ(r->terrain.soil_depth, 2.0);
  EXPECT_EQ(r->terrain.material_name, "sand");
  EXPECT_EQ(r->terrain.material.restitution, r->materials[0].restitution) << "the named material, as the library takes it";
  EXPECT_EQ(r->terrain.spacing_xz(33, 17)[0], 0.5);
  const SceneSimulationDef d;
  EXPECT_TRUE(r->terrain.granular_patches);
  EXPECT_EQ(r->terrain.idle_timeout, 120.0);
  EXPECT_EQ(r->terrain.gravity, (Vec3d{0.0, -9.81, 0.0}));
  EXPECT_EQ(r->simulation.dt, d.dt);
  EXPECT_TRUE(r->outputs.report);
  EXPECT_NEAR(r->materials[0].tangential_stiffness_ratio, 2.0 / 7.0, 1e-15);
}

TEST(Scene, Png16AndRawF32SourcesAreChecked) {
  const fs::path dir = fs::temp_directory_path() / "sandpatch_scene_test";
  fs::create_directories(dir);
  // raw_f32: 3 × 2 floats = 24 bytes.
  { std::ofstream(dir / "h.raw", std::ios::binary).write(std::string(24, '\0').data(), 24); }
  // png16: only the signature and IHDR are checked here (16-bit, greyscale).
  const std::string ihdr = std::string("\x89PNG\r\n\x1a\n", 8) + std::string("\0\0\0\x0dIHDR", 8) +
                           std::string("\0\0\0\x03\0\0\0\x02", 8) + std::string("\x10\0\0\0\0", 5);
  { std::ofstream(dir / "h.png", std::ios::binary) << ihdr; }
  std::string rgb = ihdr;
  rgb[25] = 2;  // colour type 2: RGB
  { std::ofstream(dir / "rgb.png", std::ios::binary) << rgb; }

  auto raw = parse_scene(
      scene_with({{"terrain", {{"source", {{"type", "raw_f32"}, {"kind", nullptr}, {"file", "h.raw"}, {"samples_x", 3}, {"samples_z", 2}}}}}}),
      "t.json", dir.string());
  ASSERT_TRUE(raw.ok()) << all(raw);
  EXPECT_EQ(raw->terrain.source_kind(), TerrainSourceKind::RawF32);
  EXPECT_EQ(raw->terrain.samples_x, 3);
  EXPECT_EQ(raw->terrain.samples_z, 2);
  EXPECT_EQ(raw->terrain.file, (dir / "h.raw").string());

  auto raw_bad = parse_scene(
      scene_with({{"terrain", {{"source", {{"type", "raw_f32"}, {"kind", nullptr}, {"file", "h.raw"}, {"samples_x", 4}, {"samples_z", 2}}}}}}),
      "t.json", dir.string());
  EXPECT_TRUE(has_error(raw_bad, "terrain.source.file", "\"h.raw\"", "24 bytes")) << all(raw_bad);

  auto png = parse_scene(scene_with({{"terrain", {{"source", {{"type", "png16"}, {"kind", nullptr}, {"file", "h.png"}}}}}}), "t.json",
                         dir.string());
  ASSERT_TRUE(png.ok()) << all(png);
  EXPECT_EQ(png->terrain.source_kind(), TerrainSourceKind::Png16);
  auto png_rgb = parse_scene(scene_with({{"terrain", {{"source", {{"type", "png16"}, {"kind", nullptr}, {"file", "rgb.png"}}}}}}),
                             "t.json", dir.string());
  EXPECT_TRUE(has_error(png_rgb, "terrain.source.file", "\"rgb.png\"", "colour type 2")) << all(png_rgb);
  // A directory is not a readable heightmap.
  auto as_dir = parse_scene(scene_with({{"terrain", {{"source", {{"type", "png16"}, {"kind", nullptr}, {"file", "."}}}}}}), "t.json",
                            dir.string());
  EXPECT_TRUE(has_error(as_dir, "terrain.source.file", "\".\"", "not a regular file")) << all(as_dir);
}

TEST(Scene, ShippedScenesParse) {
  for (const char* name : {"default.json", "barrel_drop.json", "mesh_drop.json", "vehicle_drive.json"}) {
    const auto r = load_scene_file(kScenes + "/" + name);
    EXPECT_TRUE(r.ok()) << name << ":\n" << all(r);
  }
  const auto barrel = load_scene_file(kScenes + "/barrel_drop.json");
  ASSERT_TRUE(barrel.ok());
  ASSERT_EQ(barrel->bodies.size(), 1u);
  EXPECT_EQ(barrel->bodies[0].shape.kind, ShapeKind::Cylinder);
  EXPECT_EQ(barrel->bodies[0].shape.radius, 0.3);
  EXPECT_EQ(barrel->bodies[0].shape.height, 0.9);
  const double m = barrel->bodies[0].mass;
  EXPECT_GE(m, 50.0);
  EXPECT_LE(m, 200.0);
  const auto mesh = load_scene_file(kScenes + "/mesh_drop.json");
  ASSERT_TRUE(mesh.ok());
  EXPECT_NEAR(mesh->bodies[0].mass, 400.0 * kPi * 0.09 * 0.9, 0.01 * 400.0 * kPi * 0.09 * 0.9);
}

TEST(Scene, EmbeddedDefaultIsScenesDefaultJson) {
  EXPECT_EQ(std::string(default_scene_json()), read_text(kScenes + "/default.json"));
  const auto r = load_default_scene();
  ASSERT_TRUE(r.ok()) << all(r);
  EXPECT_EQ(r->name, "default");
  EXPECT_EQ(r->terrain.source_kind(), TerrainSourceKind::Procedural);
  // 64 m × 64 m at 0.5 m spacing.
  const auto& p = r->terrain;
  EXPECT_EQ((p.samples_x - 1) * r->terrain.spacing_xz(p.samples_x, p.samples_z)[0], 64.0);
  EXPECT_EQ(r->bodies.size(), 2u);
  EXPECT_EQ(r->hash, load_scene_file(kScenes + "/default.json")->hash);
}

TEST(Scene, CanonicalJsonRoundTrips) {
  for (const std::string& path : {kScenes + "/default.json", kData + "/full.json", kScenes + "/vehicle_drive.json"}) {
    const auto a = load_scene_file(path);
    ASSERT_TRUE(a.ok()) << all(a);
    const nlohmann::json ja = scene_to_json(*a);
    const auto b = parse_scene(ja.dump(), "canonical.json", "");
    ASSERT_TRUE(b.ok()) << all(b);
    EXPECT_EQ(scene_to_json(*b), ja) << path;
  }
}

TEST(Scene, HashIgnoresWhitespaceAndKeyOrderButNotValues) {
  const nlohmann::json j = nlohmann::json::parse(read_text(kScenes + "/default.json"));
  const auto a = parse_scene(j.dump(), "a.json", "");
  const auto b = parse_scene(j.dump(8), "b.json", "");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->hash, b->hash);
  nlohmann::json changed = j;
  changed["bodies"][0]["pose"]["position"][1] = 3.5;
  const auto c = parse_scene(changed.dump(), "c.json", "");
  ASSERT_TRUE(c.ok());
  EXPECT_NE(a->hash, c->hash);
}

// ---- broken scenes: one file per class of bad input ----

Result<SceneDef> broken(const std::string& name) { return load_scene_file(kScenes + "/broken/" + name); }

TEST(SceneErrors, EveryErrorNamesTheFile) {
  for (const auto& entry : fs::directory_iterator(kScenes + "/broken")) {
    if (entry.path().extension() != ".json") continue;
    const auto r = load_scene_file(entry.path().string());
    ASSERT_FALSE(r.ok()) << entry.path();
    for (const auto& e : r.errors()) {
      EXPECT_EQ(e.file, entry.path().string());
      EXPECT_EQ(e.message().rfind(entry.path().string() + ": ", 0), 0u) << e.message();
    }
  }
}

TEST(SceneErrors, UnknownKeySuggestsTheNearMiss) {
  const auto r = broken("unknown_key.json");
  ASSERT_EQ(r.ok() ? 0u : r.errors().size(), 1u) << all(r);
  EXPECT_TRUE(has_error(r, "materials[0].frction", "0.5", "did you mean 'friction'?")) << all(r);
}

TEST(SceneErrors, WrongType) {
  const auto r = broken("wrong_type.json");
  EXPECT_TRUE(has_error(r, "simulation.dt", "\"0.01\"", "without quotes")) << all(r);
  const auto b = parse(scene_with({{"simulation", {{"substeps", 2.5}, {"backend", 3}, {"pool", {1, 2}}}}}));
  EXPECT_TRUE(has_error(b, "simulation.substeps", "2.5", "integer")) << all(b);
  EXPECT_TRUE(has_error(b, "simulation.backend", "3", "one of: cpu, gl")) << all(b);
  EXPECT_TRUE(has_error(b, "simulation.pool", "[1,2]", "object")) << all(b);
}

TEST(SceneErrors, MissingFile) {
  const auto r = broken("missing_file.json");
  EXPECT_TRUE(has_error(r, "terrain.source.file", "\"heightmaps/does_not_exist.png\"", "file not found")) << all(r);
}

TEST(SceneErrors, NanAndInfinity) {
  const auto r = broken("nan_inf.json");
  ASSERT_EQ(r.ok() ? 0u : r.errors().size(), 2u) << all(r);
  EXPECT_TRUE(has_error(r, "materials[0].friction", "\"nan\"", "NaN")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].pose.position[1]", "1e999", "too large")) << all(r);
}

TEST(SceneErrors, AbsurdValues) {
  const auto r = broken("absurd_value.json");
  EXPECT_TRUE(has_error(r, "simulation.dt", "5", "(0, 0.1] s")) << all(r);
  EXPECT_TRUE(has_error(r, "materials[0].stiffness", "1e+15", "[1, 1e+12] N/m")) << all(r);
}

TEST(SceneErrors, NegativeSize) {
  const auto r = broken("negative_size.json");
  ASSERT_EQ(r.ok() ? 0u : r.errors().size(), 1u) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[1].shape.radius", "-0.5", "negative")) << all(r);
}

TEST(SceneErrors, BodyBelowFlatBedrock) {
  // origin y 10 + bedrock_height −1 = 9; the ball's bottom is at 8.7 − 0.5 = 8.2.
  const auto r = broken("below_bedrock.json");
  EXPECT_TRUE(has_error(r, "bodies[0].pose.position", "8.7", "below bedrock")) << all(r);
}

TEST(SceneErrors, BodyBelowTerrainBedrockAfterLoading) {
  const auto r = load_scene_file(kScenes + "/default.json");
  ASSERT_TRUE(r.ok());
  EXPECT_TRUE(check_bodies_against_terrain(*r, [](double, double) { return -1.0f; }).empty());
  // Bedrock at 2.9 m: the ball (y 3, r 0.25) starts below it, and so does the tilted crate.
  const auto errors = check_bodies_against_terrain(*r, [](double, double) { return 2.9f; });
  ASSERT_EQ(errors.size(), 2u);
  EXPECT_EQ(errors[0].field, "bodies[0].pose.position");
  EXPECT_NE(errors[0].message().find("below bedrock"), std::string::npos);
}

TEST(SceneErrors, OpenMeshNamesTheObjAndItsOpenEdges) {
  const auto r = broken("open_mesh.json");
  EXPECT_TRUE(has_error(r, "bodies[0].shape.file", "\"meshes/open_barrel.obj\"", "64 open edges")) << all(r);
  EXPECT_NE(all(r).find("broken/meshes/open_barrel.obj"), std::string::npos);
  // The same surface as a non-solid shell with a mass is accepted.
  nlohmann::json j = nlohmann::json::parse(read_text(kScenes + "/broken/open_mesh.json"));
  j["bodies"][0]["shape"]["solid"] = false;
  j["bodies"][0].erase("density");
  j["bodies"][0]["mass"] = 20.0;
  const auto shell = parse_scene(j.dump(), "shell.json", kScenes + "/broken");
  EXPECT_TRUE(shell.ok()) << all(shell);
}

TEST(SceneErrors, MissingRequiredField) {
  const auto r = broken("missing_field.json");
  EXPECT_TRUE(has_error(r, "bodies[0].shape", "", "missing required field")) << all(r);
  const auto no_terrain = parse(R"({"materials": [{"name": "sand", "restitution": 0.3}]})");
  EXPECT_TRUE(has_error(no_terrain, "terrain", "", "missing required field")) << all(no_terrain);
}

TEST(SceneErrors, MalformedJsonGivesLineAndColumn) {
  const auto r = broken("malformed.json");
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(r.errors().size(), 1u);
  // The '}' after the trailing comma on line 4: "    { "name": "sand", "restitution": 0.3, }".
  EXPECT_EQ(r.error().field, "line 4, column 43") << r.message();
  EXPECT_NE(r.message().find("valid JSON"), std::string::npos);
}

TEST(SceneErrors, AllErrorsAreCollected) {
  const auto r = broken("three_mistakes.json");
  ASSERT_EQ(r.ok() ? 0u : r.errors().size(), 3u) << all(r);
  EXPECT_TRUE(has_error(r, "simulaton", "", "did you mean 'simulation'?")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].shape.radius", "-1")) << all(r);
  EXPECT_TRUE(has_error(r, "terrain.material", "\"snad\"", "did you mean 'sand'?")) << all(r);
}

TEST(SceneErrors, CrossFieldChecks) {
  const auto r = broken("cross_reference.json");
  EXPECT_TRUE(has_error(r, "materials[0].damping_ratio", "0.2", "only one of 'restitution' and 'damping_ratio'")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].density", "1000", "only one of 'mass' and 'density'")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[1].mass", "", "one of 'mass' (kg) or 'density'")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[1].name", "\"ball\"", "unique")) << all(r);
  EXPECT_TRUE(has_error(r, "outputs.frames[0].camera", "\"mian\"", "did you mean 'main'?")) << all(r);
}

TEST(SceneErrors, MoreChecks) {
  // Duplicate keys, bad enum with suggestion, non-unit quaternion, both orientation forms,
  // unsorted times, unknown placeholder, absolute output path, camera looking at itself.
  const std::string text = R"({
    "terrain": {"source": {"type": "procedural", "kind": "hils"}, "spacing": 0.5, "spacing": 0.25},
    "materials": [{"name": "sand", "restitution": 0.3, "packing_fraction": 0.8}],
    "bodies": [{"name": "b", "shape": {"type": "sphere", "radius": 1}, "mass": 1,
                "pose": {"position": [0, 5, 0], "orientation": [1, 1, 0, 0]}},
               {"name": "c", "shape": {"type": "sphere", "radius": 1}, "mass": 1,
                "pose": {"orientation": [1, 0, 0, 0], "euler_deg": [0, 0, 0]}}],
    "cameras": [{"name": "cam", "position": [1, 1, 1], "target": [1, 1, 1]}],
    "outputs": {"frames": [{"camera": "cam", "times": [2, 1], "file": "/tmp/{fame}.png"}],
                "heightfields": [{"format": "png16", "at_end": true, "file": "x_{frme}.{ext}"}]}
  })";
  const auto r = parse(text);
  EXPECT_TRUE(has_error(r, "terrain.spacing", "", "duplicate key")) << all(r);
  EXPECT_TRUE(has_error(r, "terrain.source.kind", "\"hils\"", "did you mean 'hills'?")) << all(r);
  EXPECT_TRUE(has_error(r, "materials[0].packing_fraction", "0.8", "(0, 0.74]")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].pose.orientation", "[1,1,0,0]", "unit quaternion")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[1].pose.euler_deg", "[0,0,0]", "only one")) << all(r);
  EXPECT_TRUE(has_error(r, "cameras[0].target", "[1,1,1]", "no view direction")) << all(r);
  EXPECT_TRUE(has_error(r, "outputs.frames[0].times[1]", "1", "ascending")) << all(r);
  EXPECT_TRUE(has_error(r, "outputs.frames[0].file", "/tmp/{fame}.png", "output directory")) << all(r);
  EXPECT_TRUE(has_error(r, "outputs.heightfields[0].file", "x_{frme}.{ext}", "did you mean '{frame}'?")) << all(r);
  const auto empty_times = parse(scene_with({{"outputs", {{"heightfields", {{{"times", nlohmann::json::array()}}}}}}}));
  EXPECT_TRUE(has_error(empty_times, "outputs.heightfields[0].times", "[]", "at least one time")) << all(empty_times);
}

TEST(SceneErrors, ProceduralSizeMustGiveSquareCells) {
  const auto r = parse(scene_with({{"terrain", {{"spacing", nullptr}, {"size", {64.0, 32.0}},
                                                {"source", {{"samples_x", 129}, {"samples_z", 129}}}}}}));
  EXPECT_TRUE(has_error(r, "terrain.size", "[64.0,32.0]", "square cells")) << all(r);
  const auto ok = parse(scene_with({{"terrain", {{"spacing", nullptr}, {"size", {64.0, 32.0}},
                                                 {"source", {{"samples_x", 129}, {"samples_z", 65}}}}}}));
  ASSERT_TRUE(ok.ok()) << all(ok);
  EXPECT_EQ(ok->terrain.spacing_xz(129, 65)[1], 0.5);
}

TEST(SceneErrors, ScenelessInputs) {
  EXPECT_FALSE(load_scene_file("/nonexistent/scene.json").ok());
  const auto empty = parse("");
  ASSERT_FALSE(empty.ok());
  EXPECT_EQ(empty.error().field, "line 1, column 1");
  const auto array = parse("[1, 2]");
  EXPECT_TRUE(has_error(array, "(top level)", "[1,2]", "object")) << all(array);
}

// ---- robustness ----

TEST(SceneFuzz, MutatedScenesNeverCrashAndAlwaysExplain) {
  // Deterministic byte mutations of the default scene (flip, delete, insert, duplicate a
  // span): each must parse or fail with at least one error that names the source.
  const std::string base = default_scene_json();
  std::uint64_t state = 0x9e3779b97f4a7c15ull;
  auto next = [&] {  // splitmix64
    state += 0x9e3779b97f4a7c15ull;
    std::uint64_t z = state;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  };
  const std::string alphabet = "{}[]\",:0123456789.-+eE aAzZ\n\\nulltruefalse";
  int failures = 0;
  for (int iter = 0; iter < 3000; ++iter) {
    std::string text = base;
    const int edits = 1 + static_cast<int>(next() % 3);
    for (int e = 0; e < edits && !text.empty(); ++e) {
      const std::size_t pos = next() % text.size();
      switch (next() % 4) {
        case 0: text[pos] = alphabet[next() % alphabet.size()]; break;
        case 1: text.erase(pos, 1 + next() % 8); break;
        case 2: text.insert(pos, 1, alphabet[next() % alphabet.size()]); break;
        case 3: text.insert(pos, text.substr(pos, 1 + next() % 16)); break;
      }
    }
    const auto r = parse_scene(text, "fuzz.json", "");
    if (r.ok()) continue;
    ++failures;
    for (const auto& err : r.errors()) {
      ASSERT_EQ(err.file, "fuzz.json") << text;
      ASSERT_FALSE(err.message().empty());
    }
  }
  EXPECT_GT(failures, 0);
}

}  // namespace
}  // namespace sandpatch

// ---- presets (docs/tradeoff.md) ----
namespace sandpatch {
namespace {

TEST(ScenePreset, EveryPresetSetsItsKnobs) {
  ASSERT_EQ(simulation_presets().size(), 3u);
  for (const char* name : {"game", "balanced", "engineering"}) {
    const SimulationPreset* p = find_simulation_preset(name);
    ASSERT_NE(p, nullptr) << name;
    const auto r = parse(scene_with({{"simulation", {{"preset", name}}}}));
    ASSERT_TRUE(r.ok()) << all(r);
    EXPECT_EQ(r->simulation.preset, name);
    EXPECT_DOUBLE_EQ(r->terrain.particle_scale, p->particle_scale);
    EXPECT_EQ(r->terrain.granules_per_slot, p->granules_per_slot);
    EXPECT_EQ(r->terrain.steps_per_contact, p->steps_per_contact);
    // accurate from t_c / 20, stable to about t_c / 1.7 (docs/dem.md): presets stay in [10, 50]
    EXPECT_GE(p->steps_per_contact, 10);
    EXPECT_LE(p->steps_per_contact, 50);
    // A slot holds the same world volume: capacity x scale^3 stays within one 1024-block of 32768.
    EXPECT_GE(p->granules_per_slot * std::pow(p->particle_scale, 3), 32768.0 - 1e-9);
    EXPECT_LT((p->granules_per_slot - 1024) * std::pow(p->particle_scale, 3), 32768.0);
    EXPECT_EQ(p->granules_per_slot % 1024, 0);
  }
  EXPECT_EQ(find_simulation_preset("fast"), nullptr);
  // coarser granules from engineering to game
  EXPECT_LT(find_simulation_preset("engineering")->particle_scale, find_simulation_preset("balanced")->particle_scale);
  EXPECT_LT(find_simulation_preset("balanced")->particle_scale, find_simulation_preset("game")->particle_scale);
}

TEST(ScenePreset, ExplicitFieldsOverrideThePreset) {
  const auto r = parse(scene_with(
      {{"simulation", {{"particle_scale", 1.25}, {"preset", "game"}, {"pool", {{"slots", 2}}}}}}));
  ASSERT_TRUE(r.ok()) << all(r);
  EXPECT_EQ(r->simulation.preset, "game");
  EXPECT_DOUBLE_EQ(r->terrain.particle_scale, 1.25);  // given: wins, whatever the key order
  EXPECT_EQ(r->terrain.slots, 2);
  EXPECT_EQ(r->terrain.granules_per_slot, find_simulation_preset("game")->granules_per_slot);  // not given
  const auto r2 = parse(scene_with({{"simulation", {{"preset", "game"}, {"pool", {{"granules_per_slot", 2048}}}}}}));
  ASSERT_TRUE(r2.ok()) << all(r2);
  EXPECT_EQ(r2->terrain.granules_per_slot, 2048);
  EXPECT_EQ(r2->terrain.steps_per_contact, find_simulation_preset("game")->steps_per_contact);  // not given
  // steps_per_contact given beside a preset wins, before or after it
  const auto r3 = parse(scene_with({{"simulation", {{"steps_per_contact", 37}, {"preset", "game"}}}}));
  ASSERT_TRUE(r3.ok()) << all(r3);
  EXPECT_EQ(r3->terrain.steps_per_contact, 37);
}

TEST(SceneSimulation, ScaleByDistanceIsParsedAndRoundTrips) {
  const nlohmann::json cams = nlohmann::json::array({{{"name", "main"}, {"position", {0, 2, 10}}, {"target", {0, 0, 0}}}});
  const nlohmann::json sbd = {{"camera", "main"},
                              {"bands", {{{"max_distance", 10}, {"particle_scale", 1}},
                                         {{"max_distance", 25}, {"particle_scale", 1.5}},
                                         {{"max_distance", 60}, {"particle_scale", 2}}}}};
  const auto r = parse(scene_with({{"simulation", {{"scale_by_distance", sbd}}}, {"cameras", cams}}));
  ASSERT_TRUE(r.ok()) << all(r);
  ASSERT_TRUE(r->simulation.scale_by_distance.has_value());
  const auto& d = *r->simulation.scale_by_distance;
  EXPECT_EQ(d.camera, "main");
  ASSERT_EQ(d.bands.size(), 3u);
  EXPECT_EQ(d.bands[1].max_distance, 25.0);
  EXPECT_EQ(d.bands[2].particle_scale, 2.0);
  const nlohmann::json j = scene_to_json(*r);
  EXPECT_EQ(j["simulation"]["scale_by_distance"], sbd);
  const auto again = parse_scene(j.dump(), "again.json", kData);
  ASSERT_TRUE(again.ok()) << all(again);
  EXPECT_EQ(scene_to_json(*again), j);
  const auto plain = parse(scene_with(nlohmann::json::object()));
  ASSERT_TRUE(plain.ok()) << all(plain);
  EXPECT_FALSE(plain->simulation.scale_by_distance.has_value());
  EXPECT_FALSE(scene_to_json(*plain)["simulation"].contains("scale_by_distance"));
}

TEST(SceneSimulation, ScaleByDistanceErrorsNameFieldValueAndRange) {
  const nlohmann::json cams = nlohmann::json::array({{{"name", "main"}, {"position", {0, 2, 10}}, {"target", {0, 0, 0}}}});
  auto with = [&](const nlohmann::json& sbd) { return parse(scene_with({{"simulation", {{"scale_by_distance", sbd}}}, {"cameras", cams}})); };
  auto band = [](double d, double s) { return nlohmann::json{{"max_distance", d}, {"particle_scale", s}}; };
  // not ascending
  const auto order = with({{"camera", "main"}, {"bands", nlohmann::json::array({band(20, 1), band(10, 2)})}});
  EXPECT_TRUE(has_error(order, "simulation.scale_by_distance.bands[1].max_distance", "10", "greater than the previous")) << all(order);
  EXPECT_NE(all(order).find("follows 20 m"), std::string::npos) << all(order);
  // distance and scale out of range
  const auto range = with({{"camera", "main"}, {"bands", nlohmann::json::array({band(-1, 1), band(10, 0)})}});
  EXPECT_TRUE(has_error(range, "simulation.scale_by_distance.bands[0].max_distance", "-1", "(0, 10000000] m")) << all(range);
  EXPECT_TRUE(has_error(range, "simulation.scale_by_distance.bands[1].particle_scale", "0", "[0.001, 1000]")) << all(range);
  // unknown camera, with the near miss
  const auto cam = with({{"camera", "mian"}, {"bands", nlohmann::json::array({band(10, 1)})}});
  EXPECT_TRUE(has_error(cam, "simulation.scale_by_distance.camera", "\"mian\"", "must name a camera: main")) << all(cam);
  EXPECT_NE(all(cam).find("did you mean 'main'"), std::string::npos) << all(cam);
  // missing and empty bands, unknown key in a band
  EXPECT_TRUE(has_error(with({{"camera", "main"}}), "simulation.scale_by_distance.bands", "", "array of 1 to 16"));
  const auto empty = with({{"camera", "main"}, {"bands", nlohmann::json::array()}});
  EXPECT_TRUE(has_error(empty, "simulation.scale_by_distance.bands", "[]", "1 to 16 bands")) << all(empty);
  nlohmann::json odd = band(5, 1);
  odd["scale"] = 2;
  const auto key = with({{"camera", "main"}, {"bands", nlohmann::json::array({odd})}});
  ASSERT_FALSE(key.ok());
  EXPECT_NE(all(key).find("simulation.scale_by_distance.bands[0].scale"), std::string::npos) << all(key);
}

TEST(SceneSimulation, StepsPerContactDefaultsTo20AndIsChecked) {
  const auto plain = parse(scene_with(nlohmann::json::object()));
  ASSERT_TRUE(plain.ok()) << all(plain);
  EXPECT_EQ(plain->terrain.steps_per_contact, 20);  // the DEM's default, t_c / 20
  const auto given = parse(scene_with({{"simulation", {{"steps_per_contact", 50}}}}));
  ASSERT_TRUE(given.ok()) << all(given);
  EXPECT_EQ(given->terrain.steps_per_contact, 50);
  EXPECT_EQ(scene_to_json(*given)["simulation"]["steps_per_contact"], 50);
  // below 2 the DEM is unstable (t_c / 1.7), above 1000 absurd; fractions and strings are refused
  for (const nlohmann::json& bad : {nlohmann::json(1), nlohmann::json(1001), nlohmann::json(10.5), nlohmann::json("20")}) {
    const auto r = parse(scene_with({{"simulation", {{"steps_per_contact", bad}}}}));
    ASSERT_FALSE(r.ok()) << bad;
    ASSERT_EQ(r.errors().size(), 1u) << all(r);
    const Error& e = r.error();
    EXPECT_EQ(e.file, "test.json");
    EXPECT_EQ(e.field, "simulation.steps_per_contact");
    EXPECT_NE(e.value.find(bad.is_string() ? "20" : bad.dump()), std::string::npos) << e.message();
    EXPECT_NE(e.allowed.find("[2, 1000]"), std::string::npos) << e.message();
  }
}

TEST(ScenePreset, BadNameNamesFileFieldValueAndTheAllowedNames) {
  const auto r = parse(scene_with({{"simulation", {{"preset", "gmae"}}}}));
  ASSERT_FALSE(r.ok());
  ASSERT_EQ(r.errors().size(), 1u) << all(r);
  const Error& e = r.error();
  EXPECT_EQ(e.file, "test.json");
  EXPECT_EQ(e.field, "simulation.preset");
  EXPECT_NE(e.value.find("gmae"), std::string::npos);
  for (const char* name : {"game", "balanced", "engineering"}) EXPECT_NE(e.allowed.find(name), std::string::npos);
  EXPECT_NE(e.message().find("did you mean 'game'"), std::string::npos) << e.message();
  const auto wrong_type = parse(scene_with({{"simulation", {{"preset", 3}}}}));
  EXPECT_TRUE(has_error(wrong_type, "simulation.preset", "3", "game")) << all(wrong_type);
}

TEST(ScenePreset, CanonicalJsonKeepsThePresetAndScenesWithoutOneKeepTheirHash) {
  const auto r = parse(scene_with({{"simulation", {{"preset", "balanced"}}}}));
  ASSERT_TRUE(r.ok()) << all(r);
  const nlohmann::json j = scene_to_json(*r);
  EXPECT_EQ(j["simulation"]["preset"], "balanced");
  const auto again = parse_scene(j.dump(), "again.json", kData);
  ASSERT_TRUE(again.ok()) << all(again);
  EXPECT_EQ(scene_to_json(*again), j);
  const auto plain = parse(scene_with(nlohmann::json::object()));
  ASSERT_TRUE(plain.ok()) << all(plain);
  EXPECT_FALSE(scene_to_json(*plain)["simulation"].contains("preset"));
}

// The scene's name is its output directory (out/<name>): a name that would leave the output
// root or is not one file name is refused, naming the field; a plain one is kept.
TEST(Scene, NameMustBeOneFileName) {
  for (const char* bad : {"../../x", "/tmp/abs", "a/b", "..", ".", "a\\b", "tab\there"}) {
    SCOPED_TRACE(bad);
    auto r = parse(scene_with({{"name", bad}}));
    ASSERT_FALSE(r.ok());
    EXPECT_NE(r.message().find("name = "), std::string::npos) << r.message();
    EXPECT_NE(r.message().find("must be a file name"), std::string::npos) << r.message();
  }
  auto ok = parse(scene_with({{"name", "dune run-2"}}));
  ASSERT_TRUE(ok.ok()) << ok.message();
  EXPECT_EQ(ok->name, "dune run-2");
}

}  // namespace

// ---- hostile input (docs/reliability.md): refused at its root, naming file and field ----

TEST(SceneReliability, DeepNestingIsRefusedBeforeItIsBuilt) {
  // 70,000 levels of '[' once overflowed the stack.
  const auto r = broken("deep_nesting.json");
  ASSERT_EQ(r.ok() ? 0u : r.errors().size(), 1u) << all(r);
  EXPECT_NE(all(r).find("nested at most 256 deep"), std::string::npos) << all(r);
  EXPECT_NE(all(r).find("line 1, column 268"), std::string::npos) << all(r);  // the 256th [ is level 257
  // 256 levels are fine for the reader (the scene is then wrong, not unreadable).
  const std::string ok = "{\"terrain\": " + std::string(255, '[') + std::string(255, ']') + "}";
  const auto r2 = parse_scene(ok, "deep.json", "");
  EXPECT_EQ(all(r2).find("nested at most"), std::string::npos) << all(r2);
  // Brackets inside strings do not count.
  const std::string in_string = "{\"name\": \"" + std::string(1000, '[') + "\"}";
  EXPECT_EQ(all(parse_scene(in_string, "s.json", "")).find("nested at most"), std::string::npos);
}

TEST(SceneReliability, GridsArePassedTheMemoryCap) {
  const auto r = broken("grid_too_large.json");
  EXPECT_TRUE(has_error(r, "terrain.source.samples_x × samples_z", "65536 × 65536", "268435456")) << all(r);
  const auto p = broken("png_header_bomb.json");
  EXPECT_TRUE(has_error(p, "terrain.source.file", "heightmaps/bomb_65536.png", "268435456")) << all(p);
  // The cap itself is allowed: 16384 × 16384.
  const std::string at_cap = R"({"terrain": {"source": {"type": "procedural", "samples_x": 16384, "samples_z": 16384}},
                                 "materials": [{"name": "s", "restitution": 0.3}]})";
  EXPECT_TRUE(parse_scene(at_cap, "cap.json", "").ok()) << all(parse_scene(at_cap, "cap.json", ""));
}

// One side may be long while the product fits: samples per side are [2, 1048577]
// (knobs::kSamplesX, as the library's TerrainDef), the product is capped apart.
TEST(SceneReliability, LongNarrowGridsAreTakenUpToThePerSideLimit) {
  const auto grid = [](double nx) {
    return parse(scene_with({{"terrain", {{"source", {{"samples_x", nx}, {"samples_z", 2}}}}}}));
  };
  const auto r = grid(1048577);  // 2 097 154 samples, far under the cap
  ASSERT_TRUE(r.ok()) << all(r);
  EXPECT_EQ((*r).terrain.samples_x, 1048577);
  const auto over = grid(1048578);
  EXPECT_TRUE(has_error(over, "terrain.source.samples_x", "1048578", "[2, 1048577]")) << all(over);
}

TEST(SceneReliability, PoolIsCapped) {
  const auto r = broken("pool_too_large.json");
  EXPECT_TRUE(has_error(r, "simulation.pool.slots", "1024 × granules_per_slot 16777216", "4194304 granules")) << all(r);
}

TEST(SceneReliability, MassFromATinyShapeIsRefused) {
  // radius 1e-6 m and density 1e-3 kg/m³: 4e-21 kg, which run once met as "mass = 0.000000".
  const auto r = broken("zero_mass.json");
  EXPECT_TRUE(has_error(r, "bodies[0].density", "0.001", "mass in [1e-06, 1000000000] kg")) << all(r);
}

TEST(SceneReliability, SpeedIsCappedAsAMagnitude) {
  const auto r = broken("too_fast.json");
  EXPECT_TRUE(has_error(r, "bodies[0].linear_velocity", "[800,0,800]", "magnitude must be at most 1000 m/s")) << all(r);
}

TEST(SceneReliability, TinyDtIsRefused) {
  const auto r = broken("tiny_dt.json");
  EXPECT_TRUE(has_error(r, "simulation.duration", "10", "at most 100000000 steps")) << all(r);
}

TEST(SceneReliability, MeshCoordinatesMustBeFiniteAndInRange) {
  const auto n = broken("mesh_nan.json");
  EXPECT_TRUE(has_error(n, "bodies[0].shape.file", "meshes/nan_vertex.obj", "line 4")) << all(n);
  EXPECT_NE(all(n).find("not a finite number"), std::string::npos) << all(n);
  const auto h = broken("mesh_huge.json");
  EXPECT_TRUE(has_error(h, "bodies[0].shape.file", "meshes/huge_vertex.obj", "±1e9 m")) << all(h);
}
}  // namespace sandpatch

namespace sandpatch {
namespace {

// ---- loads ----

// The vehicle scene: a four-wheeled vehicle (tests/manager/vehicle_run_test.cpp checks its
// size and drive) and the ball dropped beside its path.
TEST(SceneLoads, VehicleDriveScene) {
  const auto r = load_scene_file(kScenes + "/vehicle_drive.json");
  ASSERT_TRUE(r.ok()) << all(r);
  ASSERT_EQ(r->vehicles.size(), 1u);
  EXPECT_EQ(r->vehicles[0].def.name, "car");
  ASSERT_EQ(r->bodies.size(), 1u);
  EXPECT_EQ(r->bodies[0].shape.kind, ShapeKind::Sphere);
}

TEST(SceneLoads, FieldsAndDefaults) {
  using nlohmann::json;
  json l0 = {{"force", {1.0, 2.0, 3.0}}};
  json l1 = {{"torque", {0.0, 4.0, 0.0}}, {"at", {0.0, 0.5, 0.0}}, {"force", {1.0, 0.0, 0.0}},
             {"from", 0.5},          {"until", 2.0},          {"frame", "body"}};
  json l2 = {{"impulse", {0.0, 3.0, 0.0}}, {"at", {0.1, 0.0, 0.0}}, {"from", 1.5}};
  json body = {{"name", "b"}, {"shape", {{"type", "sphere"}, {"radius", 0.5}}}, {"mass", 2.0}, {"loads", json::array({l0, l1, l2})}};
  json patch = json::object();
  patch["bodies"] = json::array({body});
  const auto r = parse(scene_with(patch));
  ASSERT_TRUE(r.ok()) << all(r);
  const auto& loads = r->bodies[0].loads;
  ASSERT_EQ(loads.size(), 3u);
  EXPECT_FALSE(loads[0].impulse.has_value());
  ASSERT_TRUE(loads[2].impulse.has_value());
  EXPECT_EQ(*loads[2].impulse, (Vec3d{0.0, 3.0, 0.0}));
  EXPECT_EQ(*loads[2].at, (Vec3d{0.1, 0.0, 0.0}));
  EXPECT_EQ(loads[2].from, 1.5);
  EXPECT_EQ(loads[0].force, (Vec3d{1.0, 2.0, 3.0}));
  EXPECT_EQ(loads[0].torque, (Vec3d{0.0, 0.0, 0.0}));
  EXPECT_FALSE(loads[0].at.has_value());
  EXPECT_EQ(loads[0].from, 0.0);
  EXPECT_FALSE(loads[0].until.has_value());
  EXPECT_EQ(loads[0].frame, LoadFrame::World);
  EXPECT_EQ(loads[1].torque, (Vec3d{0.0, 4.0, 0.0}));
  ASSERT_TRUE(loads[1].at.has_value());
  EXPECT_EQ(*loads[1].at, (Vec3d{0.0, 0.5, 0.0}));
  EXPECT_EQ(loads[1].from, 0.5);
  EXPECT_EQ(*loads[1].until, 2.0);
  EXPECT_EQ(loads[1].frame, LoadFrame::Body);
  // Written back and read again: the same scene.
  const auto b = parse_scene(scene_to_json(*r).dump(), "canonical.json", "");
  ASSERT_TRUE(b.ok()) << all(b);
  EXPECT_EQ(scene_to_json(*b), scene_to_json(*r));
}

// Every bad load is named by its field path with the value and what is allowed.
TEST(SceneLoads, BadLoadsNameTheField) {
  const auto r = broken("bad_loads.json");
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(has_error(r, "bodies[0].loads[0].force[0]", "\"nan\"", "NaN")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].loads[1].torque", "800000000", "at most 1000000000 N m")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].loads[2].at[1]", "20000", "[-10000, 10000] m")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].loads[3].until", "1", "greater than 'from' (2 s)")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].loads[4].frame", "\"wheel\"", "one of: world, body")) << all(r);
  EXPECT_TRUE(has_error(r, "bodies[0].loads[5].force", "", "'force' (N), 'torque' (N m) or both")) << all(r);
  EXPECT_EQ(r.errors().size(), 6u) << all(r);
  // More loads than a body may hold, a load that is not an object, `at` without a force.
  nlohmann::json many = nlohmann::json::array();
  const nlohmann::json one = {{"force", {1.0, 0.0, 0.0}}};
  for (int k = 0; k < kMaxLoadsPerBody + 1; ++k) many.push_back(one);
  auto body = [](const nlohmann::json& loads) {
    nlohmann::json b = {{"name", "b"}, {"shape", {{"type", "sphere"}, {"radius", 0.5}}}, {"mass", 2.0}};
    b["loads"] = loads;
    nlohmann::json patch = nlohmann::json::object();
    patch["bodies"] = nlohmann::json::array({b});
    return scene_with(patch);
  };
  const auto too_many = parse(body(many));
  EXPECT_TRUE(has_error(too_many, "bodies[0].loads", "257 loads", "at most 256")) << all(too_many);
  const auto not_object = parse(body(nlohmann::json::array({3.0})));
  EXPECT_TRUE(has_error(not_object, "bodies[0].loads[0]", "3", "object")) << all(not_object);
  const nlohmann::json torque_at = {{"torque", {0.0, 1.0, 0.0}}, {"at", {1.0, 0.0, 0.0}}};
  const auto at_alone = parse(body(nlohmann::json::array({torque_at})));
  EXPECT_TRUE(has_error(at_alone, "bodies[0].loads[0].at", "[1.0,0.0,0.0]", "give 'force' or 'impulse' too")) << all(at_alone);
  const auto not_array = parse(body(one));
  EXPECT_TRUE(has_error(not_array, "bodies[0].loads", "", "array")) << all(not_array);
  // An impulse: finite and bounded like a force, given once (no force, torque or until
  // beside it), its point within World::kMaxArm.
  const nlohmann::json bad_impulses = nlohmann::json::array(
      {{{"impulse", {1.0, "nan", 0.0}}},
       {{"impulse", {0.0, 2e9, 0.0}}},
       {{"impulse", {1.0, 0.0, 0.0}}, {"force", {1.0, 0.0, 0.0}}},
       {{"impulse", {1.0, 0.0, 0.0}}, {"until", 2.0}},
       {{"impulse", {1.0, 0.0, 0.0}}, {"at", {9000.0, 9000.0, 0.0}}}});
  const auto bad = parse(body(bad_impulses));
  EXPECT_TRUE(has_error(bad, "bodies[0].loads[0].impulse[1]", "\"nan\"", "NaN")) << all(bad);
  EXPECT_TRUE(has_error(bad, "bodies[0].loads[1].impulse[1]", "2000000000.0", "N s")) << all(bad);
  EXPECT_TRUE(has_error(bad, "bodies[0].loads[2].force", "[1.0,0.0,0.0]", "given once")) << all(bad);
  EXPECT_TRUE(has_error(bad, "bodies[0].loads[3].until", "2", "given once")) << all(bad);
  EXPECT_TRUE(has_error(bad, "bodies[0].loads[4].at", "[9000.0,9000.0,0.0]", "within 10000 m")) << all(bad);
}

// terrain.frame_budget_ms: a number of ms in (0, 1e6] or "off"; anything else is refused
// naming the field; written back by scene_to_json only when given.
TEST(Scene, FrameBudget) {
  auto off = parse(scene_with({{"simulation", {{"frame_budget_ms", "off"}}}}));
  ASSERT_TRUE(off.ok()) << all(off);
  ASSERT_TRUE(off->terrain.frame_budget_ms.has_value());
  EXPECT_TRUE(std::isinf(*off->terrain.frame_budget_ms));
  EXPECT_EQ(scene_to_json(*off)["simulation"]["frame_budget_ms"], "off");
  auto eight = parse(scene_with({{"simulation", {{"frame_budget_ms", 8.0}}}}));
  ASSERT_TRUE(eight.ok()) << all(eight);
  EXPECT_EQ(*eight->terrain.frame_budget_ms, 8.0);
  auto none = parse(scene_with(nlohmann::json::object()));
  ASSERT_TRUE(none.ok());
  EXPECT_FALSE(none->terrain.frame_budget_ms.has_value());
  EXPECT_FALSE(scene_to_json(*none)["simulation"].contains("frame_budget_ms"));
  for (const nlohmann::json& bad : {nlohmann::json(0.0), nlohmann::json(-1.0), nlohmann::json("fast"), nlohmann::json(2e6)}) {
    auto r = parse(scene_with({{"simulation", {{"frame_budget_ms", bad}}}}));
    ASSERT_FALSE(r.ok()) << bad;
    EXPECT_NE(r.message().find("simulation.frame_budget_ms"), std::string::npos) << r.message();
  }
}

}  // namespace
}  // namespace sandpatch

// The hysteretic normal spring (materials[].unloading_stiffness_ratio > 1) is read, on either
// backend (the GL backend keeps each contact's largest overlap in its spring slots), and a
// ratio below 1 is refused naming the range.
TEST(Scene, HystereticSpringIsReadOnBothBackends) {
  const std::string cpu = R"({"materials": [{"name": "sand", "restitution": 0.3, "unloading_stiffness_ratio": 11.1}],
    "terrain": {"source": {"type": "procedural", "kind": "flat", "samples_x": 9, "samples_z": 9}, "spacing": 0.5}})";
  auto ok = sandpatch::parse_scene(cpu, "hys.json", "");
  ASSERT_TRUE(ok.ok()) << ok.message();
  EXPECT_DOUBLE_EQ(ok->materials[0].unloading_stiffness_ratio, 11.1);
  std::string gl = cpu;
  gl.insert(gl.rfind('}'), R"(, "simulation": {"backend": "gl"})");
  auto on_gl = sandpatch::parse_scene(gl, "hys.json", "");
  ASSERT_TRUE(on_gl.ok()) << on_gl.message();
  EXPECT_DOUBLE_EQ(on_gl->materials[0].unloading_stiffness_ratio, 11.1);
  auto low = sandpatch::parse_scene(R"({"materials": [{"name": "sand", "restitution": 0.3, "unloading_stiffness_ratio": 0.5}],
    "terrain": {"source": {"type": "procedural", "kind": "flat", "samples_x": 9, "samples_z": 9}, "spacing": 0.5}})",
                                    "hys.json", "");
  ASSERT_FALSE(low.ok());
  EXPECT_NE(low.message().find("[1, 100]"), std::string::npos) << low.message();
}
