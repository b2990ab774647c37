// GL drawing of rigid bodies (render/bodies.hpp): every body tessellated on the CPU into one
// vertex buffer per frame (a few thousand triangles per primitive body; meshes as they are)
// and drawn in one call with depth test, lit like the terrain (diffuse + ambient of the same
// sun), or in flat ID colours for tests.
#pragma once

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "common/error.hpp"
#include "gl/program.hpp"
#include "render/bodies.hpp"

namespace sandpatch::render {

struct ShadowMap;       // render/terrain_renderer.hpp
class TerrainRenderer;

class BodyRenderer {
 public:
  static Result<std::unique_ptr<BodyRenderer>> create();
  ~BodyRenderer();
  BodyRenderer(const BodyRenderer&) = delete;
  BodyRenderer& operator=(const BodyRenderer&) = delete;

  // Draws the bodies (validated by the caller) into the bound framebuffer. view_proj: local ->
  // clip; eye: local m; world_origin: the heightfield's origin (world m). With flat_ids, body k
  // is drawn unlit in body_id_color(k). With a shadow map the bodies receive the shadows of
  // the bodies (themselves included) in it; none while that map is being drawn. With a
  // terrain they receive the terrain's shadow (its march, TerrainRenderer::terrain_shadow_steps;
  // none in ID renders). Returns the number of triangles drawn.
  std::size_t draw(const std::vector<BodyInstance>& bodies, const Eigen::Matrix4f& view_proj, const Eigen::Vector3f& eye,
                   const Eigen::Vector3f& sun_direction, const Eigen::Vector3d& world_origin, bool flat_ids,
                   const ShadowMap* shadow = nullptr, const TerrainRenderer* terrain = nullptr);

 private:
  BodyRenderer() = default;
  gl::Program program_;
  unsigned vao_ = 0, vbo_ = 0;
  std::vector<BodyVertex> tris_;
  std::vector<float> data_;
};

// The flat colour of body k in ID renders (sRGB bytes): (255, k / 256, k % 256) with k < 65536,
// pure red channel saturated and no green: no lit terrain, sky or granule colour equals it.
std::array<std::uint8_t, 3> body_id_color(int k);

}  // namespace sandpatch::render
