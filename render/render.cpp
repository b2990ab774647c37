// SceneRenderer: one frame in Leach & Marais' order; see render.hpp.
#include "render/render.hpp"

#include <GL/glcorearb.h>

#include <chrono>
#include <cmath>

#include "render/camera.hpp"
#include "render/terrain_renderer.hpp"

namespace sandpatch::render {

Status validate(const CameraView& c) {
  std::vector<Error> es;
  if (!c.position.allFinite()) es.push_back(Error{"", "camera.position", "non-finite", "must be finite (m)"});
  if (!c.target.allFinite()) es.push_back(Error{"", "camera.target", "non-finite", "must be finite (m)"});
  if (c.position.allFinite() && c.target.allFinite() && (c.target - c.position).norm() == 0)
    es.push_back(Error{"", "camera.target", "= camera.position", "must differ from the position"});
  if (!(c.fov_deg > 0 && c.fov_deg < 180)) es.push_back(Error{"", "camera.fov_deg", std::to_string(c.fov_deg), "must be in (0, 180) degrees"});
  if (c.width < 1 || c.width > 16384) es.push_back(Error{"", "camera.width", std::to_string(c.width), "must be in [1, 16384] pixels"});
  if (c.height < 1 || c.height > 16384) es.push_back(Error{"", "camera.height", std::to_string(c.height), "must be in [1, 16384] pixels"});
  if (!(c.near_m >= 0) || !std::isfinite(c.near_m)) es.push_back(Error{"", "camera.near_m", std::to_string(c.near_m), "must be 0 (automatic) or > 0 (m)"});
  if (!(c.far_m >= 0) || !std::isfinite(c.far_m)) es.push_back(Error{"", "camera.far_m", std::to_string(c.far_m), "must be 0 (automatic) or > 0 (m)"});
  if (c.near_m > 0 && c.far_m > 0 && c.far_m <= c.near_m)
    es.push_back(Error{"", "camera.far_m", std::to_string(c.far_m), "must be > camera.near_m"});
  if (!es.empty()) return es;
  return Ok{};
}

int auto_levels(const ClipmapDef& def, const Heightfield& hf) {
  const double s0 = def.base_spacing > 0 ? def.base_spacing : hf.spacing();
  const double need = 2.0 * std::max(hf.extent_x(), hf.extent_z());
  int L = 1;
  while (L < 24 && double(def.n - 1) * s0 * std::ldexp(1.0, L - 1) < need) ++L;
  return L;
}

Result<std::unique_ptr<SceneRenderer>> SceneRenderer::create(gl::Context& ctx, const Heightfield& hf, const RendererDef& def_in) {
  RendererDef def = def_in;
  if (def.clipmap.base_spacing <= 0) def.clipmap.base_spacing = hf.spacing();
  if (def.clipmap.levels <= 0) def.clipmap.levels = auto_levels(def.clipmap, hf);
  if (!def.sun_direction.allFinite() || def.sun_direction.norm() == 0)
    return Error{"", "sun_direction", "zero or non-finite", "must be a finite non-zero vector"};
  if (!(def.particle_normal_bend >= 0 && def.particle_normal_bend <= 1))
    return Error{"", "particle_normal_bend", std::to_string(def.particle_normal_bend), "must be in [0, 1]"};
  if (auto st = ctx.make_current(); !st) return st.errors();
  auto terrain = TerrainRenderer::create(hf, def.clipmap);
  if (!terrain) return terrain.errors();
  auto particles = ParticleRenderer::create();
  if (!particles) return particles.errors();
  std::unique_ptr<SceneRenderer> r(new SceneRenderer());
  r->ctx_ = &ctx;
  r->hf_ = &hf;
  r->def_ = def;
  r->terrain_ = std::move(terrain.value());
  r->terrain_->set_sun_direction(def.sun_direction);
  r->particle_renderer_ = std::move(particles.value());
  if (std::string e = gl::Context::drain_errors(); !e.empty())
    return Error{"", "", "", "", "GL error while creating the renderer: " + e};
  return r;
}

SceneRenderer::~SceneRenderer() {
  terrain_.reset();
  particle_renderer_.reset();
  glDeleteFramebuffers(1, &fbo_);
  glDeleteRenderbuffers(1, &color_rb_);
  glDeleteRenderbuffers(1, &depth_rb_);
}

const std::string& SceneRenderer::renderer_string() const { return ctx_->info().gl_renderer; }

void SceneRenderer::ensure_framebuffer(int w, int h) {
  if (fbo_ && w == fb_w_ && h == fb_h_) return;
  if (!fbo_) {
    glGenFramebuffers(1, &fbo_);
    glGenRenderbuffers(1, &color_rb_);
    glGenRenderbuffers(1, &depth_rb_);
  }
  glBindRenderbuffer(GL_RENDERBUFFER, color_rb_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
  glBindRenderbuffer(GL_RENDERBUFFER, depth_rb_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color_rb_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb_);
  fb_w_ = w;
  fb_h_ = h;
}

Result<Image> SceneRenderer::render(const CameraView& cam) {
  if (auto st = validate(cam); !st) return st.errors();
  const auto t0 = std::chrono::steady_clock::now();
  gl::Context::drain_errors();  // errors of earlier stages are theirs to report, not this frame's
  // The precision boundary: world (double) -> heightfield-local (float).
  const Eigen::Vector3d origin(hf_->origin_x(), hf_->origin_y(), hf_->origin_z());
  const Eigen::Vector3f eye = (cam.position - origin).cast<float>();
  const Eigen::Vector3f target = (cam.target - origin).cast<float>();

  RenderStats st;
  st.texels_uploaded = terrain_->update(eye) + pending_texels_;
  pending_texels_ = 0;

  // Clip planes.
  const float ground = hf_->sample(eye.x(), eye.z());
  float far_m = cam.far_m;
  if (far_m <= 0) {
    float d2 = 0;
    for (float x : {0.0f, hf_->extent_x()})
      for (float z : {0.0f, hf_->extent_z()})
        for (float y : {hf_->min_height(), hf_->max_height()}) d2 = std::max(d2, (Eigen::Vector3f(x, y, z) - eye).squaredNorm());
    far_m = std::sqrt(d2) * 1.05f + 1.0f;
  }
  float near_m = cam.near_m > 0 ? cam.near_m : std::clamp(0.25f * std::fabs(eye.y() - ground), 0.01f, 10.0f);
  if (near_m >= far_m) near_m = far_m * 0.5f;
  const Eigen::Matrix4f view = look_at(eye, target);
  const Eigen::Matrix4f proj = perspective(cam.fov_deg, float(cam.width) / float(cam.height), near_m, far_m);
  const Eigen::Matrix4f view_proj = proj * view;

  ensure_framebuffer(cam.width, cam.height);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    return Error{"", "camera.width", std::to_string(cam.width) + " x " + std::to_string(cam.height), "",
                 "the offscreen framebuffer of this size is incomplete on this GL"};
  glViewport(0, 0, cam.width, cam.height);
  glDepthMask(GL_TRUE);
  glClearColor(def_.background[0] / 255.0f, def_.background[1] / 255.0f, def_.background[2] / 255.0f, 1.0f);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);

  // Leach & Marais §5.1: terrain, clear depth, particles, terrain again.
  terrain_->draw(view_proj);
  st.terrain_passes = 1;
  if (!particles_.empty()) {
    glClear(GL_DEPTH_BUFFER_BIT);
    st.particles = particle_renderer_->draw(particles_, view, proj, cam.height, *terrain_, origin, def_.particle_normal_bend);
    terrain_->redraw();
    st.terrain_passes = 2;
  }

  Image img;
  img.width = cam.width;
  img.height = cam.height;
  img.rgba.resize(std::size_t(cam.width) * cam.height * 4);
  std::vector<std::uint8_t> rows(img.rgba.size());
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadBuffer(GL_COLOR_ATTACHMENT0);
  glReadPixels(0, 0, cam.width, cam.height, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  glFinish();
  // GL's first row is the bottom one; images start at the top.
  const std::size_t row = std::size_t(cam.width) * 4;
  for (int y = 0; y < cam.height; ++y)
    std::copy_n(rows.data() + row * std::size_t(cam.height - 1 - y), row, img.rgba.data() + row * std::size_t(y));

  const auto& sel = terrain_->selection();
  st.terrain_triangles = sel.triangles;
  st.pieces = int(sel.pieces.size());
  st.culled_pieces = sel.culled_pieces;
  for (const auto& lv : sel.levels) st.active_levels += lv.active ? 1 : 0;
  st.frame_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  stats_ = st;
  if (std::string e = gl::Context::drain_errors(); !e.empty())
    return Error{"", "", "", "", "GL error while rendering: " + e};
  return img;
}

Status SceneRenderer::render_png(const CameraView& cam, const std::string& path) {
  auto img = render(cam);
  if (!img) return img.errors();
  return save_png(path, img.value());
}

void SceneRenderer::heightfield_changed(GridRegion dirty) {
  pending_texels_ += terrain_->heightfield_changed(intersect(dirty, hf_->whole()));
}

Status SceneRenderer::set_particles(const std::vector<ParticleSource>& sources) {
  std::vector<Error> es;
  for (std::size_t i = 0; i < sources.size(); ++i) {
    auto st = validate(sources[i], int(i));
    if (!st) es.insert(es.end(), st.errors().begin(), st.errors().end());
  }
  if (!es.empty()) return es;
  particles_ = sources;
  return Ok{};
}

}  // namespace sandpatch::render
