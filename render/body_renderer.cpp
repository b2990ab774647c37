// Rigid bodies in GL; see body_renderer.hpp.
#include "render/body_renderer.hpp"

#include <GL/glcorearb.h>

#include "render/shaders.hpp"
#include "render/terrain_renderer.hpp"

namespace sandpatch::render {

std::array<std::uint8_t, 3> body_id_color(int k) {
  return {255, std::uint8_t((k >> 8) & 0xff), std::uint8_t(k & 0xff)};
}

Result<std::unique_ptr<BodyRenderer>> BodyRenderer::create() {
  auto prog = build_body_program();
  if (!prog) return prog.errors();
  std::unique_ptr<BodyRenderer> r(new BodyRenderer());
  r->program_ = std::move(prog.value());
  glGenVertexArrays(1, &r->vao_);
  glGenBuffers(1, &r->vbo_);
  glBindVertexArray(r->vao_);
  glBindBuffer(GL_ARRAY_BUFFER, r->vbo_);
  const GLsizei stride = 9 * sizeof(float);
  for (int a = 0; a < 3; ++a) {
    glEnableVertexAttribArray(GLuint(a));
    glVertexAttribPointer(GLuint(a), 3, GL_FLOAT, GL_FALSE, stride, reinterpret_cast<const void*>(std::uintptr_t(a) * 3 * sizeof(float)));
  }
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  return r;
}

BodyRenderer::~BodyRenderer() {
  glDeleteVertexArrays(1, &vao_);
  glDeleteBuffers(1, &vbo_);
}

std::size_t BodyRenderer::draw(const std::vector<BodyInstance>& bodies, const Eigen::Matrix4f& view_proj,
                               const Eigen::Vector3f& eye, const Eigen::Vector3f& sun_direction,
                               const Eigen::Vector3d& world_origin, bool flat_ids, const ShadowMap* shadow,
                               const TerrainRenderer* terrain) {
  data_.clear();
  std::size_t triangles = 0;
  for (std::size_t k = 0; k < bodies.size(); ++k) {
    tris_.clear();
    triangles += tessellate(bodies[k], world_origin, tris_, bodies[k].segments > 0 ? bodies[k].segments : 32);
    Eigen::Vector3f c = bodies[k].albedo;
    if (flat_ids) {
      const auto id = body_id_color(int(k));
      c = Eigen::Vector3f(id[0], id[1], id[2]) / 255.0f;
    }
    for (const BodyVertex& v : tris_)
      data_.insert(data_.end(), {v.position.x(), v.position.y(), v.position.z(), v.normal.x(), v.normal.y(), v.normal.z(),
                                 c.x(), c.y(), c.z()});
  }
  if (data_.empty()) return 0;
  const unsigned p = program_.id();
  glUseProgram(p);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDepthMask(GL_TRUE);
  glDisable(GL_BLEND);
  glDisable(GL_CULL_FACE);
  glUniformMatrix4fv(glGetUniformLocation(p, "u_view_proj"), 1, GL_FALSE, view_proj.data());
  glUniform3f(glGetUniformLocation(p, "u_eye"), eye.x(), eye.y(), eye.z());
  const Eigen::Vector3f sun = sun_direction.normalized();
  glUniform3f(glGetUniformLocation(p, "u_sun_dir"), sun.x(), sun.y(), sun.z());
  glUniform1i(glGetUniformLocation(p, "u_flat"), flat_ids ? 1 : 0);
  bind_shadow(p, shadow && !flat_ids ? *shadow : ShadowMap{});
  if (terrain && !flat_ids) {
    terrain->bind_terrain_shadow(p, 3, terrain->terrain_shadow_steps());
  } else {
    glUniform1i(glGetUniformLocation(p, "u_terrain_shadow_steps"), 0);
  }
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(data_.size() * sizeof(float)), data_.data(), GL_STREAM_DRAW);
  glBindVertexArray(vao_);
  glDrawArrays(GL_TRIANGLES, 0, GLsizei(data_.size() / 9));
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  return triangles;
}

}  // namespace sandpatch::render
