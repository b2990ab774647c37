#include "render/shaders.hpp"

#include <string>

#include "shaders/shaders.hpp"

namespace sandpatch::render {

namespace {

// `src` with common.glsl inserted after its first line (the #version line).
std::string with_common(std::string_view name) {
  std::string s(shaders::source(name));
  const auto eol = s.find('\n');
  const std::string head = eol == std::string::npos ? s : s.substr(0, eol + 1);
  const std::string tail = eol == std::string::npos ? "" : s.substr(eol + 1);
  return head + "#line 1 1\n" + std::string(shaders::source("render/common.glsl")) + "\n#line 2 0\n" + tail;
}

}  // namespace

Result<gl::Program> build_terrain_program() {
  return gl::Program::graphics("shaders/render/terrain.{vert,frag}", with_common("render/terrain.vert"),
                               with_common("render/terrain.frag"));
}
Result<gl::Program> build_particle_program() {
  return gl::Program::graphics("shaders/render/particles.{vert,frag}", with_common("render/particles.vert"),
                               with_common("render/particles.frag"));
}
Result<gl::Program> build_body_program() {
  return gl::Program::graphics("shaders/render/body.{vert,frag}", with_common("render/body.vert"),
                               with_common("render/body.frag"));
}
Result<gl::Program> build_ao_program() {
  return gl::Program::graphics("shaders/render/ao.{vert,frag}", with_common("render/ao.vert"),
                               with_common("render/ao.frag"));
}
Result<gl::Program> build_full_grid_program() {
  return gl::Program::graphics("shaders/render/full_grid.{vert,frag}", with_common("render/full_grid.vert"),
                               with_common("render/full_grid.frag"));
}

}  // namespace sandpatch::render
