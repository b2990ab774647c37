// GL geometry-clipmap terrain (Asirvatham & Hoppe 2005; selection in clipmap.hpp).
//
// Per level three layers of T x T texture arrays (T = n + 1), addressed toroidally (vertex g at
// texel g mod T):
//   elevation  R32F     Heightfield::sample(g s_l)            (m, local), read with texelFetch
//   normals    RGBA16F  Heightfield::normal(g s_l)            (unit), linear filtering
//   materials  RGBA8    Heightfield::sample_layer(Material0..3, g s_l)  (weights), linear
// so level l is the heightfield point-sampled every s_l metres (no prefilter: coarse levels
// hold exact heightfield values, which keeps every level's surface on the same samples).
// When the viewer moves, update() writes only the vertices that entered each level's window;
// heightfield_changed() rewrites only the texels that depend on the dirty samples.
//
// Drawing: the vertex shader (shaders/render/terrain.vert) fetches the height and morphs it
// toward the coarser level in the transition band (alpha), the fragment shader blends normals
// and material weights with the same alpha, blends the materials with the normalised blend
// operator (Huhtiranta §6.2 eq. 2) and lights them with one directional light.
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include "common/error.hpp"
#include "gl/program.hpp"
#include "heightfield/heightfield.hpp"
#include "render/clipmap.hpp"

namespace sandpatch::render {

// The bodies' shadow map as the terrain and particle shaders read it (common.glsl
// sp_sun_visibility): a depth texture with compare mode, the local -> [0, 1]^3 matrix, a bias.
struct ShadowMap {
  bool on = false;
  unsigned texture = 0;
  Eigen::Matrix4f matrix = Eigen::Matrix4f::Identity();
  float bias = 0;
  float texel_m = 0;  // one texel's width (m): bodies look themselves up this far off their surface
};
// Binds `s` to the current program (texture unit kShadowUnit).
inline constexpr int kShadowUnit = 5;
void bind_shadow(unsigned program, const ShadowMap& s);

class TerrainRenderer {
 public:
  // hf must outlive the renderer; def.base_spacing <= 0 means hf.spacing(). Needs a current
  // GL context. Errors name the clipmap field.
  static Result<std::unique_ptr<TerrainRenderer>> create(const Heightfield& hf, const ClipmapDef& def);
  ~TerrainRenderer();
  TerrainRenderer(const TerrainRenderer&) = delete;
  TerrainRenderer& operator=(const TerrainRenderer&) = delete;

  // Moves every level's window to the viewer (local m), writing only the texels of vertices
  // that entered it. Returns the number of texels written (per layer).
  std::int64_t update(const Eigen::Vector3f& viewer_local);
  // Rewrites the texels (of the current windows) that depend on the heightfield samples in
  // `dirty`. Returns texels written. Call after editing the heightfield.
  std::int64_t heightfield_changed(GridRegion dirty);
  // Forgets the windows: the next update() rebuilds every level from scratch.
  void invalidate();

  // Selects the pieces for this view (select_clipmap with the viewer of the last update()) and
  // draws them into the bound framebuffer with depth testing. view_proj: local -> clip.
  void draw(const Eigen::Matrix4f& view_proj, bool cull = true);
  // Draws the last selection again (Leach's second terrain pass), leaving out the live
  // footprints (set_live_footprints): inside one the terrain fades out (alpha-blended) over its
  // band from its edge.
  static constexpr int kMaxCuts = 32;
  void redraw();

  const ClipmapSelection& selection() const { return selection_; }
  const ClipmapDef& def() const { return def_; }
  const Heightfield& heightfield() const { return *hf_; }
  int texture_size() const { return T_; }
  // The window of level coordinates each level's texture holds (empty before update()).
  const std::vector<LevelRect>& windows() const { return windows_; }
  std::int64_t texels_written_total() const { return texels_total_; }
  unsigned normals_texture() const { return tex_[1]; }
  unsigned materials_texture() const { return tex_[2]; }
  int first_active_level() const;
  void set_sun_direction(const Eigen::Vector3f& toward_sun) { sun_ = toward_sun.normalized(); }
  // The terrain's shadow on itself: steps of the march toward the sun through the clipmap's
  // heights (terrain.frag), 0 = none.
  void set_terrain_shadow_steps(int steps) { shadow_steps_ = steps; }
  // The live patches' footprints (local x0, z0, x1, z1, m; at most kMaxCuts, the rest are
  // ignored) and the band (m) over which the second terrain pass fades out inside each: the
  // terrain's shadow march takes no heightfield sample inside them (terrain_shadow.glsl), for
  // every program bind_terrain_shadow serves, and redraw() leaves them out.
  void set_live_footprints(std::vector<Eigen::Vector4f> live, std::vector<float> bands = {}) {
    live_ = std::move(live);
    live_bands_ = std::move(bands);
  }
  int terrain_shadow_steps() const { return shadow_steps_; }
  // Sets the uniforms of shaders/render/terrain_shadow.glsl on `program` (current) and binds the
  // elevation texture to texture unit `unit`, so that shader's points receive the terrain's
  // shadow as the terrain does (the same march, the same drawn surface); steps 0 = none.
  void bind_terrain_shadow(unsigned program, int unit, int steps) const;
  // The bodies' shadows on the terrain from now on (off: ShadowMap{}).
  void set_shadow(const ShadowMap& s) { shadow_ = s; }
  const Eigen::Vector3f& sun_direction() const { return sun_; }

  // Reads back one layer of a texture array for tests: 0 elevation (1 float a texel),
  // 1 normals (4 floats), 2 materials (4 floats in [0, 1]); row-major T x T, x fastest.
  std::vector<float> read_texture(int which, int level) const;

 private:
  struct Mesh {
    unsigned vao = 0, vbo = 0, ibo = 0;
    int indices = 0;
  };
  TerrainRenderer() = default;
  std::int64_t write_rect(int level, const LevelRect& r);
  const Mesh& mesh_for(const ClipmapPiece& p);
  Mesh make_mesh(const std::vector<int>& xy, const std::vector<unsigned>& idx);
  void draw_selection(const std::vector<Eigen::Vector4f>& cuts = {}, const std::vector<float>& bands = {});

  const Heightfield* hf_ = nullptr;
  ClipmapDef def_;
  int T_ = 0;
  gl::Program program_;
  unsigned tex_[3] = {0, 0, 0};  // elevation, normals, materials
  std::vector<LevelRect> windows_;
  Eigen::Vector3f viewer_{0, 0, 0};
  Eigen::Matrix4f view_proj_ = Eigen::Matrix4f::Identity();
  Eigen::Vector3f sun_ = Eigen::Vector3f(-0.6f, 0.6f, 0.55f).normalized();
  int shadow_steps_ = 0;
  std::vector<Eigen::Vector4f> live_;  // set_live_footprints
  std::vector<float> live_bands_;
  ClipmapSelection selection_;
  ShadowMap shadow_;
  std::map<std::pair<int, int>, Mesh> meshes_;  // grid meshes by (cells_x, cells_z)
  Mesh degenerate_[2];  // one border side along x, along z
  std::int64_t texels_total_ = 0;
  // Scratch arrays for uploads.
  std::vector<float> elev_, normal_, material_;
};

}  // namespace sandpatch::render
