#include "gl/program.hpp"

#include <GL/glcorearb.h>

#include <vector>

namespace sandpatch::gl {
namespace {

std::string shader_log(GLuint s) {
  GLint n = 0;
  glGetShaderiv(s, GL_INFO_LOG_LENGTH, &n);
  std::string log(static_cast<std::size_t>(n > 0 ? n : 1), '\0');
  glGetShaderInfoLog(s, n, nullptr, log.data());
  return log.c_str();
}

std::string program_log(GLuint p) {
  GLint n = 0;
  glGetProgramiv(p, GL_INFO_LOG_LENGTH, &n);
  std::string log(static_cast<std::size_t>(n > 0 ? n : 1), '\0');
  glGetProgramInfoLog(p, n, nullptr, log.data());
  return log.c_str();
}

Result<GLuint> compile(const std::string& name, GLenum stage, const std::string& src) {
  GLuint s = glCreateShader(stage);
  const char* p = src.c_str();
  glShaderSource(s, 1, &p, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    std::string log = shader_log(s);
    glDeleteShader(s);
    return Error{name, "", "", "GLSL compile error", log};
  }
  return s;
}

Result<GLuint> link(const std::string& name, const std::vector<GLuint>& shaders) {
  GLuint p = glCreateProgram();
  for (GLuint s : shaders) glAttachShader(p, s);
  glLinkProgram(p);
  for (GLuint s : shaders) {
    glDetachShader(p, s);
    glDeleteShader(s);
  }
  GLint ok = 0;
  glGetProgramiv(p, GL_LINK_STATUS, &ok);
  if (!ok) {
    std::string log = program_log(p);
    glDeleteProgram(p);
    return Error{name, "", "", "GLSL link error", log};
  }
  return p;
}

}  // namespace

Program::~Program() {
  if (id_) glDeleteProgram(id_);
}

Program& Program::operator=(Program&& o) noexcept {
  if (this != &o) {
    if (id_) glDeleteProgram(id_);
    id_ = o.id_;
    o.id_ = 0;
  }
  return *this;
}

Result<Program> Program::compute(const std::string& name, const std::string& source) {
  auto s = compile(name, GL_COMPUTE_SHADER, source);
  if (!s) return s.errors();
  auto p = link(name, {*s});
  if (!p) return p.errors();
  return Program(*p);
}

Result<Program> Program::graphics(const std::string& name, const std::string& vs, const std::string& fs) {
  auto v = compile(name + " (vertex)", GL_VERTEX_SHADER, vs);
  if (!v) return v.errors();
  auto f = compile(name + " (fragment)", GL_FRAGMENT_SHADER, fs);
  if (!f) {
    glDeleteShader(*v);
    return f.errors();
  }
  auto p = link(name, {*v, *f});
  if (!p) return p.errors();
  return Program(*p);
}

}  // namespace sandpatch::gl
