// GLSL sources compiled into the library (cmake/embed_shaders.cmake).
#pragma once

#include <string_view>

namespace sandpatch::shaders {

// The text of shaders/<name>, e.g. source("convert/particle_depth.vert"); empty if unknown.
std::string_view source(std::string_view name);

}  // namespace sandpatch::shaders
