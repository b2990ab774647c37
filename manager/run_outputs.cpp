#include "manager/run_outputs.hpp"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
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

namespace {

render::BodyInstance instance(const RigidShape& shape, const Eigen::Vector3d& position, const Eigen::Quaternionf& orientation,
                              int entry) {
  render::BodyInstance b;
  switch (shape.kind) {
    case RigidShapeKind::Sphere: b.kind = render::BodyShapeKind::Sphere; break;
    case RigidShapeKind::Box: b.kind = render::BodyShapeKind::Box; break;
    case RigidShapeKind::Cylinder: b.kind = render::BodyShapeKind::Cylinder; break;
    case RigidShapeKind::Capsule: b.kind = render::BodyShapeKind::Capsule; break;
    case RigidShapeKind::Mesh: b.kind = render::BodyShapeKind::Mesh; break;
  }
  b.radius = shape.radius;
  b.height = shape.height;
  b.half_extents = shape.half_extents;
  b.vertices = shape.vertices;
  b.triangles = shape.triangles;
  b.position = position;
  b.orientation = orientation;
  b.albedo = render::body_palette(entry);
  return b;
}

}  // namespace

std::vector<render::BodyInstance> body_instances(const World& world) {
  std::vector<render::BodyInstance> out;
  const BulletWorld& bw = world.bullet();
  const auto& entries = world.entries();
  std::vector<const RigidBodyDef*> due(entries.size(), nullptr);  // scheduled for now or earlier, not spawned yet
  for (const auto& [entry, def] : world.pending())
    if (entry < entries.size() && entries[entry].spawn_time <= world.time() + 1e-9) due[entry] = &def;
  for (std::size_t k = 0; k < entries.size(); ++k) {
    const World::Entry& e = entries[k];
    if (due[k]) {
      out.push_back(instance(due[k]->shape, due[k]->position, due[k]->orientation, int(k)));
      continue;
    }
    if (!e.spawned() || e.removed || !world.alive(e.id)) continue;
    const BodyState st = bw.state(e.id);
    out.push_back(instance(bw.definition(e.id).shape, st.position, st.orientation, int(k)));
  }
  return out;
}

// The renderer, made on the first image (in the simulation's GL context with the GL backend,
// so it can draw the particles straight from the simulation's buffers; otherwise its own).
Status FrameWriter::prepare() {
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
  return Ok{};
}

namespace {

// A ready patch's footprint (world x0, z0, x1, z1, m): the heightfield samples it covers.
Eigen::Vector4d footprint(const TerrainManager::PatchInfo& p, const Heightfield& hf) {
  if (!p.ready || p.region.empty()) return Eigen::Vector4d::Zero();
  const double h = hf.spacing();
  return {hf.origin_x() + h * p.region.i0, hf.origin_z() + h * p.region.j0,
          hf.origin_x() + h * (p.region.i0 + p.region.ni - 1), hf.origin_z() + h * (p.region.j0 + p.region.nj - 1)};
}

// The band over which the terrain fades into a patch: six granule diameters (m).
float footprint_band(const TerrainManager::PatchInfo& p) { return float(12.0 * p.granule_radius_world); }

// How many times coarser than the sand they stand for the granules are drawn: the particle
// scale (render::ParticleSource::shading_scale), in its [1, 64].
float shading_scale(const TerrainManager::PatchInfo& p) {
  return std::isfinite(p.particle_scale) ? float(std::clamp(p.particle_scale, 1.0, 64.0)) : 1.0f;
}

}  // namespace

// CPU backend: the granule spheres copied into one buffer, one source per patch so each fades
// in on its own (Leach & Marais §5.1).
Status FrameWriter::set_particles_cpu(std::unique_ptr<render::ParticleBuffer>& buf) {
  std::vector<float> xyzr;
  std::vector<std::pair<std::size_t, float>> groups;
  std::vector<TerrainManager::PatchInfo> patches;
  if (manager_) {
    manager_->particles(xyzr);  // may make the manager's GL context current
    groups = manager_->particle_groups();
    patches = manager_->patches();  // the same slot order as the groups
  }
  if (Status s = context_->make_current(); !s) return s;
  if (xyzr.empty()) {
    renderer_->clear_particles();
    return Ok{};
  }
  std::vector<Eigen::Vector4f> p(xyzr.size() / 4);
  for (std::size_t k = 0; k < p.size(); ++k) p[k] = {xyzr[4 * k], xyzr[4 * k + 1], xyzr[4 * k + 2], xyzr[4 * k + 3]};
  buf = std::make_unique<render::ParticleBuffer>(p);
  std::vector<render::ParticleSource> sources;
  std::size_t first = 0;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    const auto& [count, fade] = groups[g];
    render::ParticleSource src = buf->source({hf_.origin_x(), hf_.origin_y(), hf_.origin_z()}, 1.0f, fade);
    src.first = std::int64_t(first);
    src.count = std::int64_t(count);
    if (g < patches.size()) {
      src.footprint = footprint(patches[g], hf_);
      src.footprint_band = footprint_band(patches[g]);
      src.shading_scale = shading_scale(patches[g]);
      src.sphere_radius = float(patches[g].granule_radius_world);
    }
    first += count;
    if (count > 0) sources.push_back(src);
  }
  return renderer_->set_particles(sources);
}

// GL backend: every live patch's spheres drawn from its simulation buffer (no CPU copy).
Status FrameWriter::set_particles_gpu() {
  if (Status s = context_->make_current(); !s) return s;
  const auto patches = manager_->patches();
  std::vector<render::ParticleSource> sources;
  for (const auto& g : manager_->gpu_particles()) {
    render::ParticleSource src;
    src.buffer = g.buffer;
    src.count = g.count;
    src.stride = 16;
    src.position_offset = 0;
    src.radius_offset = 12;
    // only the granules: the bodies' shell spheres share the buffer (in cell order), and
    // drawn as sand they covered the bodies
    src.id_offset = int(g.id_offset);
    src.id_limit = g.granule_spheres;
    src.origin = g.origin;
    src.scale = g.scale;
    src.fade = g.fade;
    for (const auto& p : patches)  // the patch whose simulation frame this is
      if (p.origin == g.origin) {
        src.footprint = footprint(p, hf_);
        src.footprint_band = footprint_band(p);
        src.shading_scale = shading_scale(p);
        src.sphere_radius = float(p.granule_radius_world);
      }
    if (src.count > 0) sources.push_back(src);
  }
  return renderer_->set_particles(sources);
}

Result<render::Image> FrameWriter::render(const render::CameraView& view, const render::FrameFlags& flags) {
  if (Status s = prepare(); !s) return s.errors();
  if (!renderer_) return render::Image{};
  std::unique_ptr<render::ParticleBuffer> buf;  // alive until the frame is drawn
  const bool gpu = manager_ && manager_->gl_context();
  if (Status s = gpu ? set_particles_gpu() : set_particles_cpu(buf); !s) return s.errors();
  std::vector<render::BodyInstance> bodies = body_instances(world_);
  if (show_shells_ && manager_) {
    std::vector<double> xyzr;
    manager_->shell_spheres(xyzr);  // may make the manager's GL context current
    if (Status s = context_->make_current(); !s) return s.errors();
    for (std::size_t k = 0; k + 3 < xyzr.size(); k += 4) {
      render::BodyInstance b;
      b.kind = render::BodyShapeKind::Sphere;
      b.radius = float(xyzr[k + 3]);
      b.position = {xyzr[k], xyzr[k + 1], xyzr[k + 2]};
      b.albedo = {0.85f, 0.15f, 0.75f};  // magenta: no body of the palette and no sand is near it
      b.segments = 8;
      bodies.push_back(b);
    }
  }
  if (Status s = renderer_->set_bodies(bodies); !s) return s.errors();
  auto img = renderer_->render(view, flags);
  renderer_->clear_particles();
  renderer_->clear_bodies();
  return img;
}

Status FrameWriter::write(const render::CameraView& view, const std::string& path, const render::FrameFlags& flags) {
  auto img = render(view, flags);
  if (!img) return img.errors();
  if (!renderer_) return Ok{};
  return render::save_png(path, img.value());
}

namespace {

// `s` quoted for /bin/sh: inside single quotes, with every ' written as '\''.
std::string shell_quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace

Status VideoWriter::available() {
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "";
  for (std::size_t a = 0; a <= dirs.size();) {
    std::size_t b = dirs.find(':', a);
    if (b == std::string::npos) b = dirs.size();
    const std::string dir = dirs.substr(a, b - a);
    if (!dir.empty() && access((dir + "/ffmpeg").c_str(), X_OK) == 0) return Ok{};
    a = b + 1;
  }
  return Error{"", "", "", "ffmpeg is not installed (no executable ffmpeg on PATH; Debian package ffmpeg, "
                           "scripts/install-deps.sh installs it)"};
}

VideoWriter::~VideoWriter() {
  if (pipe_) pclose(pipe_);
}

Status VideoWriter::open(const std::string& path, int width, int height, double fps) {
  if (pipe_) return Error{path, "", "", "a video is already open"};
  if (width < 1 || height < 1 || !(fps > 0 && std::isfinite(fps)))
    return Error{path, "", std::to_string(width) + " x " + std::to_string(height) + " at " + std::to_string(fps),
                 "needs a size of at least 1 x 1 and a frame rate > 0"};
  // A broken pipe (ffmpeg gone) must come back as a write error, not end the program.
  std::signal(SIGPIPE, SIG_IGN);
  char fps_s[64];
  std::snprintf(fps_s, sizeof fps_s, "%.9g", fps);
  const std::string cmd = "ffmpeg -hide_banner -loglevel error -y -f rawvideo -pix_fmt rgba -s " + std::to_string(width) +
                          "x" + std::to_string(height) + " -r " + fps_s +
                          " -i - -vf 'pad=ceil(iw/2)*2:ceil(ih/2)*2' -pix_fmt yuv420p " +
                          shell_quote(!path.empty() && path[0] == '-' ? "./" + path : path);  // not an option
  pipe_ = popen(cmd.c_str(), "w");
  if (!pipe_) return Error{path, "", "", std::string("cannot start ffmpeg: ") + std::strerror(errno)};
  path_ = path;
  width_ = width;
  height_ = height;
  return Ok{};
}

Status VideoWriter::add(const render::Image& img) {
  if (!pipe_) return Error{path_, "", "", "the video is not open"};
  if (img.width != width_ || img.height != height_)
    return Error{path_, "", std::to_string(img.width) + " x " + std::to_string(img.height),
                 "every video frame must be " + std::to_string(width_) + " x " + std::to_string(height_)};
  if (std::fwrite(img.rgba.data(), 1, img.rgba.size(), pipe_) != img.rgba.size())
    return Error{path_, "", "", "ffmpeg stopped taking frames (see its messages above)"};
  return Ok{};
}

Status VideoWriter::close() {
  if (!pipe_) return Ok{};
  const int rc = pclose(pipe_);
  pipe_ = nullptr;
  if (rc != 0) return Error{path_, "", "", "ffmpeg failed (exit status " + std::to_string(rc) + "; see its messages above)"};
  return Ok{};
}

// ---- RunCsv ----

namespace {
std::filesystem::path temp_of(const std::filesystem::path& p) { return std::filesystem::path(p.string() + ".part"); }

// A name as one CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break.
std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}
}  // namespace

std::filesystem::path RunCsv::patches_path(const std::filesystem::path& bodies) {
  std::filesystem::path p = bodies;
  const std::string stem = p.extension() == ".csv" ? p.stem().string() : p.filename().string();
  return p.replace_filename(stem + "_patches.csv");
}

const char* RunCsv::body_header() {
  return "t,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz,granular_fx,granular_fy,granular_fz,granular_tx,granular_ty,"
         "granular_tz,heightfield_fx,heightfield_fy,heightfield_fz,sinkage,on_particles";
}
std::filesystem::path RunCsv::frames_path(const std::filesystem::path& bodies) {
  std::filesystem::path p = bodies;
  const std::string stem = p.extension() == ".csv" ? p.stem().string() : p.filename().string();
  return p.replace_filename(stem + "_frames.csv");
}

const char* RunCsv::patch_header() { return "t,patch,state,granules,spheres,substeps,step_ms,rebuilds"; }
const char* RunCsv::frame_header() {
  // (the stages' columns from the frame's own list of stages, all but the outputs)
  static const std::string header = [] {
    std::string h = "t,frame_ms,budget_ms";
    for (int k = 0; k < int(Stage::Count); ++k)
      if (Stage(k) != Stage::Outputs) h += std::string(",") + kStageNames[std::size_t(k)] + "_ms";
    return h + ",conversion_parts,urgent_fills,promotions,granules_uploaded,ready,demotion_parts,demotions,wakes,"
               "patches_stepped,side_by_side,substeps,sphere_steps";
  }();
  return header.c_str();
}

Status RunCsv::open(const std::filesystem::path& bodies) {
  discard();
  path_ = bodies;
  patches_ = patches_path(bodies);
  frames_ = frames_path(bodies);
  for (const auto& p : {path_, patches_, frames_}) {
    std::error_code ec;
    if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path(), ec);
  }
  bodies_ = std::fopen(temp_of(path_).c_str(), "wb");
  if (!bodies_) return Error{path_.string(), "", "", "must be a writable file", "cannot create " + temp_of(path_).string()};
  patch_rows_ = std::fopen(temp_of(patches_).c_str(), "wb");
  if (!patch_rows_) {
    discard();
    return Error{patches_.string(), "", "", "must be a writable file", "cannot create " + temp_of(patches_).string()};
  }
  frame_rows_ = std::fopen(temp_of(frames_).c_str(), "wb");
  if (!frame_rows_) {
    discard();
    return Error{frames_.string(), "", "", "must be a writable file", "cannot create " + temp_of(frames_).string()};
  }
  std::fprintf(bodies_, "%s\n", body_header());
  std::fprintf(patch_rows_, "%s\n", patch_header());
  std::fprintf(frame_rows_, "%s\n", frame_header());
  return Ok{};
}

Status RunCsv::frame(const World& world, double t) {
  if (!is_open()) return Ok{};
  for (const World::Entry& e : world.entries()) {
    if (e.removed || !e.spawned() || !world.alive(e.id)) continue;
    const BodyState s = world.bullet().state(e.id);
    const World::Contact c = world.contact(e.id);
    const auto& q = s.orientation;
    std::fprintf(bodies_,
                 "%.9g,%s,%.9g,%.9g,%.9g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,%.7g,"
                 "%.7g,%.7g,%.9g,%d\n",
                 t, csv_field(e.name).c_str(), s.position.x(), s.position.y(), s.position.z(), double(q.w()), double(q.x()),
                 double(q.y()), double(q.z()), double(s.linear_velocity.x()), double(s.linear_velocity.y()),
                 double(s.linear_velocity.z()), double(s.angular_velocity.x()), double(s.angular_velocity.y()),
                 double(s.angular_velocity.z()), double(c.granular.force.x()), double(c.granular.force.y()),
                 double(c.granular.force.z()), double(c.granular.torque.x()), double(c.granular.torque.y()),
                 double(c.granular.torque.z()), double(c.heightfield_force.x()), double(c.heightfield_force.y()),
                 double(c.heightfield_force.z()), c.sinkage, c.granular.carried ? 1 : 0);
  }
  if (const TerrainManager* m = world.manager())
    for (const auto& p : m->patches())
      std::fprintf(patch_rows_, "%.9g,%d,%s,%d,%d,%d,%.6g,%d\n", t, p.patch,
                   !p.ready ? "filling" : p.asleep ? "asleep" : p.stepped ? "active" : "held", p.granules, p.last_spheres,
                   p.stepped ? p.last_substeps : 0, p.stepped ? p.last_step_ms : 0.0, p.stepped ? p.last_rebuilds : 0);
  {
    const World::FrameRecord& f = world.last_frame();
    const auto& st = f.stage_ms;
    TerrainManager::FrameWork k;
    if (const TerrainManager* m = world.manager()) k = m->last_frame_work();
    std::fprintf(frame_rows_, "%.9g,%.6g,%.6g", t, f.wall_ms, std::isfinite(f.budget_ms) ? f.budget_ms : 0.0);
    for (int s = 0; s < int(Stage::Count); ++s)
      if (Stage(s) != Stage::Outputs) std::fprintf(frame_rows_, ",%.6g", st[std::size_t(s)]);
    std::fprintf(frame_rows_, ",%d,%d,%d,%d,%d,%d,%d,%d,%d,%d,%lld,%lld\n", k.conversion_parts, k.urgent_fills,
                 k.promotions, k.granules_uploaded, k.ready, k.demotion_parts, k.demotions, k.wakes, k.patches_stepped,
                 k.side_by_side, (long long)k.substeps, (long long)k.sphere_steps);
  }
  if (std::ferror(bodies_) || std::ferror(patch_rows_) || std::ferror(frame_rows_))
    return Error{path_.string(), "", "", "must be writable", "write failed"};
  return Ok{};
}

Status RunCsv::close() {
  if (!is_open()) return Ok{};
  const bool bad = std::fclose(bodies_) != 0, bad_p = std::fclose(patch_rows_) != 0, bad_f = std::fclose(frame_rows_) != 0;
  bodies_ = patch_rows_ = frame_rows_ = nullptr;
  if (bad || bad_p || bad_f) {
    discard();
    return Error{(bad ? path_ : bad_p ? patches_ : frames_).string(), "", "", "must be writable", "write failed"};
  }
  // (renamed one by one; when one fails, those renamed already are removed: none is left half)
  const std::filesystem::path files[3] = {frames_, patches_, path_};
  for (int n = 0; n < 3; ++n) {
    std::error_code ec;
    std::filesystem::rename(temp_of(files[n]), files[n], ec);
    if (!ec) continue;
    const std::string why = ec.message();
    for (int m = 0; m < n; ++m) std::filesystem::remove(files[m], ec);
    discard();
    return Error{files[n].string(), "", "", "must be writable", why};
  }
  return Ok{};
}

void RunCsv::discard() {
  if (bodies_) std::fclose(bodies_);
  if (patch_rows_) std::fclose(patch_rows_);
  if (frame_rows_) std::fclose(frame_rows_);
  bodies_ = patch_rows_ = frame_rows_ = nullptr;
  std::error_code ec;
  if (!path_.empty()) std::filesystem::remove(temp_of(path_), ec);
  if (!patches_.empty()) std::filesystem::remove(temp_of(patches_), ec);
  if (!frames_.empty()) std::filesystem::remove(temp_of(frames_), ec);
}

RunCsv::~RunCsv() { discard(); }

}  // namespace sandpatch
