// Scene reader: any text → parse_scene (parse + every validation check, no run). Relative
// paths resolve against scenes/, so seeds that name meshes and heightmaps load them too.
#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "scene/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  auto r = sandpatch::parse_scene(text, "fuzz.json", SANDPATCH_FUZZ_SCENES_DIR);
  if (r) (void)sandpatch::scene_to_json(*r).dump();  // what a valid scene is written back as
  else if (r.errors().empty()) __builtin_trap();     // a refusal always says why
  return 0;
}
