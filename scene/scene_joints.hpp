// The scene file's machine sections (docs/scene-format.md "joints"), parsed and checked apart
// from scene.cpp's sections: parse_scene calls these.
#pragma once

#include <string>
#include <vector>

#include "scene/scene.hpp"
// json_reader.hpp uses Vec3d from scene.hpp
#include "scene/json_reader.hpp"

namespace sandpatch::scene_json {

// The top-level "joints" array.
std::vector<JointDef> parse_joints(Ctx& c, const json& j);
// The top-level "vehicles" array: each checked with check_vehicle (scene/vehicle.hpp).
std::vector<VehicleSceneDef> parse_vehicles(Ctx& c, const json& j);
// Cross references once bodies are known: body names exist, not the same on both sides, not
// two non-dynamic sides; unique joint names; vehicles' names unique and their parts' names
// unlike every body's.
void check_joints(Ctx& c, const SceneDef& s);

}  // namespace sandpatch::scene_json
