// `sandpatch run`: a scene advanced headless at its fixed step, frame by frame, through the
// World (manager/world.hpp: the named, timed stages), its outputs written between frames and
// the run report at the end.
#pragma once

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "common/error.hpp"
#include "manager/run_outputs.hpp"
#include "manager/terrain_manager.hpp"
#include "scene/scene.hpp"

namespace sandpatch {

// One frame of a run, handed to RunOptions::on_frame at the end of the frame.
struct FrameSample {
  long long frame = 0;        // index of the frame, 0-based
  double time_s = 0;          // s, simulated time at the END of the frame ((frame + 1) × dt)
  double frame_ms = 0;        // ms wall, the frame's World::step (as the report's frames.median_ms counts it; outputs not included)
  double dem_ms = 0;          // ms wall, this frame's Dem stage (0 when no patch simulated)
  int patches_filling = 0;    // slots promoted and still uploading granules
  int patches_active = 0;     // slots filled and simulating
  int patches_asleep = 0;     // slots filled and asleep (DEM stopped)
  int granules = 0;           // live granules over all patches
  int queued_requests = 0;    // patch requests waiting for a free slot
  std::int64_t pool_bytes = 0;  // bytes, the pool's fixed DEM capacity (TerrainManager::pool_bytes)
};

struct RunOptions {
  std::string out_dir;        // "" = out/<scene name> under the current directory
  double seconds = -1;        // > 0 overrides simulation.duration (s)
  long long frames = -1;      // > 0 overrides the duration as a frame count
  std::string backend;        // "" = the scene's; "cpu" | "gl"
  int threads = -1;           // >= 0 overrides simulation.threads (0 = all hardware threads)
  // Overrides simulation.frame_budget_ms (ms > 0; infinity = no budget).
  std::optional<double> frame_budget_ms;
  // Overrides simulation.sleep.regions.
  std::optional<bool> sleep_regions;
  std::optional<bool> travel;  // overrides simulation.lod.travel
  ProgressStyle progress = ProgressStyle::Auto;  // Auto: a bar on a terminal, plain lines otherwise
  std::string command_line;   // recorded in the report
  std::string final_image;    // when set: after the last frame, render this PNG (`sandpatch render`)
  std::string final_camera;   // camera for final_image ("" = the scene's first, or a default view)
  std::string video;          // when set: a video of the scene's first camera piped to ffmpeg (run_outputs.hpp VideoWriter)
  double video_fps = knobs::kVideoFps.def;  // video frames per simulated second, in (0, 1 / dt] (knobs::kVideoFps)
  // When set: the run's time series to this file (and its stem + "_patches.csv"), instead of
  // the scene's outputs.csv (relative to the output directory). RunCsv, docs/cli.md "CSV".
  std::string csv;
  // Images and video also draw the bodies' particle shells (FrameWriter::set_show_shells).
  bool show_shells = false;
  // Called at the end of every frame of the frame loop (after its frame time is measured,
  // so the callback's own time is not in frame_ms; it is in the run's wall_s).
  std::function<void(const FrameSample&)> on_frame;
};

struct RunResult {
  ExitCode code = ExitCode::Ok;
  std::string stage;           // the stage that failed (code != Ok)
  std::string message;         // what went wrong, one error a line
  std::string report_path;     // written report ("" if none)
  nlohmann::ordered_json report;
};

// Runs `scene` to the end. Bad input found late (terrain file contents, bodies below the
// bedrock, an unwritable output directory) returns BadInput before the first frame and
// writes nothing.
RunResult run_scene(const SceneDef& scene, const RunOptions& options);

}  // namespace sandpatch
