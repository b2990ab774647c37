#include "render/shaders.hpp"

#include <string>

#include "shaders/shaders.hpp"

namespace sandpatch::render {

namespace {

// `s` (whose first line is line `first_line` of its file) with each line `#include "NAME"`
// replaced by shaders/render/NAME (source string 2 in the GLSL compiler's messages), or by an
// #error naming it when there is no such file. One level: an included file's own #include lines
// are left to fail in the compiler.
std::string expand_includes(const std::string& s, int first_line) {
  std::string out;
  int line = first_line - 1;
  for (std::size_t a = 0; a < s.size();) {
    std::size_t b = s.find('\n', a);
    if (b == std::string::npos) b = s.size();
    const std::string l = s.substr(a, b - a);
    ++line;
    const std::string key = "#include \"";
    if (l.rfind(key, 0) == 0 && l.find('"', key.size()) != std::string::npos) {
      const std::string name = l.substr(key.size(), l.find('"', key.size()) - key.size());
      const std::string_view text = shaders::source("render/" + name);
      if (text.empty()) {
        out += "#error no shader render/" + name + " to include\n";
      } else {
        out += "#line 1 2\n" + std::string(text) + "\n#line " + std::to_string(line + 1) + " 0\n";
      }
    } else {
      out += l + "\n";
    }
    a = b + 1;
  }
  return out;
}

// `src` with common.glsl inserted after its first line (the #version line) and its #include
// lines expanded.
std::string with_common(std::string_view name) {
  std::string s(shaders::source(name));
  const auto eol = s.find('\n');
  const std::string head = eol == std::string::npos ? s : s.substr(0, eol + 1);
  const std::string tail = eol == std::string::npos ? "" : s.substr(eol + 1);
  return head + "#line 1 1\n" + std::string(shaders::source("render/common.glsl")) + "\n#line 2 0\n" +
         expand_includes(tail, 2);
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
Result<gl::Program> build_bed_blur_program() {
  return gl::Program::graphics("shaders/render/{ao.vert,bed_blur.frag}", with_common("render/ao.vert"),
                               with_common("render/bed_blur.frag"));
}
Result<gl::Program> build_full_grid_program() {
  return gl::Program::graphics("shaders/render/full_grid.{vert,frag}", with_common("render/full_grid.vert"),
                               with_common("render/full_grid.frag"));
}

}  // namespace sandpatch::render
