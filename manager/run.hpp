// `sandpatch run`: a scene advanced headless at its fixed step, frame by frame, as a short
// list of named stages (profile.hpp), with the run report written at the end.
//
// What a run simulates today: bodies in Bullet colliding with the heightfield (and each
// other). The granule patches (issues 3-5) join the frame as the Lod / Activation / Dem /
// Sleep / Demotion stages when the manager lands; until then the report says so in its
// warnings and never reports stages that did not run.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

#include "common/error.hpp"
#include "scene/scene.hpp"

namespace sandpatch {

enum class ProgressStyle { Auto, Bar, Lines, None };

struct RunOptions {
  std::string out_dir;        // "" = out/<scene name> under the current directory
  double seconds = -1;        // > 0 overrides simulation.duration (s)
  long long frames = -1;      // > 0 overrides the duration as a frame count
  std::string backend;        // "" = the scene's; "cpu" | "gl"
  int threads = -1;           // >= 0 overrides simulation.threads (0 = all hardware threads)
  ProgressStyle progress = ProgressStyle::Auto;  // Auto: a bar on a terminal, plain lines otherwise
  std::string command_line;   // recorded in the report
  std::string final_image;    // when set: after the last frame, render this PNG (`sandpatch render`)
  std::string final_camera;   // camera for final_image ("" = the scene's first, or a default view)
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
