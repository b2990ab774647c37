#include "render/shaders.hpp"

#include <string>

#include "render/shader_sources.hpp"

namespace sandpatch::render {

namespace {

// `src` with common.glsl inserted after its first line (the #version line).
std::string with_common(const char* src) {
  std::string s = src;
  const auto eol = s.find('\n');
  const std::string head = eol == std::string::npos ? s : s.substr(0, eol + 1);
  const std::string tail = eol == std::string::npos ? "" : s.substr(eol + 1);
  return head + "#line 1 1\n" + shader_common_glsl + "\n#line 2 0\n" + tail;
}

}  // namespace

Result<gl::Program> build_terrain_program() {
  return gl::Program::graphics("shaders/render/terrain.{vert,frag}", with_common(shader_terrain_vert),
                               with_common(shader_terrain_frag));
}
Result<gl::Program> build_particle_program() {
  return gl::Program::graphics("shaders/render/particles.{vert,frag}", with_common(shader_particles_vert),
                               with_common(shader_particles_frag));
}
Result<gl::Program> build_full_grid_program() {
  return gl::Program::graphics("shaders/render/full_grid.{vert,frag}", with_common(shader_full_grid_vert),
                               with_common(shader_full_grid_frag));
}

}  // namespace sandpatch::render
