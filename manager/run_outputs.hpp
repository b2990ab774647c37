// What `sandpatch run` writes besides the report: images of the scene (one GL context, one
// renderer), file names from output patterns, atomic writes, the progress line.
#pragma once

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "gl/context.hpp"
#include "heightfield/heightfield.hpp"
#include "heightfield/io.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/world.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"

namespace sandpatch {

enum class ProgressStyle { Auto, Bar, Lines, None };

// `pattern` with {frame} (6 digits), {time_ms} (8 digits), {ext} and {camera} replaced.
std::string expand_pattern(std::string pattern, long long frame, double t, const char* ext, const std::string& camera = "");
const char* format_ext(HeightfieldFormat f);
// Writes `text` to `path` atomically (temporary file + rename): nothing is written half.
Status write_atomic(const std::filesystem::path& path, const std::string& text);

// Progress on stderr: a bar on a terminal, plain lines every 10 % otherwise (logs and CI).
class ProgressPrinter {
 public:
  ProgressPrinter(ProgressStyle style, long long frames, double dt);
  void update(long long frame, double wall_s, bool final = false);
  // A start-up step: `what`, done (a fraction, an upper bound's) and wall seconds so far, with
  // an estimate of what is left; a line every 10 % (a bar on a terminal).
  void note(const std::string& what, double fraction, double wall_s);

 private:
  ProgressStyle style_;
  long long frames_;
  double dt_;
  double last_wall_ = -1;
  int next_pct_ = 0;
  std::string note_what_;
  int note_pct_ = 0;
};

// The world's bodies as the renderer draws them, in entry order: the live ones (shape from
// BulletWorld::definition, pose from BulletWorld::state) and those scheduled at or before the
// world's time but not spawned yet (a body due at t = 0 enters in the first step; the picture
// at t = 0 shows it at its starting pose). Albedo: render::body_palette(entry index).
std::vector<render::BodyInstance> body_instances(const World& world);

// Images of the run: one GL context and one scene renderer, made on the first image. With
// the GL backend the renderer shares the simulation's context and draws the particles
// straight from the simulation's buffers; otherwise it makes its own context. Every image
// shows the terrain, the live patches' granules (ready patches' footprints cut out of the
// second terrain pass) and the world's bodies.
class FrameWriter {
 public:
  explicit FrameWriter(const World& world)
      : world_(world), hf_(world.heightfield()), manager_(world.manager()) {}
  ~FrameWriter();
  FrameWriter(const FrameWriter&) = delete;
  FrameWriter& operator=(const FrameWriter&) = delete;
  // No GL context could be made: images are skipped (why() says why).
  bool unavailable() const { return !why_.empty(); }
  const std::string& why() const { return why_; }
  // Re-uploads the heightfield regions that changed (in the renderer's own context).
  Status heightfield_changed(const std::vector<GridRegion>& regions);
  // Renders `view` (terrain, the live patches' granules, the bodies) into `path`.
  Status write(const render::CameraView& view, const std::string& path, const render::FrameFlags& flags = {});
  // The same frame as an image (tests, video). Errors as write(); an empty image when no
  // context could be made (unavailable()).
  Result<render::Image> render(const render::CameraView& view, const render::FrameFlags& flags = {});
  // The renderer (null before the first image or when unavailable).
  render::SceneRenderer* renderer() { return renderer_.get(); }
  // A debug overlay: the spheres of the bodies' particle shells in the live patches, drawn as
  // small magenta spheres over the bodies (off by default; `sandpatch run|render --shells`).
  void set_show_shells(bool on) { show_shells_ = on; }

 private:
  Status prepare();
  Status set_particles_cpu(std::unique_ptr<render::ParticleBuffer>& buf);
  Status set_particles_gpu();

  const World& world_;
  const Heightfield& hf_;
  const TerrainManager* manager_;
  std::unique_ptr<gl::Context> ctx_;    // own context (CPU backend)
  gl::Context* context_ = nullptr;      // the context in use (own or the manager's)
  std::unique_ptr<render::SceneRenderer> renderer_;
  bool show_shells_ = false;
  std::string why_;
};

// A video piped to ffmpeg (`sandpatch run --video FILE`): RGBA frames of one size in, the
// format from the file's extension (ffmpeg's choice of codec), yuv420p, odd sizes padded to even.
class VideoWriter {
 public:
  VideoWriter() = default;
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;
  // Ok when an executable `ffmpeg` is on PATH; otherwise says so (and which package has it).
  static Status available();
  // Starts ffmpeg writing `path` (overwritten) at `fps` frames per second of video.
  Status open(const std::string& path, int width, int height, double fps);
  bool is_open() const { return pipe_ != nullptr; }
  // One frame; its size must be the one given to open(). Errors name the path.
  Status add(const render::Image& img);
  // Waits for ffmpeg; its exit status other than 0 is an error naming the path.
  Status close();

 private:
  std::FILE* pipe_ = nullptr;
  std::string path_;
  int width_ = 0, height_ = 0;
};

// The run's time series (`sandpatch run --csv FILE`, scene outputs.csv; docs/cli.md "CSV"):
// FILE gets one row per frame per body, FILE's stem + "_patches.csv" one row per frame per
// live patch, its stem + "_frames.csv" one row per frame (its wall time, each stage's, the
// budget and the terrain manager's work in it). All are written as the run goes into
// temporary files beside them, renamed when the run ends well (close()); a run that fails or
// is refused leaves none.
class RunCsv {
 public:
  RunCsv() = default;
  ~RunCsv();  // removes the temporary files unless close() renamed them
  RunCsv(const RunCsv&) = delete;
  RunCsv& operator=(const RunCsv&) = delete;
  // The patch file beside a body file: "a/bodies.csv" -> "a/bodies_patches.csv".
  static std::filesystem::path patches_path(const std::filesystem::path& bodies);
  // The frame file beside a body file: "a/bodies.csv" -> "a/bodies_frames.csv".
  static std::filesystem::path frames_path(const std::filesystem::path& bodies);
  static const char* body_header();   // the body file's first line (without the newline)
  static const char* patch_header();
  static const char* frame_header();
  // Creates the temporary files and writes the headers; errors name the path.
  Status open(const std::filesystem::path& bodies);
  bool is_open() const { return bodies_ != nullptr; }
  // The rows of the state after a frame at simulated time t (s).
  Status frame(const World& world, double t);
  // Flushes and renames them into place.
  Status close();
  const std::filesystem::path& bodies_file() const { return path_; }

 private:
  void discard();
  std::filesystem::path path_, patches_, frames_;
  std::FILE* bodies_ = nullptr;
  std::FILE* patch_rows_ = nullptr;
  std::FILE* frame_rows_ = nullptr;
};

}  // namespace sandpatch
