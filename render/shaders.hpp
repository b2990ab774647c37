// The render/ GLSL programs, built from the sources embedded at build time
// (shaders/render/*, embedded by the shaders/ library). shaders/render/common.glsl is inserted after
// each stage's #version line, and a line `#include "NAME"` is replaced by shaders/render/NAME
// (terrain_shadow.glsl: the terrain's shadow march, in the terrain, particle and body shaders).
// Needs a current GL context.
#pragma once

#include "common/error.hpp"
#include "gl/program.hpp"

namespace sandpatch::render {

Result<gl::Program> build_terrain_program();
Result<gl::Program> build_particle_program();
Result<gl::Program> build_full_grid_program();
Result<gl::Program> build_body_program();
Result<gl::Program> build_ao_program();
// The granule bed's smoothing, one direction a pass (shaders/render/bed_blur.frag).
Result<gl::Program> build_bed_blur_program();

}  // namespace sandpatch::render
