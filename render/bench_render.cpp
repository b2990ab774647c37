// `sandpatch bench render`: clipmaps against a full-resolution grid of the same terrain
// (the rendering yardstick); see render.hpp and docs/rendering.md.
#include <GL/glcorearb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "heightfield/procedural.hpp"
#include "render/camera.hpp"
#include "render/render.hpp"
#include "render/shaders.hpp"
#include "render/terrain_renderer.hpp"

namespace sandpatch::render {

namespace {

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The whole grid at full resolution: one triangle strip per row of cells, generated from
// gl_VertexID / gl_InstanceID (no index buffer), heights from one R32F texture.
struct FullGrid {
  gl::Program program;
  unsigned tex = 0, vao = 0, fbo = 0, rb[2] = {0, 0};
  int nx = 0, nz = 0;
  float spacing = 1;
  ~FullGrid() {
    glDeleteTextures(1, &tex);
    glDeleteVertexArrays(1, &vao);
    glDeleteFramebuffers(1, &fbo);
    glDeleteRenderbuffers(2, rb);
  }
  std::int64_t triangles() const { return 2 * std::int64_t(nx - 1) * (nz - 1); }
};

Status setup_full_grid(FullGrid& g, const Heightfield& hf, int w, int h) {
  auto prog = build_full_grid_program();
  if (!prog) return prog.errors();
  g.program = std::move(prog.value());
  g.nx = hf.samples_x();
  g.nz = hf.samples_z();
  g.spacing = hf.spacing();
  std::vector<float> heights(std::size_t(g.nx) * g.nz);
  hf.read(hf.whole(), heights.data());
  glGenTextures(1, &g.tex);
  glBindTexture(GL_TEXTURE_2D, g.tex);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32F, g.nx, g.nz);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
  glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, g.nx, g.nz, GL_RED, GL_FLOAT, heights.data());
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
  glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
  glBindTexture(GL_TEXTURE_2D, 0);
  glGenVertexArrays(1, &g.vao);
  glGenFramebuffers(1, &g.fbo);
  glGenRenderbuffers(2, g.rb);
  glBindRenderbuffer(GL_RENDERBUFFER, g.rb[0]);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, w, h);
  glBindRenderbuffer(GL_RENDERBUFFER, g.rb[1]);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, w, h);
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g.rb[0]);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g.rb[1]);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (std::string e = gl::Context::drain_errors(); !e.empty())
    return Error{"", "", "", "", "GL error while uploading the full grid: " + e};
  return Ok{};
}

double draw_full_grid(const FullGrid& g, const Eigen::Matrix4f& view_proj, const Eigen::Vector3f& sun, int w, int h) {
  const auto t0 = std::chrono::steady_clock::now();
  glBindFramebuffer(GL_FRAMEBUFFER, g.fbo);
  glViewport(0, 0, w, h);
  glClearColor(140 / 255.0f, 180 / 255.0f, 230 / 255.0f, 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  const unsigned p = g.program.id();
  glUseProgram(p);
  glUniformMatrix4fv(glGetUniformLocation(p, "u_view_proj"), 1, GL_FALSE, view_proj.data());
  glUniform1f(glGetUniformLocation(p, "u_spacing"), g.spacing);
  glUniform3f(glGetUniformLocation(p, "u_sun_dir"), sun.x(), sun.y(), sun.z());
  glActiveTexture(GL_TEXTURE0);
  glBindTexture(GL_TEXTURE_2D, g.tex);
  glUniform1i(glGetUniformLocation(p, "u_heights"), 0);
  glBindVertexArray(g.vao);
  glDrawArraysInstanced(GL_TRIANGLE_STRIP, 0, 2 * g.nx, g.nz - 1);
  glBindVertexArray(0);
  // Read the image back as SceneRenderer::render does, so both times cover the same work.
  std::vector<std::uint8_t> pixels(std::size_t(w) * h * 4);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, w, h, GL_RGBA, GL_UNSIGNED_BYTE, pixels.data());
  glFinish();
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

int run_bench_render(const BenchRenderArgs& a_in) {
  BenchRenderArgs a = a_in;
  if (a.terrains.empty()) a.terrains = {1024, 2048, 4096, 8192};
  for (int n : a.terrains) {
    if (n < 1024 || n > 16384) {
      std::fprintf(stderr, "bench render: --terrain %d: must be in [1024, 16384] samples per side\n", n);
      return 2;
    }
  }
  if (a.frames < 1) {
    std::fprintf(stderr, "bench render: --frames %d: must be >= 1\n", a.frames);
    return 2;
  }
  if (a.width < 16 || a.width > 8192 || a.height < 16 || a.height > 8192) {
    std::fprintf(stderr, "bench render: --width/--height %dx%d: must be in [16, 8192] pixels\n", a.width, a.height);
    return 2;
  }
  auto ctx = gl::Context::create();
  if (!ctx) {
    std::fprintf(stderr, "bench render: %s", ctx.message().c_str());
    return 1;
  }
  const std::string renderer = (*ctx)->info().gl_renderer;
  std::printf("bench render: renderer %s (%s), %dx%d, %d frame(s) each, median reported\n", renderer.c_str(),
              (*ctx)->info().gl_version.c_str(), a.width, a.height, a.frames);
  std::printf("%8s %18s %18s %12s %12s %8s\n", "terrain", "clipmap_tris", "full_grid_tris", "clipmap_ms", "full_ms", "ratio");
  nlohmann::json results = nlohmann::json::array();
  for (int n : a.terrains) {
    // Terrain: n x n samples at 1 m, hills 20 m high with a 256 m period.
    HeightfieldDef grid;
    grid.samples_x = grid.samples_z = n;
    grid.spacing = 1.0f;
    ProceduralHeightsDef hills;
    hills.kind = "hills";
    hills.amplitude = 20;
    hills.wavelength = 256;
    auto hf = make_procedural(grid, hills);
    if (!hf) {
      std::fprintf(stderr, "bench render: %s", hf.message().c_str());
      return 1;
    }
    // The same camera for every size: 30 m above the ground at (200, 200), looking along the
    // diagonal; the far plane (500 m; the frustum's corners reach ~780 m) keeps the whole view
    // inside the smallest terrain, so every size sees the same ground.
    CameraView cam;
    cam.position = {200.0, double(hf->sample(200, 200)) + 30.0, 200.0};
    cam.target = {700.0, double(hf->sample(700, 700)), 700.0};
    cam.fov_deg = 60;
    cam.width = a.width;
    cam.height = a.height;
    cam.near_m = 0.5f;
    cam.far_m = 500.0f;
    RendererDef def;
    def.ao_strength = 0;  // the full grid below has no ambient-occlusion pass: compare like with like
    auto sr = SceneRenderer::create(**ctx, *hf, def);
    if (!sr) {
      std::fprintf(stderr, "bench render: %s", sr.message().c_str());
      return 1;
    }
    std::vector<double> clip_ms;
    std::int64_t clip_tris = 0;
    for (int f = 0; f <= a.frames; ++f) {  // frame 0 builds the textures: not timed
      auto img = (*sr)->render(cam);
      if (!img) {
        std::fprintf(stderr, "bench render: %s", img.message().c_str());
        return 1;
      }
      clip_tris = (*sr)->stats().terrain_triangles;
      if (f > 0) clip_ms.push_back((*sr)->stats().frame_ms);
    }
    const Eigen::Vector3f sun = (*sr)->def().sun_direction.normalized();
    sr->reset();

    FullGrid g;
    if (auto st = setup_full_grid(g, *hf, a.width, a.height); !st) {
      std::fprintf(stderr, "bench render: %s", st.message().c_str());
      return 1;
    }
    const Eigen::Vector3f eye = cam.position.cast<float>(), target = cam.target.cast<float>();
    const Eigen::Matrix4f vp = perspective(cam.fov_deg, float(a.width) / float(a.height), cam.near_m, cam.far_m) * look_at(eye, target);
    std::vector<double> full_ms;
    draw_full_grid(g, vp, sun, a.width, a.height);  // warm-up
    for (int f = 0; f < a.frames; ++f) full_ms.push_back(draw_full_grid(g, vp, sun, a.width, a.height));
    if (std::string e = gl::Context::drain_errors(); !e.empty()) {
      std::fprintf(stderr, "bench render: GL error in the full grid: %s\n", e.c_str());
      return 1;
    }
    const double cm = median(clip_ms), fm = median(full_ms);
    std::printf("%8d %18lld %18lld %12.2f %12.2f %8.1f\n", n, (long long)clip_tris, (long long)g.triangles(), cm, fm,
                double(g.triangles()) / double(std::max<std::int64_t>(clip_tris, 1)));
    std::fflush(stdout);
    results.push_back({{"terrain", n},
                       {"clipmap_triangles", clip_tris},
                       {"full_grid_triangles", g.triangles()},
                       {"clipmap_ms", cm},
                       {"full_grid_ms", fm}});
  }
  if (a.json) {
    nlohmann::json out = {{"renderer", renderer}, {"results", results}};
    std::printf("%s\n", out.dump().c_str());
  }
  return 0;
}

}  // namespace sandpatch::render
