// Headless OpenGL 4.3+ core context through EGL, with no window and no display server.
//
// Display selection, in order (each step only if the EGL client extensions allow it):
//   1. EGL_EXT_platform_device: the first device whose driver gives a GL 4.3 core context
//      (a real GPU when there is one; Mesa exposes llvmpipe as a software device too);
//   2. EGL_MESA_platform_surfaceless (Mesa without a device node);
//   3. eglGetDisplay(EGL_DEFAULT_DISPLAY).
// The context is made current with no surface (EGL_KHR_surfaceless_context); rendering goes
// to framebuffer objects. When no context can be made, create() returns an error that says
// which step failed and what to install (libegl-mesa0, libgl1-mesa-dri).
#pragma once

#include <memory>
#include <string>

#include "common/error.hpp"

namespace sandpatch::gl {

struct ContextDef {
  int major = 4;              // minimum OpenGL version (compute shaders need 4.3)
  int minor = 3;
  bool debug = false;         // request a debug context and log GL debug messages to stderr
  bool prefer_software = false;  // pick Mesa's llvmpipe even when a GPU device exists (tests)
};

struct ContextInfo {
  std::string platform;      // "device", "surfaceless" or "default"
  std::string egl_version;   // e.g. "1.5"
  std::string egl_vendor;    // e.g. "Mesa Project"
  std::string gl_vendor;     // GL_VENDOR
  std::string gl_renderer;   // GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
  std::string gl_version;    // GL_VERSION
  std::string glsl_version;  // GL_SHADING_LANGUAGE_VERSION
  int major = 0, minor = 0;  // GL version of the context made
  bool software = false;     // true on llvmpipe / softpipe / swrast
  int max_ssbo_bindings = 0;        // GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS
  long long max_ssbo_bytes = 0;     // GL_MAX_SHADER_STORAGE_BLOCK_SIZE (bytes)
  int max_work_group_invocations = 0;  // GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS
};

// One EGL display + context. Not copyable; the context is current on the creating thread.
class Context {
 public:
  static Result<std::unique_ptr<Context>> create(const ContextDef& def = {});
  // For callers with a CPU fallback: the context, or null with `why` set to why none could
  // be made.
  static std::unique_ptr<Context> create_or_explain(std::string& why, const ContextDef& def = {}) {
    auto ctx = create(def);
    if (ctx) return std::move(*ctx);
    why = ctx.message();
    return nullptr;
  }
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  // Makes this context current on the calling thread (the creating thread already has it).
  Status make_current();
  const ContextInfo& info() const { return info_; }

  // Returns and clears GL errors; "" when there were none. For checks after a stage.
  static std::string drain_errors();

 private:
  Context() = default;
  void* display_ = nullptr;  // EGLDisplay
  void* context_ = nullptr;  // EGLContext
  ContextInfo info_;
};

}  // namespace sandpatch::gl
