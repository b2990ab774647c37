// `sandpatch view [SCENE]`: the scene run live in a window (docs/cli.md "view").
//
// The scene becomes a World (manager/scene_world.hpp) stepped once per displayed frame at the
// scene's dt, paced to real time (times the speed) unless the simulation is slower. Each frame
// is drawn offscreen by the same renderer and FrameWriter `sandpatch run` uses (headless EGL
// context), the overlay is drawn into that image on the CPU (render/overlay.hpp), and the
// image is copied into the window (a GLFW window with its own GL context: texture upload and
// glBlitFramebuffer). docs/rendering.md "The viewer" says why.
#pragma once

#include <string>

namespace sandpatch {

struct ViewArgs {
  std::string scene;         // scene file; "" = the embedded default
  long long frames = -1;     // > 0: advance this many frames, then exit
  std::string screenshot;    // with frames: the window's contents after the last frame (PNG)
  std::string size;          // "WxH" (pixels); "" = 1280x720
  std::string camera;        // the scene camera to start at ("" = its first)
  std::string backend;       // "" = the scene's; "cpu" | "gl"
  int threads = -1;          // >= 0 overrides simulation.threads (0 = all)
  std::string frame_budget;  // ms or "off" (overrides simulation.frame_budget_ms); "" = the scene's
  // Scripted input, fed to the same handlers as the keyboard and mouse, one token per drawn
  // frame from the second on; the viewer exits after the last token's frame. Tokens, comma
  // separated: a key the viewer knows (" " may be written space), rotate:DX:DY and pan:DX:DY
  // (a drag of that many pixels), zoom:N (wheel notches). "" = none.
  std::string keys;
  std::string quality;       // "high" (default) | "low": half resolution, no ambient occlusion, 512² shadow map
};

// Exit code: 0 ok, 1 runtime failure (a step failed, no window could be made), 2 bad input
// (a bad option or scene, no display). Messages on stderr; the summary (average frames per
// second) on stdout.
int run_view(const ViewArgs& args);

}  // namespace sandpatch
