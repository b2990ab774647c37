// Particle splats (Leach & Marais §4.2): one GL point per particle, read straight from the
// simulation's GL buffer through a stride/offset description (no CPU copy), cut to a disc,
// shaded as a sphere and written with the sphere's depth; sized by the patch's particle scale
// (Leach §4.3) and faded in by a factor (Leach §5.1).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <memory>
#include <vector>

#include "common/error.hpp"
#include "gl/program.hpp"

namespace sandpatch::render {

class TerrainRenderer;
struct ShadowMap;

// A depth pre-pass of the same particles (a depth texture of the viewport's size) the colour
// pass estimates the bed's normal from, `scale` particle radii to each side of a pixel.
struct BedDepth {
  unsigned texture = 0;
  int width = 0, height = 0;
  float scale = 4.0f;
};

// Where one patch's particles live in a GL buffer. The buffer is the caller's (e.g. the DEM's
// position SSBO); it must stay alive while it is set on a renderer.
struct ParticleSource {
  unsigned buffer = 0;         // GL buffer name (any buffer object; bound as GL_ARRAY_BUFFER to draw)
  std::int64_t count = 0;      // particles to draw (>= 0)
  std::int64_t first = 0;      // index of the first particle
  int stride = 16;             // bytes between consecutive particles (>= 12)
  int position_offset = 0;     // bytes to three floats x, y, z (m, patch frame, unit particle scale)
  int radius_offset = 12;      // bytes to one float radius (m, unit scale); < 0: every particle has `radius`
  float radius = 0.005f;       // m, unit scale: used when radius_offset < 0 (> 0)
  Eigen::Vector3d origin{0, 0, 0};  // world position (m) of the patch frame's origin
  float scale = 1.0f;          // particle scale: drawn centre = origin + scale p, radius = scale r (> 0)
  float fade = 1.0f;           // fade-in factor in [0, 1] (1 = opaque)
  // How many times coarser the granules are than the sand they stand for (the patch's particle
  // scale, Leach §4.3), >= 1. Shading only: a granule's own roundness, occlusion and tint show
  // as they would on a granule this many times smaller on screen, and the bed's normal is taken
  // over (1 + shading_scale) / 2 times the usual span, so a coarse patch reads as sand rather
  // than as a heap of pebbles (docs/rendering.md "Particles"). 1 = as drawn.
  float shading_scale = 1.0f;
  // m, world: the radius the spheres are drawn at when they share one (scale x radius), or 0
  // (unknown; with radius_offset < 0, scale x radius is taken). The renderer smooths the granules' bed over the finest such radius of a frame
  // before it takes the bed's normal from it (docs/rendering.md "Particles").
  float sphere_radius = 0.0f;
  // The patch's footprint on the ground, world (x0, z0, x1, z1) in m, or empty (x1 <= x0, the
  // default). When set, the second terrain pass (Leach & Marais §5.1) leaves the terrain out
  // of it: there the granules are the surface, so a crater or heap carved into the bed shows
  // instead of being covered by the heightfield it was promoted from.
  Eigen::Vector4d footprint{0, 0, 0, 0};
  // Inside the footprint the terrain fades out over this band (m, from the edge inward), >= 0.
  float footprint_band = 0.0f;
  // Optional: the byte offset in `buffer` of one int32 id per particle (4 bytes apart, the same
  // order as the positions, indexed from `first` like them), and with id_limit >= 0 only the
  // particles of id below id_limit are drawn (a simulation buffer holding the granules' spheres
  // first by id and the bodies' shell spheres after them, in another order). The ids also give
  // each granule (id / 4) its own tint. < 0: no ids; every particle is drawn.
  int id_offset = -1;
  std::int64_t id_limit = -1;
  bool has_footprint() const { return footprint[2] > footprint[0] && footprint[3] > footprint[1]; }
};

// Checks a source; errors name the field ("particles[2].stride = 8: ...").
Status validate(const ParticleSource& s, int index);

// A GL buffer of vec4 (x, y, z, radius) filled from CPU arrays: for tests and tools.
class ParticleBuffer {
 public:
  explicit ParticleBuffer(const std::vector<Eigen::Vector4f>& xyzr);
  ~ParticleBuffer();
  ParticleBuffer(const ParticleBuffer&) = delete;
  ParticleBuffer& operator=(const ParticleBuffer&) = delete;
  unsigned id() const { return id_; }
  std::int64_t count() const { return count_; }
  // A source over the whole buffer (stride 16, radius in w; its sphere_radius the smallest
  // radius in the buffer times scale).
  ParticleSource source(const Eigen::Vector3d& origin, float scale = 1.0f, float fade = 1.0f) const;

 private:
  unsigned id_ = 0;
  std::int64_t count_ = 0;
  float min_radius_ = 0;  // m, unit scale: the smallest sphere radius (0: none)
};

class ParticleRenderer {
 public:
  static Result<std::unique_ptr<ParticleRenderer>> create();
  ~ParticleRenderer();
  ParticleRenderer(const ParticleRenderer&) = delete;
  ParticleRenderer& operator=(const ParticleRenderer&) = delete;

  // Draws the sources into the bound framebuffer with depth test and write, alpha-blended by
  // each source's fade. view: local -> eye; proj: eye -> clip; world_origin: the heightfield's
  // origin (world m), subtracted from each source's origin. Material weights come from the
  // terrain's clipmap textures (terrain.update() must have run this frame). normal_bend in
  // [0, 1]: lighting normal = normalize(mix(sphere normal, terrain normal, normal_bend)).
  // color_variation: each granule's albedo times 1 + v u, u in [-1, 1] hashed from the
  // granule's index (one granule's four spheres share it).
  // terrain_shadow: each particle receives the terrain's shadow (the march of
  // TerrainRenderer::terrain_shadow_steps from its centre); off for a depth-only pass.
  // Returns the number of particles drawn.
  std::int64_t draw(const std::vector<ParticleSource>& sources, const Eigen::Matrix4f& view,
                    const Eigen::Matrix4f& proj, int viewport_height, const TerrainRenderer& terrain,
                    const Eigen::Vector3d& world_origin, float normal_bend = 0.5f, float color_variation = 0.0f,
                    const ShadowMap* shadow = nullptr, float gain = 1.0f, const BedDepth* bed = nullptr,
                    bool terrain_shadow = false);

 private:
  ParticleRenderer() = default;
  gl::Program program_;
  unsigned vao_ = 0;
};

}  // namespace sandpatch::render
