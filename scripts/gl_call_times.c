// Host time of each GL call a program makes, for finding where a GL backend's frame goes on a
// driver one cannot profile (docs/BENCHMARKS.md "GL backend on a GPU: no buffer copies").
// Built as a shared library and preloaded; at exit it prints, per GL entry point it wraps, the
// calls, total and mean host time and the longest call, to $GLTIME_OUT (appended) or stderr:
//
//   gcc -O2 -shared -fPIC -o libgl_call_times.so scripts/gl_call_times.c -ldl
//   GLTIME_OUT=times.txt LD_PRELOAD=$PWD/libgl_call_times.so ./build/sandpatch run SCENE --backend gl ...
//
// It wraps the entry points the DEM and the renderers call in a frame (the programs link
// libOpenGL and libEGL directly, so a preloaded definition takes their place); one GL thread.
#define _GNU_SOURCE
#define GL_GLEXT_PROTOTYPES
#include <GL/glcorearb.h>
#include <EGL/egl.h>
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
enum { MAXF = 128 };
static const char* names[MAXF];
static unsigned long long cnt[MAXF], tot[MAXF], mx[MAXF];
static int nf;
static inline unsigned long long now(void) { struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t); return t.tv_sec * 1000000000ull + t.tv_nsec; }
static int slot(const char* n) { for (int i = 0; i < nf; ++i) if (names[i] == n) return i; names[nf] = n; return nf++; }
static void rec(int i, unsigned long long dt) { cnt[i]++; tot[i] += dt; if (dt > mx[i]) mx[i] = dt; }
__attribute__((destructor)) static void dump(void) {
  if (nf == 0) return;
  const char* p = getenv("GLTIME_OUT"); FILE* f = p ? fopen(p, "a") : stderr; if (!f) f = stderr;
  int order[MAXF]; for (int i = 0; i < nf; ++i) order[i] = i;
  for (int i = 0; i < nf; ++i) for (int j = i + 1; j < nf; ++j) if (tot[order[j]] > tot[order[i]]) { int t = order[i]; order[i] = order[j]; order[j] = t; }
  unsigned long long all = 0; for (int i = 0; i < nf; ++i) all += tot[i];
  fprintf(f, "gltime: %s total %.1f ms in GL calls\n", getenv("GLTIME_TAG") ? getenv("GLTIME_TAG") : "", all / 1e6);
  for (int k = 0; k < nf; ++k) { int i = order[k]; if (!cnt[i]) continue;
    fprintf(f, "  %-28s %9llu calls %10.1f ms %8.2f us/call max %8.1f us\n", names[i], cnt[i], tot[i] / 1e6, tot[i] / 1e3 / cnt[i], mx[i] / 1e3); }
  if (f != stderr) fclose(f);
}
#define REAL(name) static __typeof__(&name) real_##name; if (!real_##name) real_##name = (__typeof__(&name))dlsym(RTLD_NEXT, #name); \
  static const char n_##name[] = #name; static int s_##name = -1; if (s_##name < 0) s_##name = slot(n_##name); unsigned long long t0 = now();
#define DONE(name) rec(s_##name, now() - t0);
#define V0(name) void name(void) { REAL(name) real_##name(); DONE(name) }
#define V1(name, A) void name(A a) { REAL(name) real_##name(a); DONE(name) }
#define V2(name, A, B) void name(A a, B b) { REAL(name) real_##name(a, b); DONE(name) }
#define V3(name, A, B, C) void name(A a, B b, C c) { REAL(name) real_##name(a, b, c); DONE(name) }
#define V4(name, A, B, C, D) void name(A a, B b, C c, D d) { REAL(name) real_##name(a, b, c, d); DONE(name) }
#define V5(name, A, B, C, D, E) void name(A a, B b, C c, D d, E e) { REAL(name) real_##name(a, b, c, d, e); DONE(name) }
#define V7(name, A, B, C, D, E, F, G) void name(A a, B b, C c, D d, E e, F f, G g) { REAL(name) real_##name(a, b, c, d, e, f, g); DONE(name) }
V3(glDispatchCompute, GLuint, GLuint, GLuint)
V1(glDispatchComputeIndirect, GLintptr)
V1(glMemoryBarrier, GLbitfield)
V1(glUseProgram, GLuint)
V3(glBindBufferBase, GLenum, GLuint, GLuint)
V2(glBindBuffer, GLenum, GLuint)
V5(glCopyBufferSubData, GLenum, GLenum, GLintptr, GLintptr, GLsizeiptr)
V4(glBufferData, GLenum, GLsizeiptr, const void*, GLenum)
V4(glBufferStorage, GLenum, GLsizeiptr, const void*, GLbitfield)
V4(glBufferSubData, GLenum, GLintptr, GLsizeiptr, const void*)
V4(glGetBufferSubData, GLenum, GLintptr, GLsizeiptr, void*)
V3(glProgramUniform1i, GLuint, GLint, GLint)
V3(glProgramUniform1ui, GLuint, GLint, GLuint)
V3(glProgramUniform1f, GLuint, GLint, GLfloat)
V5(glProgramUniform3f, GLuint, GLint, GLfloat, GLfloat, GLfloat)
V2(glBeginQuery, GLenum, GLuint)
V1(glEndQuery, GLenum)
V3(glGetQueryObjectui64v, GLuint, GLenum, GLuint64*)
V0(glFinish)
V0(glFlush)
V2(glGetIntegerv, GLenum, GLint*)
V3(glDrawArrays, GLenum, GLint, GLsizei)
V4(glDrawElements, GLenum, GLsizei, GLenum, const void*)
V4(glDrawArraysInstanced, GLenum, GLint, GLsizei, GLsizei)
V7(glReadPixels, GLint, GLint, GLsizei, GLsizei, GLenum, GLenum, void*)
V2(glBindFramebuffer, GLenum, GLuint)
V1(glClear, GLbitfield)
V2(glGenBuffers, GLsizei, GLuint*)
V2(glDeleteBuffers, GLsizei, const GLuint*)
GLenum glGetError(void) { REAL(glGetError) GLenum r = real_glGetError(); DONE(glGetError) return r; }
EGLBoolean eglMakeCurrent(EGLDisplay d, EGLSurface a, EGLSurface b, EGLContext c) { REAL(eglMakeCurrent) EGLBoolean r = real_eglMakeCurrent(d, a, b, c); DONE(eglMakeCurrent) return r; }
