// Builds the heightfield a scene describes (file formats or a generator) and answers the
// bedrock questions that need the loaded terrain.
#pragma once

#include "common/error.hpp"
#include "heightfield/heightfield.hpp"
#include "scene/scene.hpp"

namespace sandpatch {

// Loads or generates scene.terrain. Errors name the scene file, the terrain field and,
// for heightmap files, the heightmap file (nothing is run before this succeeds).
Result<Heightfield> load_scene_terrain(const SceneDef& scene);

// World height (m) of the bedrock under world (x, z): a flat bedrock_height above the
// origin, or the surface minus soil_depth (default 2 m, docs/scene-format.md).
double bedrock_world_height(const SceneDef& scene, const Heightfield& hf, double x, double z);

}  // namespace sandpatch
