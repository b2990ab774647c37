#include "manager/run_outputs.hpp"

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <unistd.h>

namespace sandpatch {

namespace fs = std::filesystem;

std::string expand_pattern(std::string pattern, long long frame, double t, const char* ext,
                           const std::string& camera) {
  char frame_s[32], time_s[32];
  std::snprintf(frame_s, sizeof frame_s, "%06lld", frame);
  std::snprintf(time_s, sizeof time_s, "%08lld", static_cast<long long>(std::llround(t * 1000.0)));
  auto replace = [&](const std::string& key, const std::string& val) {
    for (std::size_t p; (p = pattern.find(key)) != std::string::npos;) pattern.replace(p, key.size(), val);
  };
  replace("{frame}", frame_s);
  replace("{time_ms}", time_s);
  replace("{ext}", ext);
  replace("{camera}", camera);
  return pattern;
}

const char* format_ext(HeightfieldFormat f) {
  switch (f) {
    case HeightfieldFormat::Png16: return "png";
    case HeightfieldFormat::RawF32: return "raw";
    case HeightfieldFormat::EsriAscii: return "asc";
  }
  return "bin";
}

// Writes `text` to `path` atomically (temporary file + rename): nothing is written half.
Status write_atomic(const fs::path& path, const std::string& text) {
  const fs::path tmp = path.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary);
    f << text;
    f.flush();
    if (!f) return Error{path.string(), "", "", "cannot write file"};
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) return Error{path.string(), "", "", "cannot rename temporary file: " + ec.message()};
  return Ok{};
}

ProgressPrinter::ProgressPrinter(ProgressStyle style, long long frames, double dt) : frames_(frames), dt_(dt) {
  if (style == ProgressStyle::Auto) style = isatty(STDERR_FILENO) ? ProgressStyle::Bar : ProgressStyle::Lines;
  style_ = style;
}
void ProgressPrinter::update(long long frame, double wall_s, bool final) {
  if (style_ == ProgressStyle::None) return;
  if (!note_what_.empty() && style_ == ProgressStyle::Bar) std::fputc('\n', stderr);  // the start-up's bar stays
  note_what_.clear();
  const double sim = double(frame) * dt_, total = double(frames_) * dt_;
  const double rtf = wall_s > 0 ? sim / wall_s : 0.0;
  const int pct = frames_ > 0 ? int(100 * frame / frames_) : 100;
  if (style_ == ProgressStyle::Bar) {
    if (!final && wall_s - last_wall_ < 0.1) return;
    last_wall_ = wall_s;
    const int width = 30, fill = pct * width / 100;
    std::fprintf(stderr, "\r[%.*s%*s] %3d%%  t = %.2f / %.2f s  real-time factor %.2fx ", fill,
                 "##############################", width - fill, "", pct, sim, total, rtf);
    if (final) std::fputc('\n', stderr);
  } else {
    // Plain lines every 10% for logs and CI (100% once).
    if (pct < next_pct_) return;
    next_pct_ = pct / 10 * 10 + 10;
    std::fprintf(stderr, "progress %3d%%  t = %.2f / %.2f s  real-time factor %.2fx\n", pct, sim, total, rtf);
  }
  std::fflush(stderr);
}

void ProgressPrinter::note(const std::string& what, double fraction, double wall_s) {
  if (style_ == ProgressStyle::None) return;
  const double f = std::clamp(fraction, 0.0, 1.0);
  const int pct = int(100 * f);
  // What is left at the rate so far (settling stops at rest, often before its bound: an upper
  // estimate).
  const double left = f > 0.02 ? wall_s * (1.0 - f) / f : -1;
  char eta[48] = "";
  if (left >= 0) std::snprintf(eta, sizeof eta, ", at most %.0f s left", left);
  if (what != note_what_) note_what_ = what, note_pct_ = 0, last_wall_ = -1;
  if (style_ == ProgressStyle::Bar) {
    if (wall_s - last_wall_ < 0.1 && pct < 100) return;
    last_wall_ = wall_s;
    std::fprintf(stderr, "\r%s: %3d%% (%.1f s%s)   ", what.c_str(), pct, wall_s, eta);
  } else {
    if (pct < note_pct_) return;
    note_pct_ = pct / 10 * 10 + 10;
    std::fprintf(stderr, "start-up: %s: %3d%% (%.1f s%s)\n", what.c_str(), pct, wall_s, eta);
  }
  std::fflush(stderr);
}

FrameWriter::~FrameWriter() {
  if (context_) (void)context_->make_current();  // the renderer frees its GL objects in its context
}

Status FrameWriter::heightfield_changed(const std::vector<GridRegion>& regions) {
  if (!renderer_ || regions.empty()) return Ok{};
  // The renderer's textures live in its context; another (the manager's depth render) may be
  // current after a step.
  if (Status s = context_->make_current(); !s) return s;
  for (const auto& r : regions) renderer_->heightfield_changed(r);
  return Ok{};
}

Status FrameWriter::write(const render::CameraView& view, const std::string& path) {
  // With the GL backend the renderer shares the simulation's context, so it can draw the
  // particles straight from the simulation's buffers; otherwise it makes its own.
  gl::Context* shared = manager_ ? manager_->gl_context() : nullptr;
  if (!renderer_ && why_.empty()) {
    if (!shared) {
      ctx_ = gl::Context::create_or_explain(why_);
      if (!ctx_) return Ok{};  // no images; the run's warnings say why
    }
    context_ = shared ? shared : ctx_.get();
    if (Status s = context_->make_current(); !s) return s;
    auto r = render::SceneRenderer::create(*context_, hf_);
    if (!r) return r.errors();
    renderer_ = std::move(*r);
  }
  if (!renderer_) return Ok{};
  if (shared) return write_gpu(view, path);
  std::vector<float> xyzr;
  std::vector<std::pair<std::size_t, float>> groups;
  if (manager_) {
    manager_->particles(xyzr);  // may make the manager's GL context current
    groups = manager_->particle_groups();
  }
  if (Status s = context_->make_current(); !s) return s;
  // One buffer; one source per patch so each fades in on its own (Leach & Marais §5.1).
  std::unique_ptr<render::ParticleBuffer> buf;
  if (!xyzr.empty()) {
    std::vector<Eigen::Vector4f> p(xyzr.size() / 4);
    for (std::size_t k = 0; k < p.size(); ++k) p[k] = {xyzr[4 * k], xyzr[4 * k + 1], xyzr[4 * k + 2], xyzr[4 * k + 3]};
    buf = std::make_unique<render::ParticleBuffer>(p);
    std::vector<render::ParticleSource> sources;
    std::size_t first = 0;
    for (const auto& [count, fade] : groups) {
      render::ParticleSource src = buf->source({hf_.origin_x(), hf_.origin_y(), hf_.origin_z()}, 1.0f, fade);
      src.first = std::int64_t(first);
      src.count = std::int64_t(count);
      first += count;
      if (count > 0) sources.push_back(src);
    }
    if (Status s = renderer_->set_particles(sources); !s) return s;
  } else {
    renderer_->clear_particles();
  }
  Status s = renderer_->render_png(view, path);
  renderer_->clear_particles();
  return s;
}

// GL backend: every live patch's spheres drawn from its simulation buffer (no CPU copy).
Status FrameWriter::write_gpu(const render::CameraView& view, const std::string& path) {
  if (Status s = context_->make_current(); !s) return s;
  std::vector<render::ParticleSource> sources;
  for (const auto& g : manager_->gpu_particles()) {
    render::ParticleSource src;
    src.buffer = g.buffer;
    src.count = g.count;
    src.stride = 16;
    src.position_offset = 0;
    src.radius_offset = 12;
    src.origin = g.origin;
    src.scale = g.scale;
    src.fade = g.fade;
    if (src.count > 0) sources.push_back(src);
  }
  if (Status s = renderer_->set_particles(sources); !s) return s;
  Status s = renderer_->render_png(view, path);
  renderer_->clear_particles();
  return s;
}

}  // namespace sandpatch
