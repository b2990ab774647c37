#include "manager/run.hpp"

#include <omp.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

#include "common/hash.hpp"
#include "gl/context.hpp"
#include "heightfield/heightfield.hpp"
#include "heightfield/io.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain.hpp"
#include "manager/terrain_manager.hpp"
#include "render/render.hpp"
#include "scene/mesh.hpp"

namespace fs = std::filesystem;

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;
using ojson = nlohmann::ordered_json;

Eigen::Vector3f vec3f(const Vec3d& v) { return {float(v[0]), float(v[1]), float(v[2])}; }
ojson vec_json(const Eigen::Vector3d& v) { return ojson::array({v.x(), v.y(), v.z()}); }
ojson vec_json(const Eigen::Vector3f& v) { return ojson::array({v.x(), v.y(), v.z()}); }

std::string expand_pattern(std::string pattern, long long frame, double t, const char* ext,
                           const std::string& camera = "") {
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

class ProgressPrinter {
 public:
  ProgressPrinter(ProgressStyle style, long long frames, double dt) : frames_(frames), dt_(dt) {
    if (style == ProgressStyle::Auto) style = isatty(STDERR_FILENO) ? ProgressStyle::Bar : ProgressStyle::Lines;
    style_ = style;
  }
  void update(long long frame, double wall_s, bool final = false) {
    if (style_ == ProgressStyle::None) return;
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

 private:
  ProgressStyle style_;
  long long frames_;
  double dt_;
  double last_wall_ = -1;
  int next_pct_ = 0;
};

// Camera pose at simulated time t: fixed, or linear between path keyframes (held outside).
render::CameraView camera_at(const CameraDef& c, double t) {
  render::CameraView v;
  Eigen::Vector3d p(c.position[0], c.position[1], c.position[2]), q(c.target[0], c.target[1], c.target[2]);
  if (!c.path.empty()) {
    auto key = [](const CameraKeyDef& k, Eigen::Vector3d& pos, Eigen::Vector3d& tgt) {
      pos = {k.position[0], k.position[1], k.position[2]};
      tgt = {k.target[0], k.target[1], k.target[2]};
    };
    key(c.path.front(), p, q);
    for (std::size_t k = 1; k < c.path.size(); ++k) {
      const CameraKeyDef& a = c.path[k - 1];
      const CameraKeyDef& b = c.path[k];
      if (t < a.time) break;
      if (t >= b.time) {
        key(b, p, q);
        continue;
      }
      Eigen::Vector3d pa, qa, pb, qb;
      key(a, pa, qa);
      key(b, pb, qb);
      const double u = (t - a.time) / (b.time - a.time);
      p = pa + u * (pb - pa);
      q = qa + u * (qb - qa);
      break;
    }
  }
  v.position = p;
  v.target = q;
  v.fov_deg = float(c.fov_deg);
  v.width = c.width;
  v.height = c.height;
  return v;
}

// Images of the run: one GL context and one scene renderer, made on the first image.
class FrameWriter {
 public:
  FrameWriter(const Heightfield& hf, const TerrainManager* manager) : hf_(hf), manager_(manager) {}
  ~FrameWriter() {
    if (context_) (void)context_->make_current();  // the renderer frees its GL objects in its context
  }
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;
  bool unavailable() const { return !why_.empty(); }
  const std::string& why() const { return why_; }
  void heightfield_changed(const std::vector<GridRegion>& regions) {
    if (renderer_)
      for (const auto& r : regions) renderer_->heightfield_changed(r);
  }
  // Renders `view` (terrain and the live patches' granules) into `path`.
  Status write(const render::CameraView& view, const std::string& path) {
    // With the GL backend the renderer shares the simulation's context, so it can draw the
    // particles straight from the simulation's buffers; otherwise it makes its own.
    gl::Context* shared = manager_ ? manager_->gl_context() : nullptr;
    if (!renderer_ && why_.empty()) {
      if (!shared) {
        auto ctx = gl::Context::create();
        if (!ctx) {
          why_ = ctx.message();
          return Ok{};
        }
        ctx_ = std::move(*ctx);
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

 private:
  // GL backend: every live patch's spheres drawn from its simulation buffer (no CPU copy).
  Status write_gpu(const render::CameraView& view, const std::string& path) {
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

  const Heightfield& hf_;
  const TerrainManager* manager_;
  std::unique_ptr<gl::Context> ctx_;    // own context (CPU backend)
  gl::Context* context_ = nullptr;      // the context in use (own or the manager's)
  std::unique_ptr<render::SceneRenderer> renderer_;
  std::string why_;
};

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

// The terrain manager's definition from the scene (docs/scene-format.md).
Result<RigidBodyDef> to_rigid_body(const SceneDef& scene, std::size_t index) {
  const BodyDef& b = scene.bodies[index];
  RigidBodyDef d;
  d.name = b.name;
  d.mass = float(b.mass_value());
  d.position = {b.pose.position[0], b.pose.position[1], b.pose.position[2]};
  const auto& q = b.pose.orientation;
  d.orientation = Eigen::Quaternionf(float(q[0]), float(q[1]), float(q[2]), float(q[3])).normalized();
  d.linear_velocity = vec3f(b.linear_velocity);
  d.angular_velocity = vec3f(b.angular_velocity);
  d.friction = float(b.friction);
  d.restitution = float(b.restitution);
  const ShapeDef& s = b.shape;
  d.shape.radius = float(s.radius);
  d.shape.height = float(s.height);
  d.shape.half_extents = vec3f(s.half_extents);
  switch (s.kind) {
    case ShapeKind::Sphere: d.shape.kind = RigidShapeKind::Sphere; break;
    case ShapeKind::Box: d.shape.kind = RigidShapeKind::Box; break;
    case ShapeKind::Cylinder: d.shape.kind = RigidShapeKind::Cylinder; break;
    case ShapeKind::Capsule: d.shape.kind = RigidShapeKind::Capsule; break;
    case ShapeKind::Mesh: {
      d.shape.kind = RigidShapeKind::Mesh;
      auto mesh = load_obj_mesh(s.file, s.scale);
      if (!mesh) return mesh.errors();
      // Bodies are centred on their centre of mass.
      const Eigen::Vector3f c = mesh->centroid().cast<float>();
      for (const auto& v : mesh->vertices) d.shape.vertices.push_back(v - c);
      d.shape.triangles = mesh->triangles;
      break;
    }
  }
  return d;
}

TerrainManagerDef manager_def(const SceneDef& scene, int threads, const std::string& backend) {
  const SimulationDef& sim = scene.simulation;
  const MaterialDef* mat = scene.terrain.material.empty() ? &scene.materials.front()
                                                         : scene.find_material(scene.terrain.material);
  TerrainManagerDef d;
  d.material.radius = float(mat->granule_radius);
  d.material.density = float(mat->density);
  d.material.friction = float(mat->friction);
  d.material.restitution = float(mat->restitution_value());
  d.material.stiffness = float(mat->stiffness);
  d.material.tangential_stiffness_ratio = float(mat->tangential_stiffness_ratio);
  d.particle_scale = sim.particle_scale;
  d.steps_per_contact = sim.steps_per_contact;
  d.slots = sim.pool.slots;
  d.granules_per_slot = sim.pool.granules_per_slot;
  d.soil_depth = scene.terrain.soil_depth.value_or(2.0);
  d.patch_depth = std::min(d.patch_depth, d.soil_depth);
  d.sleep_speed = sim.sleep.speed_threshold;
  d.sleep_time = sim.sleep.hold_time;
  d.idle_timeout = sim.idle_timeout;
  d.gravity = {sim.gravity[0], sim.gravity[1], sim.gravity[2]};
  d.threads = threads;
  d.seed = sim.seed;
  d.backend = backend;
  return d;
}

RunResult run_scene(const SceneDef& scene, const RunOptions& opt) {
  RunResult res;
  auto fail = [&](ExitCode code, const std::string& stage, const std::string& msg) {
    res.code = code;
    res.stage = stage;
    res.message = msg;
    return res;
  };
  const SimulationDef& sim = scene.simulation;

  // ---- everything that can be refused is checked before the first frame ----
  if (!opt.backend.empty() && opt.backend != "cpu" && opt.backend != "gl")
    return fail(ExitCode::BadInput, "options", "--backend " + opt.backend + ": allowed values are cpu, gl");
  if (!opt.final_camera.empty() && !scene.find_camera(opt.final_camera))
    return fail(ExitCode::BadInput, "options", "--camera " + opt.final_camera + ": the scene has no such camera");
  const std::string backend = opt.backend.empty() ? to_string(sim.backend) : opt.backend;
  const int threads_req = opt.threads >= 0 ? opt.threads : sim.threads;
  const int threads = threads_req > 0 ? threads_req : omp_get_num_procs();
  omp_set_num_threads(threads);

  const double dt = sim.dt;
  long long frames = opt.frames > 0 ? opt.frames : std::llround(std::ceil((opt.seconds > 0 ? opt.seconds : sim.duration) / dt - 1e-9));
  if (frames < 1) frames = 1;

  auto hf_result = load_scene_terrain(scene);
  if (!hf_result) return fail(ExitCode::BadInput, "terrain", hf_result.message());
  Heightfield& hf = *hf_result;

  auto below = check_bodies_against_terrain(
      scene, [&](double x, double z) { return float(bedrock_world_height(scene, hf, x, z)); });
  if (!below.empty()) return fail(ExitCode::BadInput, "bodies", Result<Ok>(below).message());
  // A body whose centre starts below the terrain surface is inside the terrain: Bullet's
  // heightfield contact pushes a body along the triangle's normal from the side its centre is
  // on, so it would be pushed down and fall for ever. Refused, naming the body and where it is
  // (docs/extremes.md). A body only partly in the ground (centre above the surface) is pushed
  // out by the contact. Checked against the terrain at the start, for every body (also those
  // spawned later).
  {
    std::vector<Error> inside;
    const double w = (hf.samples_x() - 1) * double(hf.spacing()), d = (hf.samples_z() - 1) * double(hf.spacing());
    for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
      const BodyDef& b = scene.bodies[i];
      const double x = b.pose.position[0] - hf.origin_x(), z = b.pose.position[2] - hf.origin_z();
      if (x < 0 || z < 0 || x > w || z > d) continue;  // no terrain under it
      const double surface = hf.origin_y() + hf.sample(float(x), float(z));
      if (b.pose.position[1] >= surface) continue;
      inside.push_back(Error{scene.source_path, "bodies[" + std::to_string(i) + "].pose.position",
                             "[" + format_number(b.pose.position[0]) + ", " + format_number(b.pose.position[1]) + ", " +
                                 format_number(b.pose.position[2]) + "]",
                             "body '" + b.name + "' starts inside the terrain: its centre is below the surface (world y = " +
                                 format_number(surface) + " m there); it must start at or above it",
                             "its lowest point may touch or enter the ground, its centre may not"});
    }
    if (!inside.empty()) return fail(ExitCode::BadInput, "bodies", Result<Ok>(inside).message());
  }

  std::vector<RigidBodyDef> body_defs;
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    auto d = to_rigid_body(scene, i);
    if (!d) return fail(ExitCode::BadInput, "bodies", d.message());
    body_defs.push_back(std::move(*d));
  }

  const fs::path out_dir = opt.out_dir.empty() ? fs::path("out") / scene.name : fs::path(opt.out_dir);
  {
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec || !fs::is_directory(out_dir))
      return fail(ExitCode::BadInput, "outputs", out_dir.string() + ": cannot create output directory" +
                                                     (ec ? ": " + ec.message() : ""));
  }

  std::vector<std::string> warnings;

  auto world_result = BulletWorld::create(hf, vec3f(sim.gravity));
  if (!world_result) return fail(ExitCode::BadInput, "bodies", world_result.message());
  BulletWorld& world = **world_result;
  // The terrain manager (granular patches), unless the scene turns them off.
  std::unique_ptr<TerrainManager> manager;
  if (sim.granular_patches) {
    TerrainManagerDef md = manager_def(scene, threads, backend);
    // Particle scale by distance from a camera (scenario 2 of Leach & Marais §6.3): the bands,
    // and the camera where it is at the start; the frame loop moves it (set_camera).
    if (const auto& sd = sim.scale_by_distance) {
      for (const auto& b : sd->bands) md.scale_bands.push_back({b.max_distance, b.particle_scale});
      md.camera = camera_at(*scene.find_camera(sd->camera), 0.0).position.cast<double>();
    }
    // A flat bedrock (terrain.bedrock_height) bounds the patches too (heightfield-local m).
    if (scene.terrain.bedrock_height) md.bedrock_height = bedrock_world_height(scene, hf, 0, 0) - hf.origin_y();
    auto m = TerrainManager::create(md, hf, world);
    if (!m) return fail(ExitCode::BadInput, "activation", m.message());
    manager = std::move(*m);
  }

  // ---- the frame loop ----
  Profile profile;
  std::vector<RigidBodyId> ids(scene.bodies.size());
  std::vector<bool> spawned(scene.bodies.size(), false);
  std::vector<std::size_t> next_export(scene.outputs.heightfields.size(), 0);
  std::vector<std::size_t> next_frame(scene.outputs.frames.size(), 0);
  FrameWriter images(hf, manager.get());
  std::size_t images_skipped = 0;
  std::vector<std::string> written;
  std::vector<double> frame_ms;
  std::vector<char> conversion_frame;  // a promotion, upload or demotion ran in the frame
  int filling = 0;                     // patches promoted and not yet ready
  int peak_granules = 0;
  frame_ms.reserve(std::size_t(frames));
  ProgressPrinter progress(opt.progress, frames, dt);
  const auto t_start = Clock::now();

  auto export_heightfield = [&](const HeightfieldOutputDef& o, long long frame, double t) -> Status {
    const fs::path p = out_dir / expand_pattern(o.file, frame, t, format_ext(o.format));
    Status s = Ok{};
    switch (o.format) {
      case HeightfieldFormat::Png16: s = save_png16(p.string(), hf); break;
      case HeightfieldFormat::RawF32: s = save_raw_f32(p.string(), hf); break;
      case HeightfieldFormat::EsriAscii: s = save_esri_ascii(p.string(), hf); break;
    }
    if (s) written.push_back(p.string());
    return s;
  };

  for (long long frame = 0; frame < frames; ++frame) {
    const auto f0 = Clock::now();
    const double dem_ms_before = profile.timer(Stage::Dem).total_ms;
    const std::size_t events_before = manager ? manager->events().size() : 0;
    bool converted = filling > 0;
    const double t = double(frame) * dt;  // s, simulated time at the start of this frame
    {
      auto timer = profile.time(Stage::Spawn);
      for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
        if (spawned[i] || scene.bodies[i].spawn_time > t + 1e-9) continue;
        auto id = world.add_body(body_defs[i]);
        if (!id) return fail(ExitCode::RuntimeFailure, "spawn", id.message());
        ids[i] = *id;
        spawned[i] = true;
      }
    }
    if (manager && sim.scale_by_distance)
      manager->set_camera(camera_at(*scene.find_camera(sim.scale_by_distance->camera), t).position.cast<double>());
    if (manager)
      if (Status st = manager->before_bodies(t, dt, profile); !st)
        return fail(ExitCode::RuntimeFailure, "dem", st.message());
    {
      auto timer = profile.time(Stage::Bodies);
      world.step_frame(float(dt), sim.substeps);  // the patches' forces act over every substep
      for (std::size_t i = 0; i < ids.size(); ++i) {
        if (!spawned[i]) continue;
        const BodyState st = world.state(ids[i]);
        if (!st.position.allFinite() || !st.linear_velocity.allFinite())
          return fail(ExitCode::RuntimeFailure, "bodies",
                      "body '" + scene.bodies[i].name + "' has a non-finite state at t = " + std::to_string(t + dt) + " s");
      }
    }
    if (manager)
      if (Status st = manager->after_bodies(t, dt, profile); !st)
        return fail(ExitCode::RuntimeFailure, "demotion", st.message());
    if (manager) peak_granules = std::max(peak_granules, manager->granules());
    {
      auto timer = profile.time(Stage::Outputs);
      const double t_end = t + dt;
      if (manager) images.heightfield_changed(manager->take_dirty_regions());
      for (std::size_t k = 0; k < scene.outputs.frames.size(); ++k) {
        const FrameOutputDef& o = scene.outputs.frames[k];
        bool due = o.every_k_frames > 0 && (frame + 1) % o.every_k_frames == 0;
        while (next_frame[k] < o.times.size() && o.times[next_frame[k]] <= t_end + 1e-9) {
          due = true;
          ++next_frame[k];
        }
        if (!due) continue;
        const CameraDef* cam = scene.find_camera(o.camera);
        const fs::path p = out_dir / expand_pattern(o.file, frame + 1, t_end, "png", o.camera);
        if (Status s = images.write(camera_at(*cam, t_end), p.string()); !s)
          return fail(ExitCode::RuntimeFailure, "outputs", s.message());
        if (images.unavailable()) ++images_skipped;
        else written.push_back(p.string());
      }
      for (std::size_t k = 0; k < scene.outputs.heightfields.size(); ++k) {
        const auto& o = scene.outputs.heightfields[k];
        while (next_export[k] < o.times.size() && o.times[next_export[k]] <= t_end + 1e-9) {
          if (Status s = export_heightfield(o, frame + 1, t_end); !s)
            return fail(ExitCode::RuntimeFailure, "outputs", s.message());
          ++next_export[k];
        }
      }
    }
    if (manager) {
      const auto& ev = manager->events();
      for (std::size_t k = events_before; k < ev.size(); ++k) {
        const PatchEventKind kind = ev[k].kind;
        if (kind == PatchEventKind::Promoted) ++filling;
        if (kind == PatchEventKind::Ready) --filling;
        converted = converted || kind == PatchEventKind::Promoted || kind == PatchEventKind::Ready ||
                    kind == PatchEventKind::Demoted;
      }
    }
    frame_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - f0).count());
    conversion_frame.push_back(converted);
    if (opt.on_frame) {
      FrameSample fs;
      fs.frame = frame;
      fs.time_s = t + dt;
      fs.frame_ms = frame_ms.back();
      fs.dem_ms = profile.timer(Stage::Dem).total_ms - dem_ms_before;
      if (manager) {
        fs.patches_filling = manager->filling_patches();
        fs.patches_asleep = manager->asleep_patches();
        fs.patches_active = manager->ready_patches() - fs.patches_asleep;
        fs.granules = manager->granules();
        fs.queued_requests = manager->queued_requests();
        fs.pool_bytes = manager->pool_bytes();
      }
      opt.on_frame(fs);
    }
    progress.update(frame + 1, std::chrono::duration<double>(Clock::now() - t_start).count());
  }
  const double wall_s = std::chrono::duration<double>(Clock::now() - t_start).count();
  progress.update(frames, wall_s, true);
  {
    auto timer = profile.time(Stage::Outputs);
    if (!opt.final_image.empty()) {
      render::CameraView view;
      if (const CameraDef* c = opt.final_camera.empty() ? (scene.cameras.empty() ? nullptr : &scene.cameras.front())
                                                        : scene.find_camera(opt.final_camera)) {
        view = camera_at(*c, double(frames) * dt);
      } else {
        // No camera in the scene: look at the terrain's centre from a corner above it.
        const double cx = hf.origin_x() + 0.5 * hf.extent_x(), cz = hf.origin_z() + 0.5 * hf.extent_z();
        const double cy = hf.origin_y() + hf.max_height();
        view.position = {cx - 0.4 * hf.extent_x(), cy + 0.3 * hf.extent_x(), cz - 0.4 * hf.extent_z()};
        view.target = {cx, cy - 0.1 * hf.extent_x(), cz};
        view.width = 640;
        view.height = 360;
      }
      if (Status s = images.write(view, opt.final_image); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
      if (images.unavailable()) return fail(ExitCode::RuntimeFailure, "outputs", "no image: " + images.why());
      written.push_back(opt.final_image);
    }
  }
  // The run ends by converting every live patch back, so the final terrain holds its changes.
  const int live_patches = manager ? manager->active_patches() : 0;
  if (manager)
    if (Status st = manager->demote_all(double(frames) * dt, profile); !st)
      return fail(ExitCode::RuntimeFailure, "demotion", st.message());
  {
    auto timer = profile.time(Stage::Outputs);
    if (manager) images.heightfield_changed(manager->take_dirty_regions());
    for (const auto& o : scene.outputs.heightfields)
      if (o.at_end)
        if (Status s = export_heightfield(o, frames, double(frames) * dt); !s)
          return fail(ExitCode::RuntimeFailure, "outputs", s.message());
  }

  if (images_skipped > 0)
    warnings.push_back("outputs.frames: " + std::to_string(images_skipped) +
                       " image(s) not written: no OpenGL context: " + images.why());

  // ---- the report ----
  Hasher state_hash;
  ojson bodies = ojson::array();
  int resting = 0;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    ojson b = {{"name", scene.bodies[i].name}, {"spawned", bool(spawned[i])}};
    if (spawned[i]) {
      const BodyState s = world.state(ids[i]);
      state_hash.str(scene.bodies[i].name);
      state_hash.pod(s.position);
      state_hash.pod(s.orientation.coeffs());
      state_hash.pod(s.linear_velocity);
      state_hash.pod(s.angular_velocity);
      const bool rest = s.linear_velocity.norm() < 0.05f && s.angular_velocity.norm() < 0.05f;
      resting += rest;
      b["position_m"] = vec_json(s.position);
      b["orientation_wxyz"] = ojson::array({s.orientation.w(), s.orientation.x(), s.orientation.y(), s.orientation.z()});
      b["linear_velocity_m_s"] = vec_json(s.linear_velocity);
      b["angular_velocity_rad_s"] = vec_json(s.angular_velocity);
      b["at_rest"] = rest;
    }
    bodies.push_back(b);
  }
  state_hash.pod(hf.hash());
  if (manager) state_hash.pod(manager->state_hash());

  const double med = median(frame_ms);
  const double mx = frame_ms.empty() ? 0 : *std::max_element(frame_ms.begin(), frame_ms.end());
  ojson& r = res.report;
  r["sandpatch_version"] = SANDPATCH_VERSION;
  r["command"] = opt.command_line;
  r["scene"] = {{"name", scene.name}, {"file", scene.source_path}, {"hash", scene.hash}};
  r["backend"] = backend;
  r["threads"] = threads;
  r["dt_s"] = dt;
  r["substeps"] = sim.substeps;
  r["frame_count"] = frames;
  r["simulated_s"] = double(frames) * dt;
  r["wall_s"] = wall_s;
  r["real_time_factor"] = wall_s > 0 ? double(frames) * dt / wall_s : 0.0;
  r["stages"] = profile.to_json();
  // Stutter (issue 5): the longest frame in which a patch was promoted, uploaded or demoted,
  // against the median frame of the run.
  double conv_max = 0;
  int conv_frames = 0;
  for (std::size_t k = 0; k < frame_ms.size(); ++k)
    if (conversion_frame[k]) conv_max = std::max(conv_max, frame_ms[k]), ++conv_frames;
  r["frames"] = {{"median_ms", med},
                 {"max_ms", mx},
                 {"max_over_median", med > 0 ? mx / med : 0.0},
                 {"conversion_frames", conv_frames},
                 {"conversion_max_ms", conv_max},
                 {"conversion_max_over_median", med > 0 ? conv_max / med : 0.0}};
  r["counts"] = {{"bodies", scene.bodies.size()},
                 {"bodies_spawned", std::count(spawned.begin(), spawned.end(), true)},
                 {"bodies_at_rest", resting},
                 {"terrain_samples", std::int64_t(hf.samples_x()) * hf.samples_z()},
                 {"terrain_tiles", world.terrain_tile_count()},
                 {"peak_granules", peak_granules},
                 {"patches_live_at_end", live_patches}};
  if (manager) {
    const nlohmann::ordered_json manager_report = manager->report();
    for (const auto& [key, value] : manager_report.items()) r[key] = value;
  }
  r["terrain"] = {{"samples_x", hf.samples_x()},
                  {"samples_z", hf.samples_z()},
                  {"spacing_m", hf.spacing()},
                  {"origin_m", ojson::array({hf.origin_x(), hf.origin_y(), hf.origin_z()})},
                  {"min_height_m", hf.origin_y() + hf.min_height()},
                  {"max_height_m", hf.origin_y() + hf.max_height()},
                  {"hash", Hasher::to_hex(hf.hash())}};
  r["bodies"] = bodies;
  r["outputs"] = written;
  r["warnings"] = warnings;
  r["final_state_hash"] = state_hash.hex();

  if (scene.outputs.report) {
    const fs::path rp = out_dir / "report.json";
    if (Status s = write_atomic(rp, r.dump(2) + "\n"); !s) return fail(ExitCode::RuntimeFailure, "report", s.message());
    res.report_path = rp.string();
  }
  return res;
}

}  // namespace sandpatch
