// `sandpatch run`: a scene made into a World (manager/scene_world.hpp), stepped frame by
// frame at its fixed step, its outputs written between frames, the report at the end.
#include "manager/run.hpp"

#include <omp.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>

#include "common/hash.hpp"
#include "heightfield/io.hpp"
#include "manager/profile.hpp"
#include "manager/run_outputs.hpp"
#include "manager/scene_world.hpp"
#include "manager/world.hpp"

namespace fs = std::filesystem;

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;
using ojson = nlohmann::ordered_json;

}  // namespace

RunResult run_scene(const SceneDef& scene, const RunOptions& opt) {
  // The options that override a scene's settings: the scene as if it said so (its hash in the
  // report follows).
  if (opt.frame_budget_ms || opt.travel || opt.sleep_regions) {
    if (opt.frame_budget_ms && !(*opt.frame_budget_ms > 0)) {
      RunResult r;
      r.code = ExitCode::BadInput;
      r.stage = "options";
      r.message = "--frame-budget " + format_number(*opt.frame_budget_ms) + ": must be a number of ms > 0, or off";
      return r;
    }
    SceneDef s = scene;
    if (opt.frame_budget_ms) s.terrain.frame_budget_ms = opt.frame_budget_ms;
    if (opt.travel) s.terrain.lod_travel = *opt.travel;
    if (opt.sleep_regions) s.terrain.sleep_regions = *opt.sleep_regions;
    RunOptions o = opt;
    o.frame_budget_ms.reset();
    o.travel.reset();
    o.sleep_regions.reset();
    return run_scene(s, o);
  }
  RunResult res;
  auto fail = [&](ExitCode code, const std::string& stage, const std::string& msg) {
    res.code = code;
    res.stage = stage;
    res.message = msg;
    return res;
  };
  const SceneSimulationDef& sim = scene.simulation;

  // ---- everything that can be refused is checked before the first frame ----
  if (!opt.backend.empty() && opt.backend != "cpu" && opt.backend != "gl")
    return fail(ExitCode::BadInput, "options", "--backend " + opt.backend + ": allowed values are cpu, gl");
  if (!opt.final_camera.empty() && !scene.find_camera(opt.final_camera))
    return fail(ExitCode::BadInput, "options", "--camera " + opt.final_camera + ": the scene has no such camera");
  const std::string backend = opt.backend.empty() ? scene.terrain.backend : opt.backend;
  const int threads_req = opt.threads >= 0 ? opt.threads : scene.terrain.threads;
  const int threads = threads_req > 0 ? threads_req : omp_get_num_procs();
  omp_set_num_threads(threads);

  const double dt = sim.dt;
  // The number of fixed steps: --frames, or --seconds / dt, or the scene's duration / dt; a
  // non-finite --seconds, or more than kMaxRunFrames steps, is refused.
  if (opt.frames <= 0 && !std::isfinite(opt.seconds))
    return fail(ExitCode::BadInput, "options", "--seconds " + format_number(opt.seconds) + ": must be a finite number > 0");
  const double steps = opt.frames > 0 ? double(opt.frames) : std::ceil((opt.seconds > 0 ? opt.seconds : sim.duration) / dt - 1e-9);
  if (!(steps <= kMaxRunFrames))
    return fail(ExitCode::BadInput, "options",
                (opt.frames > 0 ? "--frames " + std::to_string(opt.frames) : "--seconds " + format_number(opt.seconds)) +
                    ": " + format_number(steps) + " steps of dt = " + format_number(dt) + " s; at most " +
                    format_number(kMaxRunFrames) + " steps");
  const long long frames = std::max(1LL, (long long)steps);

  // The video: a camera to film, a frame rate the steps can give, ffmpeg to encode.
  if (!opt.video.empty()) {
    if (scene.cameras.empty())
      return fail(ExitCode::BadInput, "options", "--video " + opt.video + ": the scene has no camera to film");
    if (!(knobs::kVideoFps.allows(opt.video_fps) && opt.video_fps <= 1.0 / dt * (1 + 1e-9)))
      return fail(ExitCode::BadInput, "options", "--video-fps " + format_number(opt.video_fps) + ": must be in " +
                                                      knobs::describe_range(knobs::kVideoFps) + " and at most 1 / dt = " +
                                                      format_number(1.0 / dt) + " frames per simulated second");
    if (Status s = VideoWriter::available(); !s) return fail(ExitCode::BadInput, "options", "--video " + opt.video + ": " + s.message());
  }
  std::string failed_part;
  // Start-up: the tiles a run settles (seconds on a first run; read back from the tile cache
  // later) print their progress as the frames do.
  ProgressPrinter progress(opt.progress, frames, dt);
  auto made = make_world(scene, threads, backend, &failed_part, true, [&](const std::string& what, double done, double max, double wall) {
    progress.note(what, done / max, wall);
  });
  if (!made) return fail(ExitCode::BadInput, failed_part, made.message());
  World& world = **made;
  const Heightfield& hf = world.heightfield();
  TerrainManager* manager = world.manager();

  const fs::path out_dir = opt.out_dir.empty() ? fs::path("out") / scene.name : fs::path(opt.out_dir);
  {
    std::error_code ec;
    fs::create_directories(out_dir, ec);
    if (ec || !fs::is_directory(out_dir))
      return fail(ExitCode::BadInput, "outputs", out_dir.string() + ": cannot create output directory" +
                                                     (ec ? ": " + ec.message() : ""));
  }

  // ---- the frame loop: World::step, then the scene's outputs (not part of the frame time) ----
  std::vector<std::string> warnings;
  std::vector<std::size_t> next_export(scene.outputs.heightfields.size(), 0);
  std::vector<std::size_t> next_frame(scene.outputs.frames.size(), 0);
  FrameWriter images(world);
  images.set_show_shells(opt.show_shells);
  std::size_t images_skipped = 0;
  std::vector<std::string> written;
  VideoWriter video;
  long long video_frames = 0;  // video frame k shows simulated time k / video_fps

  // Output patterns may name folders ("hf/{frame}.{ext}"): made when first written to.
  auto make_parent = [&](const fs::path& p) -> Status {
    std::error_code ec;
    fs::create_directories(p.parent_path(), ec);
    if (ec || !fs::is_directory(p.parent_path()))
      return Error{p.string(), "", "", "cannot create the output folder " + p.parent_path().string(), ec ? ec.message() : ""};
    return Ok{};
  };
  auto export_heightfield = [&](const HeightfieldOutputDef& o, long long frame, double t) -> Status {
    const fs::path p = out_dir / expand_pattern(o.file, frame, t, format_ext(o.format));
    if (Status made_dir = make_parent(p); !made_dir) return made_dir;
    Status s = Ok{};
    switch (o.format) {
      case HeightfieldFormat::Png16: s = save_png16(p.string(), hf); break;
      case HeightfieldFormat::RawF32: s = save_raw_f32(p.string(), hf); break;
      case HeightfieldFormat::EsriAscii: s = save_esri_ascii(p.string(), hf); break;
    }
    if (s) written.push_back(p.string());
    return s;
  };
  // The images and heightfields due at simulated time t, the state after `frame` frames (an
  // output at time 0 is the state before the first frame).
  auto write_outputs = [&](long long frame, double t) -> Status {
    auto timer = world.profile().time(Stage::Outputs);
    if (Status s = images.heightfield_changed(world.take_dirty_regions()); !s) return s;
    for (std::size_t k = 0; k < scene.outputs.frames.size(); ++k) {
      const FrameOutputDef& o = scene.outputs.frames[k];
      bool due = frame > 0 && o.every_k_frames > 0 && frame % o.every_k_frames == 0;
      while (next_frame[k] < o.times.size() && o.times[next_frame[k]] <= t + 1e-9) {
        due = true;
        ++next_frame[k];
      }
      if (!due) continue;
      const CameraDef* cam = scene.find_camera(o.camera);
      const fs::path p = out_dir / expand_pattern(o.file, frame, t, "png", o.camera);
      if (Status made_dir = make_parent(p); !made_dir) return made_dir;
      if (Status s = images.write(camera_at(*cam, t), p.string()); !s) return s;
      if (images.unavailable()) ++images_skipped;
      else written.push_back(p.string());
    }
    while (!opt.video.empty() && double(video_frames) / opt.video_fps <= t + 1e-9) {
      const render::CameraView cam = camera_at(scene.cameras.front(), t);
      auto img = images.render(cam);
      if (!img) return img.errors();
      if (images.unavailable()) return Error{opt.video, "", "", "no image for the video: " + images.why()};
      if (!video.is_open())
        if (Status s = video.open(opt.video, cam.width, cam.height, opt.video_fps); !s) return s;
      if (Status s = video.add(img.value()); !s) return s;
      ++video_frames;
    }
    for (std::size_t k = 0; k < scene.outputs.heightfields.size(); ++k) {
      const auto& o = scene.outputs.heightfields[k];
      for (; next_export[k] < o.times.size() && o.times[next_export[k]] <= t + 1e-9; ++next_export[k])
        if (Status s = export_heightfield(o, frame, t); !s) return s;
    }
    return Ok{};
  };

  RunCsv csv;  // the time series: kept as .part files until the run ends well
  if (!opt.csv.empty() || !scene.outputs.csv.empty()) {
    const fs::path p = !opt.csv.empty() ? fs::path(opt.csv) : out_dir / scene.outputs.csv;
    if (Status s = csv.open(p); !s) return fail(ExitCode::BadInput, "outputs", s.message());
  }
  // Start-up's last part: the patches bodies need at once are made before the first frame
  // (World::prepare; report.json `prepare_ms`), as a game would while loading.
  if (Status s = world.prepare(dt); !s) return fail(ExitCode::RuntimeFailure, "prepare", s.message());
  const auto t_start = Clock::now();
  if (Status s = write_outputs(0, 0.0); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
  double frames_wall_s = 0;  // s, the frames alone (World::step), without the outputs written between them
  for (long long frame = 0; frame < frames; ++frame) {
    const double t = double(frame) * dt;  // s, simulated time at the start of this frame
    if (sim.scale_by_distance)
      world.set_camera(camera_at(*scene.find_camera(sim.scale_by_distance->camera), t).position.cast<double>());
    const double dem_ms_before = world.profile().timer(Stage::Dem).total_ms;
    if (Status st = world.step(dt, sim.substeps); !st)
      return fail(ExitCode::RuntimeFailure, world.failed_stage(), st.message());
    frames_wall_s += world.last_frame().wall_ms * 1e-3;
    if (Status s = write_outputs(frame + 1, world.time()); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
    if (Status s = csv.frame(world, world.time()); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
    if (opt.on_frame) {
      FrameSample fs;
      fs.frame = frame;
      fs.time_s = world.time();
      fs.frame_ms = world.last_frame().wall_ms;
      fs.dem_ms = world.profile().timer(Stage::Dem).total_ms - dem_ms_before;
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
  const double t_end = world.time();
  if (!opt.final_image.empty()) {
    auto timer = world.profile().time(Stage::Outputs);
    render::CameraView view;
    if (const CameraDef* c = opt.final_camera.empty() ? (scene.cameras.empty() ? nullptr : &scene.cameras.front())
                                                      : scene.find_camera(opt.final_camera)) {
      view = camera_at(*c, t_end);
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
  // The run ends by converting every live patch back, so the final terrain holds its changes.
  const int live_patches = manager ? manager->active_patches() : 0;
  if (Status st = world.demote_all(); !st) return fail(ExitCode::RuntimeFailure, "demotion", st.message());
  {
    auto timer = world.profile().time(Stage::Outputs);
    if (Status s = images.heightfield_changed(world.take_dirty_regions()); !s)
      return fail(ExitCode::RuntimeFailure, "outputs", s.message());
    for (const auto& o : scene.outputs.heightfields)
      if (o.at_end)
        if (Status s = export_heightfield(o, frames, t_end); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
  }
  if (video.is_open()) {
    if (Status s = video.close(); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
    written.push_back(opt.video);
  }
  if (csv.is_open()) {
    if (Status s = csv.close(); !s) return fail(ExitCode::RuntimeFailure, "outputs", s.message());
    written.push_back(csv.bodies_file().string());
    written.push_back(RunCsv::patches_path(csv.bodies_file()).string());
    written.push_back(RunCsv::frames_path(csv.bodies_file()).string());
  }
  if (manager)
    if (const ojson mr = manager->report(); mr.contains("planned_paths"))
      for (const auto& p : mr["planned_paths"])
        if (p["too_big_frames"].get<long long>() > 0)
          warnings.push_back("bodies." + p["body"].get<std::string>() + ": the stretch of its keyframed path that works the ground needs about " +
                             std::to_string(p["granules_predicted"].get<int>()) + " granules, more than a slot holds (simulation.pool.granules_per_slot = " +
                             std::to_string(p["granules_per_slot"].get<int>()) +
                             "): it was followed by patches asked for ahead of it instead, and what it carried fell where it left a patch");
  if (manager)
    if (const ojson mr = manager->report(); mr.contains("tools_too_fast"))
      for (const auto& f : mr["tools_too_fast"])
        warnings.push_back("bodies." + f["body"].get<std::string>() + ": moved into a patch at up to " +
                           format_number(f["max_speed_m_s"].get<double>()) + " m/s in " +
                           std::to_string(f["frames"].get<long long>()) + " frame(s), faster than its granules can be stopped (" +
                           format_number(f["limit_m_s"].get<double>()) +
                           " m/s: 2 granule radii of overlap at the material's stiffness): granules may have passed through it");
  if (images_skipped > 0)
    warnings.push_back("outputs.frames: " + std::to_string(images_skipped) +
                       " image(s) not written: no OpenGL context: " + images.why());

  // ---- the report: the run's own fields, then the World's sections (one schema for all callers) ----
  ojson& r = res.report;
  r["sandpatch_version"] = SANDPATCH_VERSION;
  r["command"] = opt.command_line;
  r["scene"] = {{"name", scene.name}, {"file", scene.source_path}, {"hash", scene.hash}};
  r["backend"] = backend;
  r["threads"] = threads;
  r["dt_s"] = dt;
  r["substeps"] = sim.substeps;
  r["frame_count"] = frames;
  r["wall_s"] = wall_s;
  r["real_time_factor"] = wall_s > 0 ? t_end / wall_s : 0.0;
  // what a game's loop pays for the terrain: the frames without the images, heightfields and
  // CSV rows a scene run writes between them
  r["frames_wall_s"] = frames_wall_s;
  r["frames_real_time_factor"] = frames_wall_s > 0 ? t_end / frames_wall_s : 0.0;
  const ojson w = world.report();
  for (const auto& [key, value] : w.items()) r[key] = value;
  r["counts"]["patches_live_at_end"] = live_patches;
  r["outputs"] = written;
  // World's (bodies that outran the patches; the same for API users), then the run's own
  std::vector<std::string> all = w["warnings"].get<std::vector<std::string>>();
  all.insert(all.end(), warnings.begin(), warnings.end());
  r["warnings"] = all;
  r.erase("final_state_hash");
  r["final_state_hash"] = w["final_state_hash"];  // last, where readers look for it

  if (scene.outputs.report) {
    const fs::path rp = out_dir / "report.json";
    if (Status s = write_atomic(rp, r.dump(2) + "\n"); !s) return fail(ExitCode::RuntimeFailure, "report", s.message());
    res.report_path = rp.string();
  }
  return res;
}

}  // namespace sandpatch
