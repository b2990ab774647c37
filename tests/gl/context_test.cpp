// tests gl/context.cpp and gl/program.cpp on whatever EGL finds (llvmpipe in CI).
#include <GL/glcorearb.h>
#include <gtest/gtest.h>

#include <numeric>
#include <vector>

#include "gl/context.hpp"
#include "gl/program.hpp"

using namespace sandpatch;

TEST(GlContext, MakesA43CoreContextHeadless) {
  auto ctx = gl::Context::create();
  ASSERT_TRUE(ctx.ok()) << ctx.message();
  const auto& info = (*ctx)->info();
  EXPECT_GE(info.major * 10 + info.minor, 43) << info.gl_version;
  EXPECT_FALSE(info.gl_renderer.empty());
  EXPECT_GT(info.max_ssbo_bindings, 7);
  std::printf("renderer: %s | %s | platform %s\n", info.gl_renderer.c_str(), info.gl_version.c_str(),
              info.platform.c_str());
}

TEST(GlContext, SoftwareRendererCanBeForced) {
  gl::ContextDef def;
  def.prefer_software = true;
  auto ctx = gl::Context::create(def);
  // A machine with a GPU driver and no Mesa (a GPU server) has no software renderer to force:
  // every display answers with its GPU. Anything else that fails is a failure.
  if (!ctx.ok() && ctx.message().find("not a software renderer") != std::string::npos &&
      ctx.message().find("failed") == std::string::npos)
    GTEST_SKIP() << "no software renderer installed: " << ctx.message();
  ASSERT_TRUE(ctx.ok()) << ctx.message();
  EXPECT_TRUE((*ctx)->info().software) << (*ctx)->info().gl_renderer;
}

// A compute shader computes y[i] = a*x[i] + i on the GPU; the CPU checks every element exactly
// (all values are small integers in float, so the result is exact on any conforming driver).
TEST(GlContext, ComputeShaderRunsAndReadsBack) {
  auto ctx = gl::Context::create();
  ASSERT_TRUE(ctx.ok()) << ctx.message();
  const char* src = R"(#version 430
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer X { float x[]; };
layout(std430, binding = 1) buffer Y { float y[]; };
uniform float a;
uniform uint n;
void main() {
  uint i = gl_GlobalInvocationID.x;
  if (i < n) y[i] = a * x[i] + float(i);
})";
  auto prog = gl::Program::compute("test_saxpy.comp", src);
  ASSERT_TRUE(prog.ok()) << prog.message();
  const GLuint n = 1000;
  std::vector<float> x(n);
  std::iota(x.begin(), x.end(), 0.0f);
  GLuint buf[2];
  glGenBuffers(2, buf);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, buf[0]);
  glBufferData(GL_SHADER_STORAGE_BUFFER, n * sizeof(float), x.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, buf[1]);
  glBufferData(GL_SHADER_STORAGE_BUFFER, n * sizeof(float), nullptr, GL_DYNAMIC_READ);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, buf[0]);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, buf[1]);
  glUseProgram(prog->id());
  glUniform1f(glGetUniformLocation(prog->id(), "a"), 3.0f);
  glUniform1ui(glGetUniformLocation(prog->id(), "n"), n);
  glDispatchCompute((n + 63) / 64, 1, 1);
  glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  std::vector<float> y(n, -1.0f);
  glGetBufferSubData(GL_SHADER_STORAGE_BUFFER, 0, n * sizeof(float), y.data());
  for (GLuint i = 0; i < n; ++i) ASSERT_EQ(y[i], 4.0f * float(i)) << "element " << i;
  glDeleteBuffers(2, buf);
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

TEST(GlProgram, CompileErrorNamesTheShader) {
  auto ctx = gl::Context::create();
  ASSERT_TRUE(ctx.ok()) << ctx.message();
  auto prog = gl::Program::compute("broken.comp", "#version 430\nlayout(local_size_x=1) in; void main() { x = 1; }");
  ASSERT_FALSE(prog.ok());
  EXPECT_NE(prog.message().find("broken.comp"), std::string::npos) << prog.message();
  EXPECT_NE(prog.message().find("compile"), std::string::npos) << prog.message();
}
