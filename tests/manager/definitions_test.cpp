// The one definition chain (manager/definitions.hpp): scene files and the library's
// definitions go through the same validation, heightfield builder and body mapping.
#include "manager/definitions.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "manager/scene_world.hpp"
#include "manager/terrain.hpp"
#include "scene/scene.hpp"

namespace sandpatch {
namespace {

const std::string kScenes = SANDPATCH_SOURCE_DIR "/scenes";

std::string all(const std::vector<Error>& es) {
  std::string m;
  for (const auto& e : es) m += e.message() + "\n";
  return m;
}

// Every shipped scene, mapped onto the library's definitions, passes the library's own
// validation: the two doors accept the same settings.
TEST(Definitions, EveryShippedSceneIsAValidLibraryDefinition) {
  int scenes = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kScenes)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(entry.path().string());
    auto scene = load_scene_file(entry.path().string());
    ASSERT_TRUE(scene.ok()) << scene.message();
    const api::TerrainDef t = terrain_def(*scene, 0, scene->terrain.backend);
    EXPECT_TRUE(validate(t).empty()) << all(validate(t));
    for (std::size_t i = 0; i < scene->bodies.size(); ++i) {
      auto b = rigid_body_def(body_def(*scene, i));
      EXPECT_TRUE(b.ok()) << b.message();
    }
    ++scenes;
  }
  EXPECT_GE(scenes, 10);
}

// vertical_scale and vertical_offset apply to every source, the generator's heights too
// (as in scene files): height = offset + scale · value.
TEST(Definitions, VerticalScaleAppliesToTheGenerator) {
  api::TerrainDef t;
  t.procedural = "plane";
  t.base_height = 1.0f;
  t.slope_x = 0.5f;
  t.samples_x = t.samples_z = 5;
  t.spacing = 2.0;
  t.vertical_scale = 3.0;
  t.vertical_offset = -0.5;
  ASSERT_TRUE(validate(t).empty());
  auto hf = build_heightfield(t);
  ASSERT_TRUE(hf.ok()) << hf.message();
  for (int i = 0; i < 5; ++i) EXPECT_NEAR(hf->height(i, 2), -0.5 + 3.0 * (1.0 + 0.5 * 2.0 * i), 1e-5) << i;
}

// file_type reads a heightmap whatever its extension (scene files name the type); without
// it the extension decides, and an unknown one is refused naming the field.
TEST(Definitions, FileTypeReadsAnyExtension) {
  const std::string path = (std::filesystem::temp_directory_path() / "sandpatch_definitions_test.heights").string();
  {
    std::ofstream f(path, std::ios::binary);
    for (int k = 0; k < 9; ++k) {
      const float v = 0.25f * k;
      f.write(reinterpret_cast<const char*>(&v), sizeof v);
    }
  }
  api::TerrainDef t;
  t.file = path;
  t.samples_x = t.samples_z = 3;
  auto no_type = validate(t);
  ASSERT_EQ(no_type.size(), 1u) << all(no_type);
  EXPECT_EQ(no_type[0].field, "TerrainDef.file");
  t.file_type = "raw_f32";
  ASSERT_TRUE(validate(t).empty()) << all(validate(t));
  auto hf = build_heightfield(t);
  ASSERT_TRUE(hf.ok()) << hf.message();
  EXPECT_NEAR(hf->height(2, 2), 0.25 * 8, 1e-6);
  t.file_type = "tiff";
  auto bad = validate(t);
  ASSERT_EQ(bad.size(), 1u) << all(bad);
  EXPECT_EQ(bad[0].field, "TerrainDef.file_type");
  EXPECT_EQ(bad[0].value, "\"tiff\"");
  std::remove(path.c_str());
}

// A scene body's errors from the shared mapping name the scene's field.
TEST(Definitions, SceneBodyErrorsNameTheSceneField) {
  auto scene = load_scene_file(kScenes + "/barrel_drop.json");
  ASSERT_TRUE(scene.ok()) << scene.message();
  scene->bodies[0].shape.kind = ShapeKind::Sphere;
  scene->bodies[0].shape.radius = -1.0;  // what the parser would have refused
  auto r = to_rigid_body(*scene, 0);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors()[0].field, "bodies[0].shape.radius");
}

}  // namespace
}  // namespace sandpatch

namespace sandpatch {
namespace {

// A body whose particle shell does not fit a slot is refused before the run (also by
// `sandpatch check`, which builds no pool), naming the capacity to raise and what it needs.
TEST(Definitions, ABodyTooBigForTheShellCapacityIsRefusedBeforeTheRun) {
  auto scene = load_scene_file(kScenes + "/barrel_drop.json");
  ASSERT_TRUE(scene.ok()) << scene.message();
  scene->terrain.shell_spheres_per_slot = 64;
  auto world = make_world(*scene, 1, "cpu", nullptr, /*patches=*/false);
  ASSERT_FALSE(world.ok());
  const Error& e = world.errors()[0];
  EXPECT_EQ(e.field, "simulation.pool.shell_spheres_per_slot");
  EXPECT_EQ(e.value, "64");
  EXPECT_NE(e.allowed.find("too small for a body shell of"), std::string::npos) << e.message();
  EXPECT_NE(e.detail.find("bodies[0]"), std::string::npos) << e.message();
  scene->terrain.shell_spheres_per_slot = 8192;
  EXPECT_TRUE(make_world(*scene, 1, "cpu", nullptr, false).ok());
}

}  // namespace
}  // namespace sandpatch
