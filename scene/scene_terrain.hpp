// The scene file's terrain section (docs/scene-format.md "terrain"), parsed and checked apart
// from scene.cpp's sections: parse_scene calls it.
#pragma once

#include "scene/scene.hpp"
// json_reader.hpp uses Vec3d from scene.hpp
#include "scene/json_reader.hpp"

namespace sandpatch::scene_json {

// The terrain section into the library's fields of `t` (scene.hpp TerrainDef): the source
// (its files' headers checked), spacing or size, vertical scale and offset, origin, soil and
// patch depths, the material's name.
void parse_terrain(Ctx& c, const json& j, TerrainDef& t);

}  // namespace sandpatch::scene_json
