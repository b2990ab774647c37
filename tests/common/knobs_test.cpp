// The knob table (common/knobs.hpp) against every copy of a default and every door: scene
// files, the public API, the internal definitions, the docs' field tables.
#include "common/knobs.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <set>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "manager/bullet_world.hpp"
#include "manager/lod.hpp"
#include "manager/run.hpp"
#include "manager/scene_world.hpp"
#include "manager/terrain_manager.hpp"
#include "sandpatch/sandpatch.hpp"
#include "scene/scene.hpp"

namespace sandpatch {
namespace {

using json = nlohmann::json;

// A small valid scene; each case below sets one field of it.
json base_scene() {
  return json::parse(R"({
    "name": "knobs",
    "terrain": {"source": {"type": "procedural", "kind": "flat", "samples_x": 17, "samples_z": 17}, "spacing": 0.5},
    "materials": [{"name": "sand", "restitution": 0.3}],
    "bodies": [{"name": "ball", "shape": {"type": "sphere", "radius": 0.2}, "mass": 5.0, "pose": {"position": [4.0, 1.0, 4.0]}}],
    "simulation": {"duration": 1.0}
  })");
}

// One knob: where it lives in a scene file, in the public definitions, and what each door
// and internal definition made from them holds.
struct Case {
  const knobs::Knob* knob;
  std::function<void(json&, double)> set_scene;                           // write v into a scene
  std::function<double(const SceneDef&)> scene_value;                     // what the parser read
  std::function<void(api::TerrainDef&, api::BodyDef&, double)> set_api;   // write v into the API's definitions
  double api_default;                                                     // the public header's default
  std::function<double(const SceneDef&)> internal_value;                  // what the World is made with
};

double manager_field(const SceneDef& s, const std::function<double(const TerrainManagerDef&)>& f) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = 2;
  return f(manager_def(s, Heightfield::create(g).value(), 1, "cpu"));
}
double body_field(const SceneDef& s, const std::function<double(const RigidBodyDef&)>& f) {
  return f(to_rigid_body(s, 0).value());
}

std::vector<Case> cases() {
  const api::TerrainDef td;
  const api::BodyDef bd;
  auto mat = [](const char* k) { return [k](json& j, double v) { j["materials"][0][k] = v; }; };
  auto sim = [](const char* k) { return [k](json& j, double v) { j["simulation"][k] = v; }; };
  auto sim2 = [](const char* a, const char* b) { return [a, b](json& j, double v) { j["simulation"][a][b] = v; }; };
  auto ter = [](const char* k) { return [k](json& j, double v) { j["terrain"][k] = v; }; };
  auto body = [](const char* k) { return [k](json& j, double v) { j["bodies"][0][k] = v; }; };
  using S = const SceneDef&;
  using M = const TerrainManagerDef&;
  using B = const RigidBodyDef&;
  using T = api::TerrainDef&;
  using D = api::BodyDef&;
  return {
      {&knobs::kGranuleRadius, mat("granule_radius"), [](S s) { return s.materials[0].granule_radius; },
       [](T t, D, double v) { t.material.granule_radius = v; }, td.material.granule_radius,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.radius); }); }},
      {&knobs::kDensity, mat("density"), [](S s) { return s.materials[0].density; },
       [](T t, D, double v) { t.material.density = v; }, td.material.density,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.density); }); }},
      {&knobs::kFriction, mat("friction"), [](S s) { return s.materials[0].friction; },
       [](T t, D, double v) { t.material.friction = v; }, td.material.friction,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.friction); }); }},
      {&knobs::kRestitution, mat("restitution"), [](S s) { return s.materials[0].restitution; },
       [](T t, D, double v) { t.material.restitution = v; }, td.material.restitution,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.restitution); }); }},
      {&knobs::kStiffness, mat("stiffness"), [](S s) { return s.materials[0].stiffness; },
       [](T t, D, double v) { t.material.stiffness = v; }, td.material.stiffness,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.stiffness); }); }},
      {&knobs::kTangentialRatio, mat("tangential_stiffness_ratio"), [](S s) { return s.materials[0].tangential_stiffness_ratio; },
       [](T t, D, double v) { t.material.tangential_stiffness_ratio = v; }, td.material.tangential_stiffness_ratio,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.tangential_stiffness_ratio); }); }},
      {&knobs::kUnloadingRatio, mat("unloading_stiffness_ratio"), [](S s) { return s.materials[0].unloading_stiffness_ratio; },
       [](T t, D, double v) { t.material.unloading_stiffness_ratio = v; }, td.material.unloading_stiffness_ratio,
       [](S s) { return manager_field(s, [](M m) { return double(m.material.unloading_stiffness_ratio); }); }},
      {&knobs::kSlots, sim2("pool", "slots"), [](S s) { return double(s.terrain.slots); },
       [](T t, D, double v) { t.slots = int(v); }, double(td.slots),
       [](S s) { return manager_field(s, [](M m) { return double(m.slots); }); }},
      {&knobs::kGranulesPerSlot, sim2("pool", "granules_per_slot"), [](S s) { return double(s.terrain.granules_per_slot); },
       [](T t, D, double v) { t.granules_per_slot = int(v); }, double(td.granules_per_slot),
       [](S s) { return manager_field(s, [](M m) { return double(m.granules_per_slot); }); }},
      {&knobs::kShellSpheresPerSlot, sim2("pool", "shell_spheres_per_slot"), [](S s) { return double(s.terrain.shell_spheres_per_slot); },
       [](T t, D, double v) { t.shell_spheres_per_slot = int(v); }, double(td.shell_spheres_per_slot),
       [](S s) { return manager_field(s, [](M m) { return double(m.shell_particles_per_slot); }); }},
      {&knobs::kParticleScale, sim("particle_scale"), [](S s) { return s.terrain.particle_scale; },
       [](T t, D, double v) { t.particle_scale = v; }, td.particle_scale,
       [](S s) { return manager_field(s, [](M m) { return m.particle_scale; }); }},
      {&knobs::kStepsPerContact, sim("steps_per_contact"), [](S s) { return double(s.terrain.steps_per_contact); },
       [](T t, D, double v) { t.steps_per_contact = int(v); }, double(td.steps_per_contact),
       [](S s) { return manager_field(s, [](M m) { return double(m.steps_per_contact); }); }},
      {&knobs::kMaxSubsteps, sim("max_substeps"), [](S s) { return double(s.terrain.max_substeps); },
       [](T t, D, double v) { t.max_substeps = int(v); }, double(td.max_substeps),
       [](S s) { return manager_field(s, [](M m) { return double(m.max_substeps); }); }},
      {&knobs::kPatchDepth, ter("patch_depth"), [](S s) { return s.terrain.patch_depth; },
       [](T t, D, double v) { t.patch_depth = v; }, td.patch_depth,
       [](S s) { return manager_field(s, [](M m) { return m.patch_depth; }); }},
      {&knobs::kSoilDepth, ter("soil_depth"), [](S s) { return s.terrain.soil_depth; },
       [](T t, D, double v) { t.soil_depth = v; }, td.soil_depth,
       [](S s) { return manager_field(s, [](M m) { return m.soil_depth; }); }},
      {&knobs::kSleepSpeed, sim2("sleep", "speed_threshold"), [](S s) { return s.terrain.sleep_speed; },
       [](T t, D, double v) { t.sleep_speed = v; }, td.sleep_speed,
       [](S s) { return manager_field(s, [](M m) { return m.sleep_speed; }); }},
      {&knobs::kSleepTime, sim2("sleep", "hold_time"), [](S s) { return s.terrain.sleep_time; },
       [](T t, D, double v) { t.sleep_time = v; }, td.sleep_time,
       [](S s) { return manager_field(s, [](M m) { return m.sleep_time; }); }},
      {&knobs::kRegionSleepTime, sim2("sleep", "region_hold_time"), [](S s) { return s.terrain.region_sleep_time; },
       [](T t, D, double v) { t.region_sleep_time = v; }, td.region_sleep_time,
       [](S s) { return manager_field(s, [](M m) { return m.region_sleep_time; }); }},
      {&knobs::kIdleTimeout, sim("idle_timeout"), [](S s) { return s.terrain.idle_timeout; },
       [](T t, D, double v) { t.idle_timeout = v; }, td.idle_timeout,
       [](S s) { return manager_field(s, [](M m) { return m.idle_timeout; }); }},
      {&knobs::kThreads, sim("threads"), [](S s) { return double(s.terrain.threads); },
       [](T t, D, double v) { t.threads = int(v); }, double(td.threads),
       [](S s) { return double(s.terrain.threads); }},  // the run picks the thread count (RunOptions)
      {&knobs::kLodHorizon, sim2("lod", "horizon"), [](S s) { return s.terrain.lod_horizon; },
       [](T t, D, double v) { t.lod_horizon = v; }, td.lod_horizon,
       [](S s) { return manager_field(s, [](M m) { return m.lod.horizon; }); }},
      {&knobs::kLodMargin, sim2("lod", "margin"), [](S s) { return s.terrain.lod_margin; },
       [](T t, D, double v) { t.lod_margin = v; }, td.lod_margin,
       [](S s) { return manager_field(s, [](M m) { return m.lod.margin; }); }},
      {&knobs::kLodApron, sim2("lod", "apron"), [](S s) { return s.terrain.lod_apron; },
       [](T t, D, double v) { t.lod_apron = v; }, td.lod_apron,
       [](S s) { return manager_field(s, [](M m) { return m.lod.apron; }); }},
      {&knobs::kBodyFriction, body("friction"), [](S s) { return s.bodies[0].friction; },
       [](T, D b, double v) { b.friction = v; }, bd.friction,
       [](S s) { return body_field(s, [](B b) { return double(b.friction); }); }},
      {&knobs::kBodyRestitution, body("restitution"), [](S s) { return s.bodies[0].restitution; },
       [](T, D b, double v) { b.restitution = v; }, bd.restitution,
       [](S s) { return body_field(s, [](B b) { return double(b.restitution); }); }},
      {&knobs::kBodyRollingFriction, body("rolling_friction"), [](S s) { return s.bodies[0].rolling_friction; },
       [](T, D b, double v) { b.rolling_friction = v; }, bd.rolling_friction,
       [](S s) { return body_field(s, [](B b) { return double(b.rolling_friction); }); }},
  };
}

// A value inside the range other than the default (integers whole).
double other_value(const knobs::Knob& k) {
  double v = k.def > 0 ? k.def * 0.5 : (k.lo + k.hi) * 0.5;
  if (v < k.lo || (k.lo_open && v == k.lo)) v = k.def * 2;  // (a default at the range's low end)
  if (k.integer) v = std::floor(v);
  if (v == k.def) v = k.def + 1;
  return v;
}
// A value outside the range.
double bad_value(const knobs::Knob& k) { return k.hi_open ? k.hi : k.hi * 10 + 1; }

TEST(Knobs, EveryKnobHasACaseAndBothDoors) {
  const auto cs = cases();
  ASSERT_EQ(cs.size(), knobs::kAll.size());
  for (std::size_t i = 0; i < cs.size(); ++i) {
    EXPECT_EQ(cs[i].knob, knobs::kAll[i]) << "cases() in the order of kAll";
    EXPECT_TRUE(*cs[i].knob->scene || *cs[i].knob->one_door) << cs[i].knob->api << ": no scene field and no reason";
    EXPECT_TRUE(*cs[i].knob->api || *cs[i].knob->one_door) << cs[i].knob->scene << ": no API field and no reason";
    EXPECT_TRUE(cs[i].knob->allows(cs[i].knob->def)) << cs[i].knob->scene << ": the default is outside its range";
  }
}

// The default agrees in the table, a scene that leaves the field out, the public header and
// the internal definition the World is made with.
TEST(Knobs, DefaultsAgreeEverywhere) {
  auto scene = parse_scene(base_scene().dump(), "knobs.json", "");
  ASSERT_TRUE(scene.ok()) << scene.message();
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.knob->scene);
    if (c.knob == &knobs::kRestitution) continue;  // a material must give restitution or damping_ratio
    EXPECT_DOUBLE_EQ(c.scene_value(*scene), c.knob->def) << "scene file";
    EXPECT_DOUBLE_EQ(c.api_default, c.knob->def) << "include/sandpatch/sandpatch.hpp";
    EXPECT_FLOAT_EQ(float(c.internal_value(*scene)), float(c.knob->def)) << "the internal definition";
  }
  // Internal definitions made without a scene.
  const TerrainManagerDef m;
  EXPECT_FLOAT_EQ(m.material.restitution, float(knobs::kRestitution.def));
  EXPECT_EQ(m.sleep_time, knobs::kSleepTime.def);
  const RigidBodyDef b;
  EXPECT_FLOAT_EQ(b.restitution, float(knobs::kBodyRestitution.def));
  const LodDef l;
  EXPECT_EQ(l.apron, knobs::kLodApron.def);
}

// A value other than the default written in a scene reaches the World's definitions.
TEST(Knobs, SceneValuesReachTheWorld) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.knob->scene);
    json j = base_scene();
    const double v = other_value(*c.knob);
    c.set_scene(j, v);
    auto scene = parse_scene(j.dump(), "knobs.json", "");
    ASSERT_TRUE(scene.ok()) << scene.message();
    EXPECT_DOUBLE_EQ(c.scene_value(*scene), v);
    EXPECT_FLOAT_EQ(float(c.internal_value(*scene)), float(v));
    // The canonical JSON (scene hash, `sandpatch check`) writes it back at the same path.
    const json canon = scene_to_json(*scene);
    const json* at = &canon;
    std::string path = c.knob->scene;
    for (std::size_t start = 0; start <= path.size();) {
      std::size_t dot = path.find('.', start);
      if (dot == std::string::npos) dot = path.size();
      std::string key = path.substr(start, dot - start);
      const bool array = key.ends_with("[]");
      if (array) key.resize(key.size() - 2);
      ASSERT_TRUE(at->contains(key)) << "scene_to_json has no " << path;
      at = &(*at)[key];
      if (array) at = &(*at)[0];
      start = dot + 1;
    }
    EXPECT_DOUBLE_EQ(at->get<double>(), v) << "scene_to_json at " << path;
  }
}

// A value outside the range is refused by both doors, naming the field.
TEST(Knobs, BothDoorsRefuseTheSameRange) {
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.knob->scene);
    const double v = bad_value(*c.knob);
    json j = base_scene();
    c.set_scene(j, v);
    auto scene = parse_scene(j.dump(), "knobs.json", "");
    ASSERT_FALSE(scene.ok()) << "scene file accepted " << v;
    std::string path = c.knob->scene;
    for (std::size_t p; (p = path.find("[]")) != std::string::npos;) path.replace(p, 2, "[0]");
    EXPECT_NE(scene.message().find(path), std::string::npos) << scene.message();

    api::TerrainDef t;
    t.procedural = "flat";
    t.samples_x = t.samples_z = 9;
    t.granular_patches = false;
    api::BodyDef b;
    b.position = {4.0, 2.0, 4.0};
    c.set_api(t, b, v);
    const bool body = std::string(c.knob->api).starts_with("BodyDef.");
    if (!body) {
      auto r = api::Terrain::create(t);
      ASSERT_FALSE(r.ok()) << "TerrainDef accepted " << v;
      EXPECT_NE(r.message().find(c.knob->api), std::string::npos) << r.message();
    } else {
      auto terrain = api::Terrain::create(t);
      ASSERT_TRUE(terrain.ok()) << terrain.message();
      auto h = terrain->add_body(b);
      ASSERT_FALSE(h.ok()) << "BodyDef accepted " << v;
      EXPECT_NE(h.message().find(c.knob->api), std::string::npos) << h.message();
    }
  }
}

// Every field path of a scene's canonical JSON ("bodies[].shape.radius").
void field_paths(const json& j, const std::string& path, std::vector<std::string>& out) {
  if (j.is_object()) {
    for (const auto& [k, v] : j.items()) field_paths(v, path.empty() ? k : path + "." + k, out);
  } else if (j.is_array() && !j.empty() && j[0].is_object()) {
    for (const auto& v : j) field_paths(v, path + "[]", out);
  } else {
    out.push_back(path);
  }
}

bool covers(const std::string& section, const std::string& path) {
  return path == section || path.starts_with(section + ".") || path.starts_with(section + "[");
}

// Every field of every shipped scene (and of the parser's test scene, which uses every
// section) is a knob, another listed setting, or part of the run's description: a new scene
// field must say what the library has for it, or why it has none.
TEST(Knobs, EverySceneFieldHasALibraryFieldOrAReason) {
  std::vector<std::string> files = {std::string(SANDPATCH_SOURCE_DIR) + "/tests/scene/data/full.json"};
  for (const auto& e : std::filesystem::directory_iterator(std::string(SANDPATCH_SOURCE_DIR) + "/scenes"))
    if (e.path().extension() == ".json") files.push_back(e.path().string());
  files.push_back("");  // base_scene() with a preset
  std::set<std::string> seen;
  json with_preset = base_scene();
  with_preset["simulation"]["preset"] = "game";  // no shipped scene uses a preset
  for (const auto& f : files) {
    auto scene = f.empty() ? parse_scene(with_preset.dump(), "preset.json", "") : load_scene_file(f);
    ASSERT_TRUE(scene.ok()) << scene.message();
    std::vector<std::string> paths;
    field_paths(scene_to_json(*scene), "", paths);
    for (const auto& p : paths) {
      seen.insert(p);
      bool ok = false;
      for (const knobs::Knob* k : knobs::kAll) ok = ok || p == k->scene;
      for (const knobs::Knob* k : knobs::kLimits) ok = ok || p == k->scene;
      for (const knobs::Field& o : knobs::kOtherFields) ok = ok || (*o.scene && covers(o.scene, p));
      for (const char* r : knobs::kRunSections) ok = ok || covers(r, p);
      EXPECT_TRUE(ok) << f << ": scene field " << p << " is in no table of common/knobs.hpp";
    }
  }
  // The tables name no scene field that does not exist.
  for (const knobs::Field& o : knobs::kOtherFields) {
    if (!*o.scene) {
      EXPECT_TRUE(*o.note) << o.api << ": a library-only field needs a reason";
      continue;
    }
    if (!*o.api) {
      EXPECT_TRUE(*o.note) << o.scene << ": a scene-only field needs a reason";
    }
    EXPECT_TRUE(std::any_of(seen.begin(), seen.end(), [&](const std::string& p) { return covers(o.scene, p); }))
        << o.scene << " is listed but no shipped scene has it";
  }
}

std::string read_file(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// docs/scene-format.md and docs/api.md hold the table knob_table_markdown() prints.
TEST(Knobs, DocsHoldTheTable) {
  for (const char* doc : {"docs/scene-format.md", "docs/api.md"}) {
    SCOPED_TRACE(doc);
    const std::string text = read_file(std::string(SANDPATCH_SOURCE_DIR) + "/" + doc);
    const std::string begin = "<!-- knobs:begin -->\n", end = "<!-- knobs:end -->";
    const auto a = text.find(begin), b = text.find(end);
    ASSERT_NE(a, std::string::npos) << "no " << begin;
    ASSERT_NE(b, std::string::npos) << "no " << end;
    EXPECT_EQ(text.substr(a + begin.size(), b - a - begin.size()), knobs::knob_table_markdown())
        << "regenerate the block with `sandpatch info --knobs`";
  }
}

// ---- the limits of shapes, cameras and outputs (knobs::kLimits) ----

// A scene with one body of `shape` and a camera that an output films.
json limits_scene(const json& shape) {
  json j = base_scene();
  j["bodies"][0]["shape"] = shape;
  j["cameras"] = json::parse(R"([{"name": "cam", "position": [0, 5, 10], "target": [4, 0, 4]}])");
  j["outputs"] = json::parse(R"({"frames": [{"camera": "cam", "times": [0.5]}]})");
  return j;
}
const std::string kBarrel = std::string(SANDPATCH_SOURCE_DIR) + "/scenes/meshes/barrel.obj";

struct LimitCase {
  const knobs::Knob* knob;
  std::function<json(double)> scene;                 // a scene with the value at the limit's field
  std::string scene_field;                           // the field its error names
  std::function<void(api::BodyDef&, double)> set_api;  // nullptr: a scene-only limit or a terrain one
  std::string api_field;
  std::function<void(api::TerrainDef&, double)> set_terrain = nullptr;  // a limit of TerrainDef
};

std::vector<LimitCase> limit_cases() {
  const json sphere = {{"type", "sphere"}, {"radius", 0.2}};
  auto with = [](json shape, const char* key, double v) {
    shape[key] = v;
    return limits_scene(shape);
  };
  auto cam = [sphere](const char* key) {
    return [sphere, key](double v) {
      json j = limits_scene(sphere);
      j["cameras"][0][key] = v;
      return j;
    };
  };
  // The terrain's source: the scene's terrain section, the library's TerrainDef.
  auto source = [](const char* key) {
    return [key](double v) {
      json j = limits_scene({{"type", "sphere"}, {"radius", 0.2}});
      j["terrain"]["source"][key] = v;
      return j;
    };
  };
  auto terrain = [](const char* key) {
    return [key](double v) {
      json j = limits_scene({{"type", "sphere"}, {"radius", 0.2}});
      j["terrain"][key] = v;
      return j;
    };
  };
  using T = api::TerrainDef&;
  return {
      {&knobs::kBaseHeight, source("height"), "terrain.source.height", nullptr, "TerrainDef.base_height",
       [](T t, double v) { t.base_height = float(v); }},
      {&knobs::kSlopeX, source("slope_x"), "terrain.source.slope_x", nullptr, "TerrainDef.slope_x",
       [](T t, double v) { t.slope_x = float(v); }},
      {&knobs::kSlopeZ, source("slope_z"), "terrain.source.slope_z", nullptr, "TerrainDef.slope_z",
       [](T t, double v) { t.slope_z = float(v); }},
      {&knobs::kAmplitude, source("amplitude"), "terrain.source.amplitude", nullptr, "TerrainDef.amplitude",
       [](T t, double v) { t.amplitude = float(v); }},
      {&knobs::kWavelength, source("wavelength"), "terrain.source.wavelength", nullptr, "TerrainDef.wavelength",
       [](T t, double v) { t.wavelength = float(v); }},
      {&knobs::kOctaves, source("octaves"), "terrain.source.octaves", nullptr, "TerrainDef.octaves",
       [](T t, double v) { t.octaves = int(v); }},
      {&knobs::kSamplesX, source("samples_x"), "terrain.source.samples_x", nullptr, "TerrainDef.samples_x",
       [](T t, double v) { t.samples_x = int(v); }},
      {&knobs::kSamplesZ, source("samples_z"), "terrain.source.samples_z", nullptr, "TerrainDef.samples_z",
       [](T t, double v) { t.samples_z = int(v); }},
      {&knobs::kSpacing, terrain("spacing"), "terrain.spacing", nullptr, "TerrainDef.spacing",
       [](T t, double v) { t.spacing = v; }},
      {&knobs::kVerticalScale, terrain("vertical_scale"), "terrain.vertical_scale", nullptr, "TerrainDef.vertical_scale",
       [](T t, double v) { t.vertical_scale = v; }},
      {&knobs::kVerticalOffset, terrain("vertical_offset"), "terrain.vertical_offset", nullptr, "TerrainDef.vertical_offset",
       [](T t, double v) { t.vertical_offset = v; }},
      {&knobs::kShapeRadius, [=](double v) { return with(sphere, "radius", v); }, "bodies[0].shape.radius",
       [](api::BodyDef& b, double v) { b.shape.radius = v; }, "BodyDef.shape.radius"},
      {&knobs::kShapeHalfExtent,
       [](double v) { return limits_scene({{"type", "box"}, {"half_extents", {0.2, v, 0.2}}}); }, "bodies[0].shape.half_extents[1]",
       [](api::BodyDef& b, double v) {
         b.shape.kind = api::ShapeKind::Box;
         b.shape.half_extents = {0.2, v, 0.2};
       },
       "BodyDef.shape.half_extents[1]"},
      {&knobs::kCylinderHeight, [=](double v) { return with({{"type", "cylinder"}, {"radius", 0.2}}, "height", v); },
       "bodies[0].shape.height",
       [](api::BodyDef& b, double v) {
         b.shape.kind = api::ShapeKind::Cylinder;
         b.shape.height = v;
       },
       "BodyDef.shape.height"},
      {&knobs::kCapsuleHeight, [=](double v) { return with({{"type", "capsule"}, {"radius", 0.2}}, "height", v); },
       "bodies[0].shape.height",
       [](api::BodyDef& b, double v) {
         b.shape.kind = api::ShapeKind::Capsule;
         b.shape.height = v;
       },
       "BodyDef.shape.height"},
      {&knobs::kMeshScale, [=](double v) { return with({{"type", "mesh"}, {"file", kBarrel}}, "scale", v); }, "bodies[0].shape.scale",
       [](api::BodyDef& b, double v) {
         b.shape.kind = api::ShapeKind::Mesh;
         b.shape.mesh_file = kBarrel;
         b.shape.mesh_scale = v;
       },
       "BodyDef.shape.mesh_scale"},
      {&knobs::kCameraFov, cam("fov_deg"), "cameras[0].fov_deg", nullptr, ""},
      {&knobs::kCameraWidth, cam("width"), "cameras[0].width", nullptr, ""},
      {&knobs::kCameraHeight, cam("height"), "cameras[0].height", nullptr, ""},
      {&knobs::kCameraKeyTime,
       [=](double v) {
         json j = limits_scene(sphere);
         j["cameras"][0].erase("position");
         j["cameras"][0].erase("target");
         j["cameras"][0]["path"] = {{{"time", v}, {"position", {0, 5, 10}}, {"target", {4, 0, 4}}}};
         return j;
       },
       "cameras[0].path[0].time", nullptr, ""},
      {&knobs::kOutputTime,
       [=](double v) {
         json j = limits_scene(sphere);
         j["outputs"]["frames"][0]["times"] = {v};
         return j;
       },
       "outputs.frames[0].times[0]", nullptr, ""},
      {&knobs::kEveryKFrames,
       [=](double v) {
         json j = limits_scene(sphere);
         j["outputs"]["frames"][0].erase("times");
         j["outputs"]["frames"][0]["every_k_frames"] = v;
         return j;
       },
       "outputs.frames[0].every_k_frames", nullptr, ""},
      // kVideoFps: a command-line option, refused by the run (tests/manager/run_outputs_test.cpp).
  };
}

// Values outside a limit's range at both ends (a whole number inside it for integers).
std::vector<double> outside(const knobs::Knob& k) {
  return {k.hi_open ? k.hi : k.hi * 10 + 1, k.lo_open ? k.lo : (k.lo > 0 ? k.lo / 2 : k.lo - 1)};
}

TEST(Knobs, EveryLimitHasACase) {
  const auto cs = limit_cases();
  ASSERT_EQ(cs.size() + 1, knobs::kLimits.size()) << "every limit but kVideoFps has a case";
  for (std::size_t i = 0; i < cs.size(); ++i) {
    EXPECT_EQ(cs[i].knob, knobs::kLimits[i]) << "limit_cases() in the order of kLimits";
    EXPECT_EQ(cs[i].scene_field.substr(0, cs[i].scene_field.find('[')),
              std::string(cs[i].knob->scene).substr(0, std::string(cs[i].knob->scene).find('[')));
    EXPECT_EQ(cs[i].set_api != nullptr || cs[i].set_terrain != nullptr, *cs[i].knob->api != '\0') << cs[i].knob->scene;
    EXPECT_FALSE(cs[i].set_api && cs[i].set_terrain) << cs[i].knob->scene << ": a BodyDef or a TerrainDef field, not both";
    if (*cs[i].knob->api) EXPECT_EQ(cs[i].api_field.substr(0, cs[i].api_field.find('[')), cs[i].knob->api);
    EXPECT_TRUE(*cs[i].knob->api || *cs[i].knob->one_door) << cs[i].knob->scene << ": no API field and no reason";
  }
  for (const knobs::Knob* k : knobs::kLimits)
    EXPECT_TRUE(std::isnan(k->def) || k->allows(k->def)) << k->scene << ": the default is outside its range";
}

// A value inside the range is taken by both doors; one outside, at either end, is refused by
// both, naming the field, the value and the table's range.
TEST(Knobs, BothDoorsRefuseTheSameLimits) {
  for (const LimitCase& c : limit_cases()) {
    SCOPED_TRACE(c.knob->scene);
    const double inside = std::isnan(c.knob->def) ? c.knob->lo : c.knob->def;
    auto good = parse_scene(c.scene(inside).dump(), "limits.json", "");
    ASSERT_TRUE(good.ok()) << inside << ": " << good.message();
    for (double v : outside(*c.knob)) {
      auto scene = parse_scene(c.scene(v).dump(), "limits.json", "");
      ASSERT_FALSE(scene.ok()) << "scene file accepted " << v;
      EXPECT_NE(scene.message().find(c.scene_field), std::string::npos) << scene.message();
      const std::string range = format_number(c.knob->lo) + ", " + format_number(c.knob->hi);
      EXPECT_NE(scene.message().find(range), std::string::npos) << scene.message();
      if (c.set_terrain) {
        // The library's TerrainDef: a small generated grid, the value in its field.
        api::TerrainDef t;
        t.procedural = "flat";
        t.samples_x = t.samples_z = 9;
        t.granular_patches = false;
        c.set_terrain(t, inside);
        auto ok = api::Terrain::create(t);
        EXPECT_TRUE(ok.ok()) << "TerrainDef refused " << inside << ": " << ok.message();
        c.set_terrain(t, v);
        auto bad = api::Terrain::create(t);
        ASSERT_FALSE(bad.ok()) << "TerrainDef accepted " << v;
        EXPECT_NE(bad.message().find(c.api_field + " = "), std::string::npos) << bad.message();
        EXPECT_NE(bad.message().find(knobs::describe_range(*c.knob)), std::string::npos) << bad.message();
      }
      if (!c.set_api) continue;
      api::TerrainDef t;
      t.procedural = "flat";
      t.samples_x = t.samples_z = 9;
      t.granular_patches = false;
      auto terrain = api::Terrain::create(t);
      ASSERT_TRUE(terrain.ok()) << terrain.message();
      api::BodyDef b;
      b.position = {4.0, 2.0, 4.0};
      c.set_api(b, inside);
      EXPECT_TRUE(terrain->add_body(b).ok()) << "BodyDef refused " << inside;
      c.set_api(b, v);
      auto h = terrain->add_body(b);
      ASSERT_FALSE(h.ok()) << "BodyDef accepted " << v;
      EXPECT_NE(h.message().find(c.api_field), std::string::npos) << h.message();
      EXPECT_NE(h.message().find(knobs::describe_range(*c.knob)), std::string::npos) << h.message();
    }
  }
}

// The defaults of the table are those of the public TerrainDef and ShapeDef, the scene's
// cameras and the run.
TEST(Knobs, LimitDefaultsAgree) {
  const api::TerrainDef t;  // scene files' terrain is the library's (scene.hpp TerrainDef)
  EXPECT_EQ(t.base_height, knobs::kBaseHeight.def);
  EXPECT_EQ(t.slope_x, knobs::kSlopeX.def);
  EXPECT_EQ(t.slope_z, knobs::kSlopeZ.def);
  EXPECT_EQ(t.amplitude, knobs::kAmplitude.def);
  EXPECT_EQ(t.wavelength, knobs::kWavelength.def);
  EXPECT_EQ(t.octaves, knobs::kOctaves.def);
  EXPECT_EQ(t.spacing, knobs::kSpacing.def);
  EXPECT_EQ(t.vertical_scale, knobs::kVerticalScale.def);
  EXPECT_EQ(t.vertical_offset, knobs::kVerticalOffset.def);
  EXPECT_TRUE(std::isnan(knobs::kSamplesX.def) && std::isnan(knobs::kSamplesZ.def)) << "the library has no default sample count";
  const api::ShapeDef a;  // scene files' shapes are the library's
  EXPECT_EQ(a.radius, knobs::kShapeRadius.def);
  EXPECT_EQ(a.half_extents[0], knobs::kShapeHalfExtent.def);
  EXPECT_EQ(a.height, knobs::kCylinderHeight.def);
  EXPECT_EQ(a.height, knobs::kCapsuleHeight.def);
  EXPECT_EQ(a.mesh_scale, knobs::kMeshScale.def);
  const CameraDef cam;
  EXPECT_EQ(cam.fov_deg, knobs::kCameraFov.def);
  EXPECT_EQ(cam.width, knobs::kCameraWidth.def);
  EXPECT_EQ(cam.height, knobs::kCameraHeight.def);
  EXPECT_EQ(RunOptions{}.video_fps, knobs::kVideoFps.def);
}

}  // namespace
}  // namespace sandpatch
