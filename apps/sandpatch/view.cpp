// `sandpatch view` (apps/sandpatch/view.hpp). Built with GLFW when the configure step finds it
// (apps/sandpatch/CMakeLists.txt); without it the command says so and what to install.
#include "apps/sandpatch/view.hpp"

#include <cstdio>

#ifndef SANDPATCH_HAVE_GLFW

namespace sandpatch {

int run_view(const ViewArgs&) {
  std::fprintf(stderr, "sandpatch view: this sandpatch was built without GLFW; install libglfw3-dev "
                       "(scripts/install-deps.sh does) and configure again\n");
  return 1;
}

}  // namespace sandpatch

#else

#include <EGL/egl.h>
#include <GL/glcorearb.h>
#include <GLFW/glfw3.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdarg>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <limits>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "common/error.hpp"
#include "manager/run_outputs.hpp"
#include "manager/scene_world.hpp"
#include "manager/world.hpp"
#include "render/orbit_camera.hpp"
#include "render/overlay.hpp"
#include "scene/scene.hpp"

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int bad(const std::string& msg) {
  std::fprintf(stderr, "sandpatch view: %s\n", msg.c_str());
  return static_cast<int>(ExitCode::BadInput);
}
int failed(const std::string& msg) {
  std::fprintf(stderr, "sandpatch view: %s\n", msg.c_str());
  return static_cast<int>(ExitCode::RuntimeFailure);
}

// "WxH" with W and H integers in [16, 8192]; false otherwise.
bool parse_size(const std::string& s, int& w, int& h) {
  const std::size_t x = s.find_first_of("xX");
  if (x == std::string::npos) return false;
  auto number = [](const std::string& t, int& out) {
    if (t.empty() || t.size() > 5 || t.find_first_not_of("0123456789") != std::string::npos) return false;
    out = std::stoi(t);
    return out >= 16 && out <= 8192;
  };
  return number(s.substr(0, x), w) && number(s.substr(x + 1), h);
}

// The last message GLFW reported (its error callback), for the errors below.
std::string g_glfw_error;
void on_glfw_error(int code, const char* what) {
  g_glfw_error = std::string(what ? what : "") + " (GLFW error 0x" + [&] {
    char b[16];
    std::snprintf(b, sizeof b, "%x", code);
    return std::string(b);
  }() + ")";
}

// No EGL context current on this thread (the renderer's or the simulation's): GLVND lets a
// thread have one API's context current at a time, and the window's is GLX.
void release_egl() {
  if (eglGetCurrentContext() != EGL_NO_CONTEXT)
    eglMakeCurrent(eglGetCurrentDisplay(), EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
}

// What the keys and the mouse change (GLFW callbacks write it through the window's user pointer).
struct Controls {
  bool paused = false;
  bool step_once = false;   // `.` / `n`: one frame, then paused
  double speed = 1;         // real-time pacing × speed, in [1/64, 64]
  bool reset_camera = false;
  bool quit = false;
  bool dirty = true;        // the picture must be drawn again (camera moved, window resized, a key)
  render::OrbitCamera orbit;
  double fov_deg = 60;
  int fb_height = 720;
  bool left = false, right = false;
  double mouse_x = 0, mouse_y = 0;

  // What a drag with the left / right button and the wheel do (the callbacks and --keys).
  void drag_rotate(double dx, double dy) { orbit.rotate(dx, dy), dirty = true; }
  void drag_pan(double dx, double dy) { orbit.pan(dx, dy, fov_deg, fb_height), dirty = true; }
  void scroll(double notches) { orbit.zoom(notches), dirty = true; }

  void key(unsigned c) {
    switch (c) {
      case ' ': paused = !paused; break;
      case '.': case 'n': case 'N': paused = true, step_once = true; break;
      case '+': case '=': speed = std::min(speed * 2, 64.0); break;
      case '-': case '_': speed = std::max(speed / 2, 1.0 / 64); break;
      case 'r': case 'R': reset_camera = true; break;
      case 'q': case 'Q': quit = true; break;
      default: return;
    }
    dirty = true;
  }
};

// One --keys token: a key, or a drag / wheel motion.
struct ScriptToken {
  enum Kind { Key, Rotate, Pan, Zoom } kind = Key;
  unsigned key = 0;
  double a = 0, b = 0;
  std::string text;
  void apply(Controls& c) const {
    switch (kind) {
      case Key: c.key(key); break;
      case Rotate: c.drag_rotate(a, b); break;
      case Pan: c.drag_pan(a, b); break;
      case Zoom: c.scroll(a); break;
    }
  }
};

// Parses --keys; on error, the message names the token and what is allowed.
bool parse_keys(const std::string& s, std::vector<ScriptToken>& out, std::string& why) {
  const std::string known = " .nN+=-_rRqQ";
  std::size_t start = 0;
  while (start <= s.size()) {
    std::size_t end = s.find(',', start);
    if (end == std::string::npos) end = s.size();
    const std::string t = s.substr(start, end - start);
    start = end + 1;
    ScriptToken k;
    k.text = t;
    auto number = [&](const std::string& x, double& v) {
      char* e = nullptr;
      v = std::strtod(x.c_str(), &e);
      return !x.empty() && e && *e == '\0' && std::isfinite(v) && std::fabs(v) <= 1e6;
    };
    const std::size_t c1 = t.find(':');
    if (t == "space") {
      k.key = ' ';
    } else if (t.size() == 1 && known.find(t[0]) != std::string::npos) {
      k.key = static_cast<unsigned char>(t[0]);
    } else if (c1 != std::string::npos) {
      const std::string name = t.substr(0, c1), rest = t.substr(c1 + 1);
      const std::size_t c2 = rest.find(':');
      if ((name == "rotate" || name == "pan") && c2 != std::string::npos && number(rest.substr(0, c2), k.a) &&
          number(rest.substr(c2 + 1), k.b)) {
        k.kind = name == "rotate" ? ScriptToken::Rotate : ScriptToken::Pan;
      } else if (name == "zoom" && number(rest, k.a)) {
        k.kind = ScriptToken::Zoom;
      } else {
        why = "'" + t + "'";
        return false;
      }
    } else {
      why = "'" + t + "'";
      return false;
    }
    out.push_back(k);
  }
  return true;
}

Controls& controls(GLFWwindow* w) { return *static_cast<Controls*>(glfwGetWindowUserPointer(w)); }

void install_callbacks(GLFWwindow* win) {
  glfwSetCharCallback(win, [](GLFWwindow* w, unsigned c) { controls(w).key(c); });
  glfwSetKeyCallback(win, [](GLFWwindow* w, int key, int, int action, int) {
    if (action == GLFW_PRESS && key == GLFW_KEY_ESCAPE) controls(w).quit = true;
  });
  glfwSetMouseButtonCallback(win, [](GLFWwindow* w, int button, int action, int) {
    Controls& c = controls(w);
    const bool down = action == GLFW_PRESS;
    if (button == GLFW_MOUSE_BUTTON_LEFT) c.left = down;
    if (button == GLFW_MOUSE_BUTTON_RIGHT || button == GLFW_MOUSE_BUTTON_MIDDLE) c.right = down;
    glfwGetCursorPos(w, &c.mouse_x, &c.mouse_y);
  });
  glfwSetCursorPosCallback(win, [](GLFWwindow* w, double x, double y) {
    Controls& c = controls(w);
    const double dx = x - c.mouse_x, dy = y - c.mouse_y;
    c.mouse_x = x, c.mouse_y = y;
    if (c.left) c.drag_rotate(dx, dy);
    else if (c.right) c.drag_pan(dx, dy);
  });
  glfwSetScrollCallback(win, [](GLFWwindow* w, double, double dy) {
    controls(w).scroll(dy);
  });
  glfwSetFramebufferSizeCallback(win, [](GLFWwindow* w, int, int) { controls(w).dirty = true; });
}

// The window's side of presenting: the frame as a texture, blitted to the default framebuffer.
struct Presenter {
  GLuint tex = 0, fbo = 0;
  int tex_w = 0, tex_h = 0;

  // Draws `img` (top row first) into the window's back buffer; with `shot` set, reads the back
  // buffer back into it (the window's contents as shown). The window's context is current.
  void draw(const render::Image& img, int fb_w, int fb_h, render::Image* shot) {
    if (!tex) {
      glGenTextures(1, &tex);
      glGenFramebuffers(1, &fbo);
    }
    glBindTexture(GL_TEXTURE_2D, tex);
    if (img.width != tex_w || img.height != tex_h) {
      glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, img.width, img.height, 0, GL_RGBA, GL_UNSIGNED_BYTE, nullptr);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
      glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
      tex_w = img.width, tex_h = img.height;
    }
    glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
    glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, img.width, img.height, GL_RGBA, GL_UNSIGNED_BYTE, img.rgba.data());
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, tex, 0);
    glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    // Texture row 0 is the image's top row; the window's row 0 is its bottom: flip in the blit.
    // An image smaller than the window (--quality low) is scaled up to fill it.
    const bool scaled = img.width != fb_w || img.height != fb_h;
    glBlitFramebuffer(0, 0, img.width, img.height, 0, fb_h, scaled ? fb_w : img.width, scaled ? 0 : fb_h - img.height,
                      GL_COLOR_BUFFER_BIT, scaled ? GL_LINEAR : GL_NEAREST);
    if (shot) {
      glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
      glReadBuffer(GL_BACK);
      glPixelStorei(GL_PACK_ALIGNMENT, 1);
      std::vector<std::uint8_t> rows(std::size_t(fb_w) * fb_h * 4);
      glReadPixels(0, 0, fb_w, fb_h, GL_RGBA, GL_UNSIGNED_BYTE, rows.data());
      shot->width = fb_w, shot->height = fb_h;
      shot->rgba.resize(rows.size());
      const std::size_t row = std::size_t(fb_w) * 4;
      for (int y = 0; y < fb_h; ++y)
        std::copy_n(&rows[std::size_t(fb_h - 1 - y) * row], row, &shot->rgba[std::size_t(y) * row]);
      for (std::size_t k = 3; k < shot->rgba.size(); k += 4) shot->rgba[k] = 255;  // the window is opaque
    }
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  }
  void release() {
    if (fbo) glDeleteFramebuffers(1, &fbo);
    if (tex) glDeleteTextures(1, &tex);
    fbo = tex = 0;
  }
};

// Colours of the patch states in the overlay (outlines and their lines in the list).
constexpr render::Rgb kFilling{255, 214, 0}, kActive{255, 96, 48}, kAsleep{96, 170, 255}, kText{255, 255, 255};

// A patch's footprint outlined on the terrain: its region's edge, following the heightfield
// (lifted 3 cm), projected with the frame's camera.
void outline_patch(render::Image& img, render::SceneRenderer& r, const render::CameraView& view, const Heightfield& hf,
                   const GridRegion& g, render::Rgb color, int thickness) {
  if (g.empty()) return;
  const int i0 = std::clamp(g.i0, 0, hf.samples_x() - 1), j0 = std::clamp(g.j0, 0, hf.samples_z() - 1);
  const int i1 = std::clamp(g.i0 + g.ni - 1, 0, hf.samples_x() - 1), j1 = std::clamp(g.j0 + g.nj - 1, 0, hf.samples_z() - 1);
  auto world = [&](int i, int j) {
    return Eigen::Vector3d(hf.origin_x() + double(hf.spacing()) * i, hf.origin_y() + double(hf.height(i, j)) + 0.03,
                           hf.origin_z() + double(hf.spacing()) * j);
  };
  // Corner to corner, counter-clockwise, at most 48 pieces an edge.
  const int corners[5][2] = {{i0, j0}, {i1, j0}, {i1, j1}, {i0, j1}, {i0, j0}};
  for (int e = 0; e < 4; ++e) {
    const int ai = corners[e][0], aj = corners[e][1], bi = corners[e + 1][0], bj = corners[e + 1][1];
    const int n = std::max(std::abs(bi - ai), std::abs(bj - aj)), pieces = std::clamp(n, 1, 48);
    std::optional<render::SceneRenderer::Projected> prev;
    for (int s = 0; s <= pieces; ++s) {
      const int i = ai + (bi - ai) * s / pieces, j = aj + (bj - aj) * s / pieces;
      auto p = r.project(view, world(i, j));
      if (p && prev) render::draw_line(img, prev->pixel, p->pixel, color, thickness);
      prev = p;
    }
  }
}

struct Line {
  std::string text;
  render::Rgb color = kText;
};

// printf into a string (one overlay line; longer lines are cut at 255 characters).
__attribute__((format(printf, 1, 2))) std::string format(const char* fmt, ...) {
  char b[256];
  va_list args;
  va_start(args, fmt);
  std::vsnprintf(b, sizeof b, fmt, args);
  va_end(args);
  return b;
}

struct FrameStats {
  double step_ms = 0, render_ms = 0, present_ms = 0, frame_ms = 0;
  double budget_ms = 0;
  double fps = 0, rtf = 0;
};

// The overlay: patch outlines on the terrain, then a panel at the top left. Returns the panel
// (x, y, w, h), which the tests leave out of their comparison with `sandpatch run`'s frames.
std::array<int, 4> draw_overlay(render::Image& img, render::SceneRenderer* r, const render::CameraView& view,
                                const World& world, const SceneDef& scene, const Controls& ctl, const FrameStats& st) {
  const int scale = std::max(1, std::min(img.width / 640, img.height / 360));
  const TerrainManager* m = world.manager();
  const std::vector<TerrainManager::PatchInfo> patches = m ? m->patches() : std::vector<TerrainManager::PatchInfo>{};
  auto state_color = [](const TerrainManager::PatchInfo& p) { return !p.ready ? kFilling : p.asleep ? kAsleep : kActive; };
  if (r)
    for (const auto& p : patches) outline_patch(img, *r, view, world.heightfield(), p.region, state_color(p), scale + 1);

  std::vector<Line> lines;
  lines.push_back({format("sandpatch view: %s", scene.name.c_str()), kText});
  lines.push_back(
      {format("t %.3f s  frame %lld  speed x%g%s", world.time(), world.steps(), ctl.speed, ctl.paused ? "  paused" : ""),
       kText});
  if (std::isfinite(st.budget_ms)) lines.push_back({format("step %.1f ms  budget %.1f ms", st.step_ms, st.budget_ms), kText});
  else lines.push_back({format("step %.1f ms  budget off", st.step_ms), kText});
  lines.push_back({format("frame %.1f ms (render %.1f)  %.1f fps", st.frame_ms, st.render_ms, st.fps), kText});
  lines.push_back({format("real-time factor %.2fx", st.rtf), kText});
  if (m) {
    lines.push_back(
        {format("patches %zu  queued %d  granules %d", patches.size(), m->queued_requests(), m->granules()), kText});
    const std::size_t shown = std::min<std::size_t>(patches.size(), 8);
    for (std::size_t k = 0; k < shown; ++k) {
      const auto& p = patches[k];
      const char* state = !p.ready ? "filling" : p.asleep ? "asleep" : p.stepped ? "active" : "held";
      lines.push_back({format(" #%d %s %d granules", p.patch, state, p.granules), state_color(p)});
    }
    if (patches.size() > shown) lines.push_back({format(" +%zu more", patches.size() - shown), kText});
  } else {
    lines.push_back({format("patches off"), kText});
  }
  lines.push_back({format("drag turn  right-drag pan  wheel zoom"), kText});
  lines.push_back({format("space pause  n step  +/- speed  r reset  q quit"), kText});

  const int pad = 4 * scale, lh = render::line_height(scale);
  int w = 0;
  for (const auto& l : lines) w = std::max(w, render::text_width(l.text, scale));
  const std::array<int, 4> panel{8, 8, w + 2 * pad, int(lines.size()) * lh + 2 * pad};
  render::fill_rect(img, panel[0], panel[1], panel[2], panel[3], {0, 0, 0}, 0.6f);
  for (std::size_t k = 0; k < lines.size(); ++k)
    render::draw_text(img, panel[0] + pad, panel[1] + pad + int(k) * lh, lines[k].text, lines[k].color, scale);
  return panel;
}

// The camera the viewer starts at: the named or first scene camera, else a view of the whole
// terrain from above a corner (as `sandpatch render` uses).
render::CameraView start_view(const SceneDef& scene, const std::string& name, const Heightfield& hf) {
  if (const CameraDef* c = name.empty() ? (scene.cameras.empty() ? nullptr : &scene.cameras.front()) : scene.find_camera(name))
    return camera_at(*c, 0.0);
  render::CameraView v;
  const double cx = hf.origin_x() + 0.5 * hf.extent_x(), cz = hf.origin_z() + 0.5 * hf.extent_z();
  const double cy = hf.origin_y() + hf.max_height();
  v.position = {cx - 0.4 * hf.extent_x(), cy + 0.3 * hf.extent_x(), cz - 0.4 * hf.extent_z()};
  v.target = {cx, cy - 0.1 * hf.extent_x(), cz};
  return v;
}

}  // namespace

int run_view(const ViewArgs& a) {
  // ---- everything that can be refused, before a window opens ----
  int width = 1280, height = 720;
  if (!a.size.empty() && !parse_size(a.size, width, height))
    return bad("--size " + a.size + ": must be WxH, two integers in [16, 8192] pixels (e.g. 1280x720)");
  if (!a.screenshot.empty() && a.frames <= 0)
    return bad("--screenshot " + a.screenshot + ": needs --frames N (the screenshot is taken after frame N)");
  std::vector<ScriptToken> script;
  if (!a.keys.empty()) {
    std::string why;
    if (a.keys.size() > 100000 || !parse_keys(a.keys, script, why))
      return bad("--keys " + a.keys.substr(0, 200) + ": token " + (why.empty() ? "list too long" : why) +
                 " unknown: allowed are the keys space . n + = - _ r q, rotate:DX:DY, pan:DX:DY (pixels), zoom:N "
                 "(notches), comma separated, at most 100000 characters");
  }
  if (!a.quality.empty() && a.quality != "high" && a.quality != "low")
    return bad("--quality " + a.quality + ": allowed values are high, low");
  const bool low = a.quality == "low";
  if (a.frames > 0 && !(double(a.frames) <= kMaxRunFrames))
    return bad("--frames " + std::to_string(a.frames) + ": at most " + format_number(kMaxRunFrames));
  auto loaded = a.scene.empty() ? load_default_scene() : load_scene_file(a.scene);
  if (!loaded) {
    std::fprintf(stderr, "sandpatch view: %s: invalid scene (%zu error(s))\n%s\n",
                 a.scene.empty() ? "<embedded default>" : a.scene.c_str(), loaded.errors().size(), loaded.message().c_str());
    return static_cast<int>(ExitCode::BadInput);
  }
  SceneDef scene = *loaded;
  if (a.frame_budget == "off") {
    scene.terrain.frame_budget_ms = std::numeric_limits<double>::infinity();
  } else if (!a.frame_budget.empty()) {
    char* end = nullptr;
    const double v = std::strtod(a.frame_budget.c_str(), &end);
    if (!end || *end != '\0' || end == a.frame_budget.c_str() || !(v > 0) || !std::isfinite(v))
      return bad("--frame-budget " + a.frame_budget + ": must be a number of ms > 0, or off");
    scene.terrain.frame_budget_ms = v;
  }
  if (!a.camera.empty() && !scene.find_camera(a.camera)) return bad("--camera " + a.camera + ": the scene has no such camera");
  const std::string backend = a.backend.empty() ? scene.terrain.backend : a.backend;
  if (backend != "cpu" && backend != "gl") return bad("--backend " + backend + ": allowed values are cpu, gl");

  // ---- the display ----
  const char* display = std::getenv("DISPLAY");
  if (!display || !*display)
    return bad("no display: DISPLAY is not set (run it in an X session, or headless as "
               "xvfb-run -a sandpatch view ...; `sandpatch run --video` needs no display)");
  glfwSetErrorCallback(on_glfw_error);
  if (!glfwInit())
    return bad(std::string("cannot open the display DISPLAY=") + display + ": " +
               (g_glfw_error.empty() ? "GLFW could not start" : g_glfw_error));
  struct GlfwGuard {
    ~GlfwGuard() { glfwTerminate(); }
  } glfw_guard;

  // ---- the world ----
  const int threads_req = a.threads >= 0 ? a.threads : scene.terrain.threads;
  omp_set_num_threads(threads_req > 0 ? threads_req : omp_get_num_procs());
  std::string stage;
  const auto t_setup = Clock::now();
  int last_pct = -1;  // start-up progress: a line every 10 %
  auto made = make_world(scene, omp_get_max_threads(), backend, &stage, true,
                         [&](const std::string& what, double done, double max, double) {
                           const int pct = max > 0 ? int(100 * done / max) / 10 * 10 : 0;
                           if (pct != last_pct) std::fprintf(stderr, "start-up: %s: %d%%\n", what.c_str(), pct);
                           last_pct = pct;
                         });
  if (!made) {
    std::fprintf(stderr, "sandpatch view: invalid scene (stage %s)\n%s\n", stage.c_str(), made.message().c_str());
    return static_cast<int>(ExitCode::BadInput);
  }
  World& world = **made;
  const double dt = scene.simulation.dt;
  const render::CameraView start = start_view(scene, a.camera, world.heightfield());

  // ---- the window ----
  // The world may have left its EGL context current (the depth renderer of demotions).
  release_egl();
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);  // glBlitFramebuffer
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 0);
  const std::string title = "sandpatch view: " + scene.name;
  // A GLX context (GLFW's default on X11), else an EGL one on the same window.
  GLFWwindow* win = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (!win) {
    const std::string glx_error = g_glfw_error;
    glfwWindowHint(GLFW_CONTEXT_CREATION_API, GLFW_EGL_CONTEXT_API);
    win = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (!win)
      return failed(std::string("no window on DISPLAY=") + display + " with an OpenGL 3.0 context: GLX: " + glx_error +
                    "; EGL: " + g_glfw_error);
  }
  Controls ctl;
  auto reset_camera = [&] { ctl.orbit = render::OrbitCamera::looking(start.position, start.target); };
  reset_camera();
  ctl.fov_deg = start.fov_deg;
  glfwSetWindowUserPointer(win, &ctl);
  install_callbacks(win);
  glfwMakeContextCurrent(win);
  glfwSwapInterval(0);  // paced below, not by the display
  glfwMakeContextCurrent(nullptr);

  int code = 0;
  {
    FrameWriter images(world);
    Presenter presenter;
    FrameStats st;
    std::deque<std::pair<double, double>> recent;  // (wall s, simulated s) of the last second of frames
    long long shown = 0;
    bool shot_saved = false;
    double sum_step = 0, sum_render = 0, sum_overlay = 0, sum_present = 0;
    const auto t0 = Clock::now();
    double next_due = 0;  // wall s (since t0) at which the next step is due
    std::fprintf(stderr, "view: start-up %.2f s; window %dx%d on DISPLAY=%s\n", seconds_since(t_setup), width, height, display);

    std::size_t next_token = 0;  // --keys: the next token to apply
    bool token_applied = false;  // a token was applied for the frame being drawn
    bool effects_set = !low;
    while (!glfwWindowShouldClose(win) && !ctl.quit) {
      if (next_token < script.size() && shown > 0 && !token_applied) {
        script[next_token].apply(ctl);
        token_applied = true;
        if (ctl.quit) break;
      }
      const bool done = a.frames > 0 && world.steps() >= a.frames;
      const bool stepping = !done && (!ctl.paused || ctl.step_once);
      if (!stepping && !ctl.dirty) {
        if (done) break;
        glfwWaitEventsTimeout(0.05);
        continue;
      }
      const auto frame_start = Clock::now();
      if (stepping) {
        if (const auto& sd = scene.simulation.scale_by_distance)  // the scene's camera, as `run` does: same state
          world.set_camera(camera_at(*scene.find_camera(sd->camera), world.time()).position.cast<double>());
        const auto t = Clock::now();
        if (Status s = world.step(dt, scene.simulation.substeps); !s) {
          code = failed(std::string("step failed in stage '") + world.failed_stage() + "': " + s.message());
          break;
        }
        st.step_ms = seconds_since(t) * 1e3;
        st.budget_ms = world.last_frame().budget_ms;
        ctl.step_once = false;
      }
      if (ctl.reset_camera) reset_camera(), ctl.reset_camera = false;
      ctl.dirty = false;

      int fb_w = 0, fb_h = 0;
      glfwGetFramebufferSize(win, &fb_w, &fb_h);
      const bool last = a.frames > 0 && world.steps() >= a.frames;
      if (fb_w > 0 && fb_h > 0) {
        render::CameraView view = start;
        view.position = ctl.orbit.eye();
        view.target = ctl.orbit.target;
        // --quality low: half the window's pixels each way, scaled up when presented.
        view.width = low ? std::max(fb_w / 2, 16) : fb_w, view.height = low ? std::max(fb_h / 2, 16) : fb_h;
        ctl.fb_height = fb_h;
        const auto t_r = Clock::now();
        if (Status s = images.heightfield_changed(world.take_dirty_regions()); !s) {
          code = failed(s.message());
          break;
        }
        auto img = images.render(view);
        if (img && !effects_set && images.renderer()) {  // the renderer exists from the first image on
          if (Status s = images.renderer()->set_effects(0.0f, 512, 0); !s) {
            code = failed(s.message());
            break;
          }
          effects_set = true;
          img = images.render(view);
        }
        if (!img) {
          code = failed("render: " + img.message());
          break;
        }
        if (images.unavailable()) {
          code = failed("no OpenGL context to render with: " + images.why());
          break;
        }
        st.render_ms = seconds_since(t_r) * 1e3;
        const auto t_o = Clock::now();
        const std::array<int, 4> panel = draw_overlay(*img, images.renderer(), view, world, scene, ctl, st);
        const double overlay_ms = seconds_since(t_o) * 1e3;

        const auto t_p = Clock::now();
        release_egl();
        glfwMakeContextCurrent(win);
        render::Image shot;
        const bool want_shot = last && !a.screenshot.empty();
        presenter.draw(*img, fb_w, fb_h, want_shot ? &shot : nullptr);
        glfwSwapBuffers(win);
        glfwMakeContextCurrent(nullptr);
        st.present_ms = seconds_since(t_p) * 1e3;
        if (want_shot) {
          if (Status s = render::save_png(a.screenshot, shot); !s) {
            code = failed(s.message());
            break;
          }
          shot_saved = true;
          std::printf("screenshot: %s (%dx%d), overlay panel at x %d y %d, %d x %d px\n", a.screenshot.c_str(), shot.width,
                      shot.height, panel[0], panel[1], panel[2], panel[3]);
        }
        ++shown;
        if (token_applied) {
          const Eigen::Vector3d eye = ctl.orbit.eye();
          std::printf("keys: %s -> %s, steps %lld, t = %.6f s, speed %g, eye %.9f %.9f %.9f\n",
                      script[next_token].text.c_str(), ctl.paused ? "paused" : "running", world.steps(), world.time(),
                      ctl.speed, eye.x(), eye.y(), eye.z());
          token_applied = false;
          if (++next_token == script.size()) ctl.quit = true;  // the script's last frame is drawn
        }
        sum_step += stepping ? st.step_ms : 0;
        sum_render += st.render_ms;
        sum_overlay += overlay_ms;
        sum_present += st.present_ms;
      }
      glfwPollEvents();

      // Frame rate and real-time factor over the last second.
      const double now = seconds_since(t0);
      st.frame_ms = seconds_since(frame_start) * 1e3;
      recent.emplace_back(now, world.time());
      while (recent.size() > 2 && recent.front().first < now - 1.0) recent.pop_front();
      const double span = recent.back().first - recent.front().first;
      st.fps = span > 0 ? double(recent.size() - 1) / span : 0;
      st.rtf = span > 0 ? (recent.back().second - recent.front().second) / span : 0;
      if (last) break;
      // Real-time pacing: a step every dt / speed of wall time; a slower simulation runs as fast
      // as it can (no catching up afterwards).
      if (stepping && !ctl.paused) {
        next_due = std::max(next_due + dt / ctl.speed, now - 0.25);
        if (next_due > now) std::this_thread::sleep_for(std::chrono::duration<double>(next_due - now));
      } else {
        next_due = now;
      }
    }

    const double wall = seconds_since(t0);
    if (code == 0 && !a.screenshot.empty() && !shot_saved)
      code = failed("--screenshot " + a.screenshot + ": not written: the window was closed, or had no pixels (minimised), "
                    "before frame " + std::to_string(a.frames));
    glfwMakeContextCurrent(win);
    presenter.release();
    glfwMakeContextCurrent(nullptr);
    if (shown > 0)
      std::printf("view: %lld frames shown in %.2f s: average %.2f fps; %lld steps to t = %.3f s; per frame (mean): "
                  "step %.1f ms, render %.1f ms, overlay %.2f ms, present %.1f ms\n",
                  shown, wall, double(shown) / wall, world.steps(), world.time(), sum_step / double(shown),
                  sum_render / double(shown), sum_overlay / double(shown), sum_present / double(shown));
  }
  glfwDestroyWindow(win);
  return code;
}

}  // namespace sandpatch

#endif  // SANDPATCH_HAVE_GLFW
