// GLSL program building with errors that name the shader and carry the driver's log.
#pragma once

#include <string>

#include "common/error.hpp"

namespace sandpatch::gl {

// A linked GL program object. Owns the GL name; move-only. Needs a current context.
class Program {
 public:
  Program() = default;
  ~Program();
  Program(Program&& o) noexcept : id_(o.id_) { o.id_ = 0; }
  Program& operator=(Program&& o) noexcept;
  Program(const Program&) = delete;
  Program& operator=(const Program&) = delete;

  unsigned id() const { return id_; }

  // Compiles and links one compute shader. `name` appears in errors (e.g. "shaders/dem_force.comp").
  static Result<Program> compute(const std::string& name, const std::string& source);
  // Compiles and links a vertex + fragment pair.
  static Result<Program> graphics(const std::string& name, const std::string& vertex_source,
                                  const std::string& fragment_source);

 private:
  explicit Program(unsigned id) : id_(id) {}
  unsigned id_ = 0;
};

}  // namespace sandpatch::gl
