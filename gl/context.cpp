// Headless EGL context creation (see context.hpp for the display-selection order).
#include "gl/context.hpp"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

namespace sandpatch::gl {
namespace {

bool has_extension(const char* list, const char* name) {
  if (!list) return false;
  const std::size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)); p += n) {
    if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0')) return true;
  }
  return false;
}

const char* egl_error_name(EGLint e) {
  switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    default: return "EGL error";
  }
}

std::string gl_string(GLenum name) {
  const GLubyte* s = glGetString(name);
  return s ? reinterpret_cast<const char*>(s) : "";
}

void APIENTRY debug_callback(GLenum, GLenum type, GLuint, GLenum severity, GLsizei, const GLchar* msg,
                               const void*) {
  if (severity == GL_DEBUG_SEVERITY_NOTIFICATION) return;
  std::fprintf(stderr, "GL debug (type 0x%x): %s\n", type, msg);
}

// Tries to make a current GL context of at least def.major.def.minor core on `dpy`.
// On failure, terminates the display and returns a reason.
std::string try_display(EGLDisplay dpy, const ContextDef& def, EGLContext* out_ctx, ContextInfo* info) {
  if (dpy == EGL_NO_DISPLAY) return "no display";
  EGLint maj = 0, min = 0;
  if (!eglInitialize(dpy, &maj, &min)) return std::string("eglInitialize failed: ") + egl_error_name(eglGetError());
  auto fail = [&](std::string why) {
    eglTerminate(dpy);
    return why;
  };
  const char* exts = eglQueryString(dpy, EGL_EXTENSIONS);
  if (!eglBindAPI(EGL_OPENGL_API)) return fail("eglBindAPI(EGL_OPENGL_API) failed: desktop OpenGL not offered");
  const bool surfaceless = has_extension(exts, "EGL_KHR_surfaceless_context");
  if (!surfaceless) return fail("EGL_KHR_surfaceless_context missing");
  const EGLint cfg_attr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, 0, EGL_NONE};
  EGLConfig cfg = nullptr;
  EGLint ncfg = 0;
  const bool no_config = has_extension(exts, "EGL_KHR_no_config_context");
  if (!eglChooseConfig(dpy, cfg_attr, &cfg, 1, &ncfg) || ncfg == 0) {
    if (!no_config) return fail("no EGLConfig with EGL_OPENGL_BIT");
    cfg = nullptr;  // EGL_NO_CONFIG_KHR
  }
  std::vector<EGLint> ctx_attr = {EGL_CONTEXT_MAJOR_VERSION, def.major, EGL_CONTEXT_MINOR_VERSION, def.minor,
                                  EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT};
  if (def.debug) ctx_attr.insert(ctx_attr.end(), {EGL_CONTEXT_OPENGL_DEBUG, EGL_TRUE});
  ctx_attr.push_back(EGL_NONE);
  EGLContext ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, ctx_attr.data());
  if (ctx == EGL_NO_CONTEXT) {
    return fail("no OpenGL " + std::to_string(def.major) + "." + std::to_string(def.minor) +
                " core context (" + egl_error_name(eglGetError()) + ")");
  }
  if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) {
    eglDestroyContext(dpy, ctx);
    return fail(std::string("eglMakeCurrent failed: ") + egl_error_name(eglGetError()));
  }
  info->egl_version = std::to_string(maj) + "." + std::to_string(min);
  const char* vendor = eglQueryString(dpy, EGL_VENDOR);
  info->egl_vendor = vendor ? vendor : "";
  info->gl_vendor = gl_string(GL_VENDOR);
  info->gl_renderer = gl_string(GL_RENDERER);
  info->gl_version = gl_string(GL_VERSION);
  info->glsl_version = gl_string(GL_SHADING_LANGUAGE_VERSION);
  glGetIntegerv(GL_MAJOR_VERSION, &info->major);
  glGetIntegerv(GL_MINOR_VERSION, &info->minor);
  const std::string& r = info->gl_renderer;
  info->software = r.find("llvmpipe") != std::string::npos || r.find("softpipe") != std::string::npos ||
                   r.find("swrast") != std::string::npos;
  glGetIntegerv(GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS, &info->max_ssbo_bindings);
  GLint64 ssbo_bytes = 0;
  glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &ssbo_bytes);
  info->max_ssbo_bytes = static_cast<long long>(ssbo_bytes);
  glGetIntegerv(GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS, &info->max_work_group_invocations);
  if (info->major * 10 + info->minor < def.major * 10 + def.minor) {
    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(dpy, ctx);
    return fail("context is only OpenGL " + info->gl_version);
  }
  if (def.debug) {
    glEnable(GL_DEBUG_OUTPUT);
    glDebugMessageCallback(debug_callback, nullptr);
  }
  *out_ctx = ctx;
  return "";
}

}  // namespace

Result<std::unique_ptr<Context>> Context::create(const ContextDef& def) {
  std::unique_ptr<Context> c(new Context());
  const char* client_exts = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  std::vector<std::string> tried;

  auto attempt = [&](EGLDisplay dpy, const char* platform) -> bool {
    EGLContext ctx = EGL_NO_CONTEXT;
    ContextInfo info;
    info.platform = platform;
    std::string why = try_display(dpy, def, &ctx, &info);
    if (why.empty() && def.prefer_software && !info.software) {
      eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
      eglDestroyContext(dpy, ctx);
      eglTerminate(dpy);
      why = "not a software renderer (" + info.gl_renderer + ")";
    }
    if (!why.empty()) {
      tried.push_back(std::string(platform) + ": " + why);
      return false;
    }
    c->display_ = dpy;
    c->context_ = ctx;
    c->info_ = info;
    return true;
  };

  auto get_platform_display =
      reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  // 1. Devices (GPUs first in the driver's order; llvmpipe shows up as a software device).
  if (get_platform_display && has_extension(client_exts, "EGL_EXT_platform_device")) {
    auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    EGLDeviceEXT devices[16];
    EGLint ndev = 0;
    if (query_devices && query_devices(16, devices, &ndev)) {
      for (EGLint i = 0; i < ndev; ++i) {
        if (attempt(get_platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr), "device")) return c;
      }
    }
  }
  // 2. Mesa's surfaceless platform.
  if (get_platform_display && has_extension(client_exts, "EGL_MESA_platform_surfaceless")) {
    if (attempt(get_platform_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr), "surfaceless"))
      return c;
  }
  // 3. Whatever the default display is.
  if (attempt(eglGetDisplay(EGL_DEFAULT_DISPLAY), "default")) return c;

  std::string why;
  for (const auto& t : tried) {
    if (!why.empty()) why += "; ";
    why += t;
  }
  if (why.empty()) why = "EGL offered no display";
  return Error{"", "OpenGL", std::to_string(def.major) + "." + std::to_string(def.minor) + " core via EGL",
               "no headless context could be made: " + why,
               "install Mesa's EGL and DRI drivers (scripts/install-deps.sh installs libegl-mesa0 and "
               "libgl1-mesa-dri) or a GPU driver with EGL"};
}

Context::~Context() {
  if (display_) {
    auto dpy = static_cast<EGLDisplay>(display_);
    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (context_) eglDestroyContext(dpy, static_cast<EGLContext>(context_));
    eglTerminate(dpy);
  }
}

Status Context::make_current() {
  if (!eglMakeCurrent(static_cast<EGLDisplay>(display_), EGL_NO_SURFACE, EGL_NO_SURFACE,
                      static_cast<EGLContext>(context_))) {
    return Error{"", "OpenGL context", "", "eglMakeCurrent failed", egl_error_name(eglGetError())};
  }
  return Ok{};
}

std::string Context::drain_errors() {
  std::string out;
  for (GLenum e; (e = glGetError()) != GL_NO_ERROR;) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "0x%04x", e);
    if (!out.empty()) out += ' ';
    out += buf;
  }
  return out;
}

}  // namespace sandpatch::gl
