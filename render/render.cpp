// SceneRenderer: one frame in Leach & Marais' order; see render.hpp.
#include "render/render.hpp"

#include <GL/glcorearb.h>

#include <chrono>
#include <Eigen/LU>
#include <cmath>

#include "render/body_renderer.hpp"
#include "render/camera.hpp"
#include "render/shaders.hpp"
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
  if (!(def.particle_color_variation >= 0 && def.particle_color_variation <= 0.5f))
    return Error{"", "particle_color_variation", std::to_string(def.particle_color_variation), "must be in [0, 0.5]"};
  if (!(def.particle_bed_scale >= 1.0f && def.particle_bed_scale <= 32.0f))
    return Error{"", "particle_bed_scale", std::to_string(def.particle_bed_scale), "must be in [1, 32] particle radii"};
  if (!(def.particle_gain >= 0.5f && def.particle_gain <= 2.0f))
    return Error{"", "particle_gain", std::to_string(def.particle_gain), "must be in [0.5, 2]"};
  if (!(def.ao_radius > 0 && std::isfinite(def.ao_radius)))
    return Error{"", "ao_radius", std::to_string(def.ao_radius), "must be > 0 and finite (m)"};
  if (!(def.ao_strength >= 0 && def.ao_strength <= 4))
    return Error{"", "ao_strength", std::to_string(def.ao_strength), "must be in [0, 4] (0 = off)"};
  if (def.shadow_map_size != 0 && (def.shadow_map_size < 256 || def.shadow_map_size > 8192))
    return Error{"", "shadow_map_size", std::to_string(def.shadow_map_size), "must be 0 (no shadows) or in [256, 8192] texels"};
  if (def.terrain_shadow_steps != 0 && (def.terrain_shadow_steps < 8 || def.terrain_shadow_steps > 64))
    return Error{"", "terrain_shadow_steps", std::to_string(def.terrain_shadow_steps), "must be 0 (none) or in [8, 64]"};
  if (def.ao_samples < 1 || def.ao_samples > 64)
    return Error{"", "ao_samples", std::to_string(def.ao_samples), "must be in [1, 64]"};
  if (auto st = ctx.make_current(); !st) return st.errors();
  auto terrain = TerrainRenderer::create(hf, def.clipmap);
  if (!terrain) return terrain.errors();
  auto particles = ParticleRenderer::create();
  if (!particles) return particles.errors();
  auto bodies = BodyRenderer::create();
  if (!bodies) return bodies.errors();
  auto ao = build_ao_program();
  if (!ao) return ao.errors();
  auto bed_blur = build_bed_blur_program();
  if (!bed_blur) return bed_blur.errors();
  std::unique_ptr<SceneRenderer> r(new SceneRenderer());
  r->ctx_ = &ctx;
  r->hf_ = &hf;
  r->def_ = def;
  r->terrain_ = std::move(terrain.value());
  r->terrain_->set_sun_direction(def.sun_direction);
  r->terrain_->set_terrain_shadow_steps(def.terrain_shadow_steps);
  r->particle_renderer_ = std::move(particles.value());
  r->body_renderer_ = std::move(bodies.value());
  r->ao_program_ = std::move(ao.value());
  r->bed_blur_program_ = std::move(bed_blur.value());
  glGenVertexArrays(1, &r->empty_vao_);
  if (std::string e = gl::Context::drain_errors(); !e.empty())
    return Error{"", "", "", "", "GL error while creating the renderer: " + e};
  return r;
}

SceneRenderer::~SceneRenderer() {
  terrain_.reset();
  particle_renderer_.reset();
  body_renderer_.reset();
  glDeleteFramebuffers(1, &fbo_);
  glDeleteFramebuffers(1, &ao_fbo_);
  glDeleteTextures(1, &color_tex_);
  glDeleteTextures(1, &depth_tex_);
  glDeleteTextures(1, &bed_tex_);
  glDeleteFramebuffers(1, &bed_fbo_);
  glDeleteTextures(1, &bed_mid_tex_);
  glDeleteTextures(1, &bed_smooth_tex_);
  glDeleteRenderbuffers(1, &ao_rb_);
  glDeleteVertexArrays(1, &empty_vao_);
  glDeleteFramebuffers(1, &shadow_fbo_);
  glDeleteTextures(1, &shadow_tex_);
}

const std::string& SceneRenderer::renderer_string() const { return ctx_->info().gl_renderer; }

void SceneRenderer::ensure_framebuffer(int w, int h) {
  if (fbo_ && w == fb_w_ && h == fb_h_) return;
  if (!fbo_) {
    glGenFramebuffers(1, &fbo_);
    glGenFramebuffers(1, &ao_fbo_);
    glGenFramebuffers(1, &bed_fbo_);
    glGenRenderbuffers(1, &ao_rb_);
  }
  // Textures are immutable once allocated (glTexStorage2D): a new size makes new ones.
  glDeleteTextures(1, &color_tex_);
  glDeleteTextures(1, &depth_tex_);
  glDeleteTextures(1, &bed_tex_);
  glDeleteTextures(1, &bed_mid_tex_);
  glDeleteTextures(1, &bed_smooth_tex_);
  glGenTextures(1, &color_tex_);
  glGenTextures(1, &depth_tex_);
  glGenTextures(1, &bed_tex_);
  glGenTextures(1, &bed_mid_tex_);
  glGenTextures(1, &bed_smooth_tex_);
  auto setup = [&](unsigned tex, GLenum format) {
    glBindTexture(GL_TEXTURE_2D, tex);
    glTexStorage2D(GL_TEXTURE_2D, 1, format, w, h);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
  };
  setup(color_tex_, GL_RGBA8);
  setup(depth_tex_, GL_DEPTH_COMPONENT24);
  setup(bed_tex_, GL_DEPTH_COMPONENT24);
  setup(bed_mid_tex_, GL_R32F);
  setup(bed_smooth_tex_, GL_R32F);
  glBindTexture(GL_TEXTURE_2D, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, color_tex_, 0);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, depth_tex_, 0);
  glBindRenderbuffer(GL_RENDERBUFFER, ao_rb_);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  glBindFramebuffer(GL_FRAMEBUFFER, ao_fbo_);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, ao_rb_);
  fb_w_ = w;
  fb_h_ = h;
}

// The granule bed's smoothing (bed_blur.frag): a Gaussian of sigma = this many drawn sphere
// radii. Measured on the default scene's patches at particle scale 1 (granules 1.5 px in
// radius, SceneFrames.FinePatchReadsAsSand) and the crater one granule deep of
// ParticleRenderer.CraterInAPatchShowsWithItsFootprintCutOut: sigma 1, 2, 3 radii gave the
// crate's patch a local contrast of 6.5, 5.4, 6.0 (10.1 unsmoothed) and the crater a contrast of
// 11.6, 11.2, 9.8 (it needs 8): 2 smooths the caps (a granule is about 4.5 radii across) and
// keeps the crater.
constexpr float kBedSmoothingRadii = 2.0f;

void SceneRenderer::smooth_bed(const Eigen::Matrix4f& proj, int w, int h, float radius) {
  const unsigned p = bed_blur_program_.id();
  glUseProgram(p);
  glBindFramebuffer(GL_FRAMEBUFFER, bed_fbo_);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_BLEND);
  glDepthMask(GL_FALSE);
  const Eigen::Matrix4f inv_proj = proj.inverse();
  glUniformMatrix4fv(glGetUniformLocation(p, "u_proj_inv"), 1, GL_FALSE, inv_proj.data());
  glUniform2f(glGetUniformLocation(p, "u_size"), float(w), float(h));
  glUniform1f(glGetUniformLocation(p, "u_px_per_m"), proj(1, 1) * 0.5f * float(h));
  glUniform1f(glGetUniformLocation(p, "u_radius"), radius);
  glUniform1f(glGetUniformLocation(p, "u_sigma"), kBedSmoothingRadii);
  glUniform1i(glGetUniformLocation(p, "u_depth"), 0);
  glActiveTexture(GL_TEXTURE0);
  glBindVertexArray(empty_vao_);
  const unsigned from[2] = {bed_tex_, bed_mid_tex_}, to[2] = {bed_mid_tex_, bed_smooth_tex_};
  for (int pass = 0; pass < 2; ++pass) {
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, to[pass], 0);
    glBindTexture(GL_TEXTURE_2D, from[pass]);
    glUniform2i(glGetUniformLocation(p, "u_dir"), pass == 0 ? 1 : 0, pass == 0 ? 0 : 1);
    glDrawArrays(GL_TRIANGLES, 0, 3);
  }
  glBindVertexArray(0);
  glBindTexture(GL_TEXTURE_2D, 0);
  glDepthMask(GL_TRUE);
  glEnable(GL_DEPTH_TEST);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
}

SceneRenderer::Matrices SceneRenderer::matrices(const CameraView& cam) const {
  // The precision boundary: world (double) -> heightfield-local (float).
  const Eigen::Vector3d origin(hf_->origin_x(), hf_->origin_y(), hf_->origin_z());
  const Eigen::Vector3f eye = (cam.position - origin).cast<float>();
  const Eigen::Vector3f target = (cam.target - origin).cast<float>();
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
  return {look_at(eye, target), perspective(cam.fov_deg, float(cam.width) / float(cam.height), near_m, far_m), eye};
}

ShadowMap SceneRenderer::shadow_pass(const Eigen::Vector3d& origin) {
  ShadowMap sm;
  if (def_.shadow_map_size == 0 || bodies_.empty()) return sm;
  // The bodies' bounding sphere (local m): centre = mean position, radius = the farthest
  // body's distance plus its own bounding radius.
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const BodyInstance& b : bodies_) c += b.position - origin;
  c /= double(bodies_.size());
  double R = 0;
  for (const BodyInstance& b : bodies_) {
    double ext = 0;
    switch (b.kind) {
      case BodyShapeKind::Sphere: ext = b.radius; break;
      case BodyShapeKind::Box: ext = b.half_extents.norm(); break;
      case BodyShapeKind::Cylinder: ext = std::hypot(b.radius, 0.5 * b.height); break;
      case BodyShapeKind::Capsule: ext = b.radius + 0.5 * b.height; break;
      case BodyShapeKind::Mesh:
        for (const auto& v : b.vertices) ext = std::max(ext, double(v.norm()));
        break;
    }
    R = std::max(R, (b.position - origin - c).norm() + ext);
  }
  R = std::max(R * 1.05, 0.05);
  if (!std::isfinite(R)) return sm;
  const int n = def_.shadow_map_size;
  if (!shadow_fbo_) {
    glGenFramebuffers(1, &shadow_fbo_);
    glGenTextures(1, &shadow_tex_);
    glBindTexture(GL_TEXTURE_2D, shadow_tex_);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_DEPTH_COMPONENT24, n, n);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_MODE, GL_COMPARE_REF_TO_TEXTURE);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_COMPARE_FUNC, GL_LEQUAL);
    glBindTexture(GL_TEXTURE_2D, 0);
    glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_TEXTURE_2D, shadow_tex_, 0);
    glDrawBuffer(GL_NONE);
    glReadBuffer(GL_NONE);
  }
  // Orthographic view along the sun: the eye R + 1 m above the sphere toward the sun, depth
  // reaching 200 m past it (the ground the shadows fall on).
  const Eigen::Vector3f s = terrain_->sun_direction();
  const Eigen::Vector3f cf = c.cast<float>();
  const float Rf = float(R), near_m = 0.5f, far_m = 2.0f * Rf + 1.0f + 200.0f;
  const Eigen::Matrix4f view = look_at(cf + s * (Rf + 1.0f), cf);
  Eigen::Matrix4f ortho = Eigen::Matrix4f::Identity();
  ortho(0, 0) = 1.0f / Rf;
  ortho(1, 1) = 1.0f / Rf;
  ortho(2, 2) = -2.0f / (far_m - near_m);
  ortho(2, 3) = -(far_m + near_m) / (far_m - near_m);
  const Eigen::Matrix4f light_vp = ortho * view;
  glBindFramebuffer(GL_FRAMEBUFFER, shadow_fbo_);
  glViewport(0, 0, n, n);
  glDepthMask(GL_TRUE);
  glClearDepth(1.0);
  glClear(GL_DEPTH_BUFFER_BIT);
  body_renderer_->draw(bodies_, light_vp, cf + s * (Rf + 1.0f), s, origin, false);
  Eigen::Matrix4f to_unit = Eigen::Matrix4f::Identity();  // clip [-1, 1] -> [0, 1]
  to_unit.topLeftCorner<3, 3>() *= 0.5f;
  to_unit.topRightCorner<3, 1>().setConstant(0.5f);
  sm.on = true;
  sm.texture = shadow_tex_;
  sm.matrix = to_unit * light_vp;
  sm.bias = 0.01f / (far_m - near_m);  // 1 cm along the sun
  sm.texel_m = 2.0f * Rf / float(n);
  return sm;
}

Status SceneRenderer::set_effects(float ao_strength, int shadow_map_size, int terrain_shadow_steps) {
  std::vector<Error> es;
  if (!(ao_strength >= 0 && ao_strength <= 4))
    es.push_back(Error{"", "ao_strength", std::to_string(ao_strength), "must be in [0, 4] (0 = off)"});
  if (shadow_map_size != 0 && (shadow_map_size < 256 || shadow_map_size > 8192))
    es.push_back(Error{"", "shadow_map_size", std::to_string(shadow_map_size), "must be 0 (none) or in [256, 8192] texels"});
  if (terrain_shadow_steps != 0 && (terrain_shadow_steps < 8 || terrain_shadow_steps > 64))
    es.push_back(Error{"", "terrain_shadow_steps", std::to_string(terrain_shadow_steps), "must be 0 (none) or in [8, 64]"});
  if (!es.empty()) return es;
  def_.ao_strength = ao_strength;
  def_.terrain_shadow_steps = terrain_shadow_steps;
  terrain_->set_terrain_shadow_steps(terrain_shadow_steps);
  if (shadow_map_size != def_.shadow_map_size) {  // the map is made again at its new size when next needed
    if (shadow_fbo_) glDeleteFramebuffers(1, &shadow_fbo_);
    if (shadow_tex_) glDeleteTextures(1, &shadow_tex_);
    shadow_fbo_ = shadow_tex_ = 0;
    def_.shadow_map_size = shadow_map_size;
  }
  return Ok{};
}

std::optional<SceneRenderer::Projected> SceneRenderer::project(const CameraView& cam, const Eigen::Vector3d& p) const {
  if (!validate(cam).ok() || !p.allFinite()) return std::nullopt;
  const Matrices m = matrices(cam);
  const Eigen::Vector3d origin(hf_->origin_x(), hf_->origin_y(), hf_->origin_z());
  const Eigen::Vector4d e = m.view.cast<double>() * (p - origin).homogeneous();
  if (!(e.z() < 0)) return std::nullopt;
  const Eigen::Vector4d c = m.proj.cast<double>() * e;
  Projected out;
  out.pixel = {(c.x() / c.w() * 0.5 + 0.5) * cam.width, (0.5 - c.y() / c.w() * 0.5) * cam.height};
  out.depth_m = -e.z();
  return out;
}

Result<Image> SceneRenderer::render(const CameraView& cam, const FrameFlags& flags) {
  if (auto st = validate(cam); !st) return st.errors();
  const auto t0 = std::chrono::steady_clock::now();
  gl::Context::drain_errors();  // errors of earlier stages are theirs to report, not this frame's
  const Eigen::Vector3d origin(hf_->origin_x(), hf_->origin_y(), hf_->origin_z());
  const Matrices m = matrices(cam);
  const Eigen::Matrix4f& view = m.view;
  const Eigen::Matrix4f& proj = m.proj;
  const Eigen::Matrix4f view_proj = proj * view;

  RenderStats st;
  st.texels_uploaded = terrain_->update(m.eye) + pending_texels_;
  pending_texels_ = 0;

  // The bodies' shadows (not in ID renders: those show bodies only as flat colours).
  const ShadowMap shadow = flags.bodies && !flags.body_ids ? shadow_pass(origin) : ShadowMap{};
  terrain_->set_shadow(shadow);
  st.shadows = shadow.on;

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

  // The footprints of the sources that have one: there the granules are the surface, so the
  // terrain's second pass leaves them out and no shadow march samples the heightfield there.
  std::vector<Eigen::Vector4f> cuts;
  std::vector<float> bands;
  for (const ParticleSource& s : particles_)
    if (s.has_footprint() && s.count > 0) {
      cuts.push_back({float(s.footprint[0] - origin.x()), float(s.footprint[1] - origin.z()),
                      float(s.footprint[2] - origin.x()), float(s.footprint[3] - origin.z())});
      bands.push_back(s.footprint_band);
    }
  terrain_->set_live_footprints(std::move(cuts), std::move(bands));

  // Leach & Marais §5.1: terrain, clear depth, particles, terrain again (without the footprints).
  terrain_->draw(view_proj);
  st.terrain_passes = 1;
  if (!particles_.empty()) {
    glClear(GL_DEPTH_BUFFER_BIT);
    // Depth pre-pass of the granules, copied aside: the colour pass reads the bed's slopes from it.
    glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
    particle_renderer_->draw(particles_, view, proj, cam.height, *terrain_, origin, def_.particle_normal_bend,
                             def_.particle_color_variation, &shadow, def_.particle_gain);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    glCopyImageSubData(depth_tex_, GL_TEXTURE_2D, 0, 0, 0, 0, bed_tex_, GL_TEXTURE_2D, 0, 0, 0, 0, cam.width, cam.height, 1);
    // ... and smoothed over one sphere radius: the bed the granules make up, not their caps
    // (the finest drawn radius of the frame's patches; unknown: the caps as drawn).
    float radius = 0;
    for (const ParticleSource& s : particles_) {
      const float r = s.sphere_radius > 0 ? s.sphere_radius : s.radius_offset < 0 ? s.scale * s.radius : 0.0f;
      if (s.count > 0 && r > 0) radius = radius > 0 ? std::min(radius, r) : r;
    }
    unsigned bed_texture = bed_tex_;
    if (radius > 0) {
      smooth_bed(proj, cam.width, cam.height, radius);
      bed_texture = bed_smooth_tex_;
    }
    glViewport(0, 0, cam.width, cam.height);
    glClear(GL_DEPTH_BUFFER_BIT);
    const BedDepth bed{bed_texture, cam.width, cam.height, def_.particle_bed_scale};
    st.particles = particle_renderer_->draw(particles_, view, proj, cam.height, *terrain_, origin,
                                            def_.particle_normal_bend, def_.particle_color_variation, &shadow,
                                            def_.particle_gain, &bed, /*terrain_shadow=*/true);
    terrain_->redraw();
    st.terrain_passes = 2;
  }
  // Bodies last: depth-tested against the terrain and the granules in front of them.
  if (flags.bodies && !bodies_.empty()) {
    st.body_triangles = std::int64_t(body_renderer_->draw(bodies_, view_proj, m.eye, terrain_->sun_direction(), origin, flags.body_ids, &shadow,
                                                                     terrain_.get()));
    st.bodies = int(bodies_.size());
  }

  // Ambient occlusion: fbo_'s colour and depth -> ao_fbo_ (not for ID renders).
  unsigned read_fbo = fbo_;
  if (def_.ao_strength > 0 && !flags.body_ids) {
    glBindFramebuffer(GL_FRAMEBUFFER, ao_fbo_);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_BLEND);
    const unsigned p = ao_program_.id();
    glUseProgram(p);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, color_tex_);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, depth_tex_);
    glUniform1i(glGetUniformLocation(p, "u_color"), 0);
    glUniform1i(glGetUniformLocation(p, "u_depth"), 1);
    const Eigen::Matrix4f inv_proj = proj.inverse();
    glUniformMatrix4fv(glGetUniformLocation(p, "u_inv_proj"), 1, GL_FALSE, inv_proj.data());
    glUniform1f(glGetUniformLocation(p, "u_proj_scale"), proj(1, 1) * 0.5f * float(cam.height));
    glUniform2f(glGetUniformLocation(p, "u_size"), float(cam.width), float(cam.height));
    glUniform1f(glGetUniformLocation(p, "u_radius"), def_.ao_radius);
    glUniform1f(glGetUniformLocation(p, "u_strength"), def_.ao_strength);
    glUniform1i(glGetUniformLocation(p, "u_samples"), def_.ao_samples);
    glBindVertexArray(empty_vao_);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glBindVertexArray(0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glEnable(GL_DEPTH_TEST);
    read_fbo = ao_fbo_;
  }

  Image img;
  img.width = cam.width;
  img.height = cam.height;
  img.rgba.resize(std::size_t(cam.width) * cam.height * 4);
  std::vector<std::uint8_t> rows(img.rgba.size());
  glBindFramebuffer(GL_FRAMEBUFFER, read_fbo);
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

Status SceneRenderer::render_png(const CameraView& cam, const std::string& path, const FrameFlags& flags) {
  auto img = render(cam, flags);
  if (!img) return img.errors();
  return save_png(path, img.value());
}

void SceneRenderer::heightfield_changed(GridRegion dirty) {
  pending_texels_ += terrain_->heightfield_changed(intersect(dirty, hf_->whole()));
}

Status SceneRenderer::set_bodies(std::vector<BodyInstance> bodies) {
  std::vector<Error> es;
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    auto st = validate(bodies[i], int(i));
    if (!st) es.insert(es.end(), st.errors().begin(), st.errors().end());
  }
  if (!es.empty()) return es;
  bodies_ = std::move(bodies);
  return Ok{};
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
