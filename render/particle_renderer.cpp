// Particle splats; see particle_renderer.hpp.
#include "render/particle_renderer.hpp"

#include <GL/glcorearb.h>

#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <string>

#include "render/shaders.hpp"
#include "render/terrain_renderer.hpp"

namespace sandpatch::render {

Status validate(const ParticleSource& s, int index) {
  const std::string f = "particles[" + std::to_string(index) + "].";
  std::vector<Error> es;
  if (s.buffer == 0) es.push_back(Error{"", f + "buffer", "0", "must be a GL buffer name"});
  if (s.count < 0) es.push_back(Error{"", f + "count", std::to_string(s.count), "must be >= 0"});
  if (s.first < 0) es.push_back(Error{"", f + "first", std::to_string(s.first), "must be >= 0"});
  if (s.stride < 12) es.push_back(Error{"", f + "stride", std::to_string(s.stride), "must be >= 12 bytes (three floats)"});
  if (s.position_offset < 0 || s.position_offset + 12 > s.stride)
    es.push_back(Error{"", f + "position_offset", std::to_string(s.position_offset), "must be in [0, stride - 12] bytes"});
  if (s.radius_offset >= 0 && s.radius_offset + 4 > s.stride)
    es.push_back(Error{"", f + "radius_offset", std::to_string(s.radius_offset), "must be < 0 (constant radius) or in [0, stride - 4] bytes"});
  if (s.radius_offset < 0 && !(s.radius > 0 && std::isfinite(s.radius)))
    es.push_back(Error{"", f + "radius", std::to_string(s.radius), "must be > 0 and finite (m)"});
  if (!(s.scale > 0 && std::isfinite(s.scale))) es.push_back(Error{"", f + "scale", std::to_string(s.scale), "must be > 0 and finite"});
  if (!(s.fade >= 0 && s.fade <= 1)) es.push_back(Error{"", f + "fade", std::to_string(s.fade), "must be in [0, 1]"});
  if (!(s.shading_scale >= 1 && s.shading_scale <= 64))
    es.push_back(Error{"", f + "shading_scale", std::to_string(s.shading_scale), "must be in [1, 64]"});
  if (!(s.sphere_radius >= 0 && std::isfinite(s.sphere_radius)))
    es.push_back(Error{"", f + "sphere_radius", std::to_string(s.sphere_radius), "must be >= 0 m (0: unknown)"});
  if (!s.origin.allFinite()) es.push_back(Error{"", f + "origin", "non-finite", "must be finite (m)"});
  if (!s.footprint.allFinite()) es.push_back(Error{"", f + "footprint", "non-finite", "must be finite (m) or empty"});
  if (s.id_offset < -1) es.push_back(Error{"", f + "id_offset", std::to_string(s.id_offset), "must be -1 (no ids) or >= 0 bytes"});
  if (s.id_offset >= 0 && s.id_offset % 4 != 0)
    es.push_back(Error{"", f + "id_offset", std::to_string(s.id_offset), "must be a multiple of 4 bytes (int32 ids)"});
  if (s.id_limit >= 0 && s.id_offset < 0) es.push_back(Error{"", f + "id_limit", std::to_string(s.id_limit), "needs id_offset >= 0"});
  if (s.id_limit > std::int64_t(0x7fffffff)) es.push_back(Error{"", f + "id_limit", std::to_string(s.id_limit), "must be < 2^31"});
  if (!(s.footprint_band >= 0 && std::isfinite(s.footprint_band)))
    es.push_back(Error{"", f + "footprint_band", std::to_string(s.footprint_band), "must be >= 0 and finite (m)"});
  if (!es.empty()) return es;
  return Ok{};
}

ParticleBuffer::ParticleBuffer(const std::vector<Eigen::Vector4f>& xyzr) : count_(std::int64_t(xyzr.size())) {
  for (const Eigen::Vector4f& p : xyzr)
    if (p.w() > 0 && std::isfinite(p.w())) min_radius_ = min_radius_ > 0 ? std::min(min_radius_, p.w()) : p.w();
  glGenBuffers(1, &id_);
  glBindBuffer(GL_ARRAY_BUFFER, id_);
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(xyzr.size() * sizeof(Eigen::Vector4f)), xyzr.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

ParticleBuffer::~ParticleBuffer() { glDeleteBuffers(1, &id_); }

ParticleSource ParticleBuffer::source(const Eigen::Vector3d& origin, float scale, float fade) const {
  ParticleSource s;
  s.buffer = id_;
  s.count = count_;
  s.stride = 16;
  s.position_offset = 0;
  s.radius_offset = 12;
  s.sphere_radius = scale * min_radius_;
  s.origin = origin;
  s.scale = scale;
  s.fade = fade;
  return s;
}

Result<std::unique_ptr<ParticleRenderer>> ParticleRenderer::create() {
  auto prog = build_particle_program();
  if (!prog) return prog.errors();
  std::unique_ptr<ParticleRenderer> r(new ParticleRenderer());
  r->program_ = std::move(prog.value());
  glGenVertexArrays(1, &r->vao_);
  return r;
}

ParticleRenderer::~ParticleRenderer() { glDeleteVertexArrays(1, &vao_); }

std::int64_t ParticleRenderer::draw(const std::vector<ParticleSource>& sources, const Eigen::Matrix4f& view,
                                    const Eigen::Matrix4f& proj, int viewport_height, const TerrainRenderer& terrain,
                                    const Eigen::Vector3d& world_origin, float normal_bend, float color_variation,
                                    const ShadowMap* shadow, float gain, const BedDepth* bed, bool terrain_shadow) {
  const unsigned p = program_.id();
  auto loc = [p](const char* name) { return glGetUniformLocation(p, name); };
  glUseProgram(p);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glEnable(GL_PROGRAM_POINT_SIZE);
  glEnable(GL_BLEND);
  // a fading patch's colour over the terrain's; the frame's alpha stays 1 (opaque: a PNG with
  // alpha below 1 there showed a fading patch pale, composited over the viewer's background)
  glBlendFuncSeparate(GL_SRC_ALPHA, GL_ONE_MINUS_SRC_ALPHA, GL_ZERO, GL_ONE);
  const Eigen::Matrix4f view_inv = view.inverse();
  glUniformMatrix4fv(loc("u_view"), 1, GL_FALSE, view.data());
  glUniformMatrix4fv(loc("u_proj"), 1, GL_FALSE, proj.data());
  glUniformMatrix4fv(loc("u_view_inv"), 1, GL_FALSE, view_inv.data());
  glUniform1f(loc("u_viewport_h"), float(viewport_height));
  const Eigen::Vector3f sun = terrain.sun_direction();
  glUniform3f(loc("u_sun_dir"), sun.x(), sun.y(), sun.z());
  const ClipmapDef& def = terrain.def();
  glUniform1i(loc("u_T"), terrain.texture_size());
  glUniform1i(loc("u_n"), def.n);
  glUniform1i(loc("u_first_level"), terrain.first_active_level());
  glUniform1i(loc("u_levels"), def.levels);
  glUniform1f(loc("u_base_spacing"), def.base_spacing);
  std::vector<int> origins;
  for (const LevelRect& w : terrain.windows()) {
    origins.push_back(w.x0);
    origins.push_back(w.z0);
  }
  glUniform2iv(loc("u_level_origin"), GLsizei(terrain.windows().size()), origins.data());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D_ARRAY, terrain.materials_texture());
  glUniform1i(loc("u_materials"), 0);
  glActiveTexture(GL_TEXTURE1);
  glBindTexture(GL_TEXTURE_2D_ARRAY, terrain.normals_texture());
  glUniform1i(loc("u_normals"), 1);
  glActiveTexture(GL_TEXTURE0);
  terrain.bind_terrain_shadow(p, 3, terrain_shadow ? terrain.terrain_shadow_steps() : 0);  // u_elevation on unit 3
  glUniform1f(loc("u_normal_bend"), normal_bend);
  glUniform1f(loc("u_color_variation"), color_variation);
  bind_shadow(p, shadow ? *shadow : ShadowMap{});
  glUniform1f(loc("u_gain"), gain);
  glUniform1i(loc("u_bed_on"), bed && bed->texture ? 1 : 0);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, bed ? bed->texture : 0);
  glUniform1i(loc("u_bed_depth"), 2);
  glActiveTexture(GL_TEXTURE0);
  {
    const Eigen::Matrix4f proj_inv = proj.inverse();
    glUniformMatrix4fv(loc("u_proj_inv"), 1, GL_FALSE, proj_inv.data());
  }
  glUniform2f(loc("u_viewport"), bed ? float(bed->width) : 1.0f, bed ? float(bed->height) : 1.0f);
  glUniform1f(loc("u_bed_scale"), bed ? bed->scale : 4.0f);
  const GLint l_origin = loc("u_patch_origin"), l_scale = loc("u_scale"), l_fade = loc("u_fade"),
              l_first = loc("u_first_index"), l_shading = loc("u_shading_scale"), l_has_id = loc("u_has_id"),
              l_id_limit = loc("u_id_limit");

  glBindVertexArray(vao_);
  std::int64_t drawn = 0;
  for (const ParticleSource& s : sources) {
    assert(validate(s, 0).ok());
    if (s.count == 0 || s.fade <= 0.0f) continue;  // fade 0: nothing to show (not even depth)
    const Eigen::Vector3d o = s.origin - world_origin;
    glUniform3f(l_origin, float(o.x()), float(o.y()), float(o.z()));
    glUniform1f(l_scale, s.scale);
    glUniform1f(l_fade, s.fade);
    glUniform1f(l_shading, s.shading_scale);
    glUniform1i(l_first, int(s.first & 0x7fffffff));
    glBindBuffer(GL_ARRAY_BUFFER, s.buffer);
    const std::uintptr_t base = std::uintptr_t(s.first) * std::uintptr_t(s.stride);
    glEnableVertexAttribArray(0);
    glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, s.stride, reinterpret_cast<const void*>(base + std::uintptr_t(s.position_offset)));
    if (s.radius_offset >= 0) {
      glEnableVertexAttribArray(1);
      glVertexAttribPointer(1, 1, GL_FLOAT, GL_FALSE, s.stride, reinterpret_cast<const void*>(base + std::uintptr_t(s.radius_offset)));
    } else {
      glDisableVertexAttribArray(1);
      glVertexAttrib1f(1, s.radius);
    }
    if (s.id_offset >= 0) {
      glEnableVertexAttribArray(2);
      glVertexAttribIPointer(2, 1, GL_INT, 4, reinterpret_cast<const void*>(std::uintptr_t(s.id_offset) + 4 * std::uintptr_t(s.first)));
    } else {
      glDisableVertexAttribArray(2);
      glVertexAttribI1i(2, 0);
    }
    glUniform1i(l_has_id, s.id_offset >= 0 ? 1 : 0);
    glUniform1i(l_id_limit, s.id_limit >= 0 ? int(s.id_limit) : -1);
    if (s.fade < 1.0f) {
      glEnable(GL_BLEND);
    } else {
      glDisable(GL_BLEND);  // opaque: exactly the shaded colour
    }
    glDrawArrays(GL_POINTS, 0, GLsizei(s.count));
    drawn += s.count;
  }
  glDisableVertexAttribArray(2);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  glActiveTexture(GL_TEXTURE2);
  glBindTexture(GL_TEXTURE_2D, 0);
  glActiveTexture(GL_TEXTURE0);
  glDisable(GL_BLEND);
  glDisable(GL_PROGRAM_POINT_SIZE);
  return drawn;
}

}  // namespace sandpatch::render
