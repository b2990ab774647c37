// Sandpatch's renderer, the one entry point for the CLI (`sandpatch render`, `sandpatch bench
// render`) and the scene runner's PNG frames. docs/rendering.md describes what is drawn.
//
// One frame (Leach & Marais §5.1):
//   1. move the clipmap windows to the camera (toroidal texel updates);
//   2. clear colour (the background) and depth; draw the terrain (geometry clipmaps);
//   3. when particles are set: clear depth, draw the particle splats, draw the terrain again,
//      so particles below the surface never show and fading patches blend over the terrain
//      (a source with a footprint keeps the terrain out of it in this pass: its granules are
//      the surface there, craters included);
//   4. draw the rigid bodies (depth-tested against terrain and granules);
//   5. screen-space ambient occlusion over the whole frame (craters, gaps between granules,
//      the ground next to a body);
//   6. read the framebuffer back as an RGBA8 image (and write a PNG atomically).
// Everything renders into an offscreen framebuffer of the camera's resolution through the
// headless EGL context (gl/context.hpp); on machines with no GPU that is Mesa's llvmpipe.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/error.hpp"
#include "gl/context.hpp"
#include "heightfield/heightfield.hpp"
#include "render/bodies.hpp"
#include "render/clipmap.hpp"
#include "render/image.hpp"
#include "render/particle_renderer.hpp"

namespace sandpatch::render {

class TerrainRenderer;
class BodyRenderer;
struct ShadowMap;

struct RendererDef {
  // Clipmap layout. base_spacing <= 0 (the default here) = the heightfield's spacing;
  // levels <= 0 = enough levels for the coarsest to cover the whole terrain from anywhere on it.
  ClipmapDef clipmap = [] {
    ClipmapDef d;
    d.base_spacing = 0;
    d.levels = 0;
    return d;
  }();
  std::array<std::uint8_t, 3> background{140, 180, 230};  // sRGB bytes of the sky; no terrain colour equals it
  // Toward the sun (normalised on use): 25° above the horizon, from −x, +z. A low sun is what
  // makes shallow relief read (docs/rendering.md "Shading").
  Eigen::Vector3f sun_direction{-0.6f, 0.38f, 0.55f};
  // Particle lighting normal = normalize(mix(sphere normal, bed normal, bend)), in [0, 1]: 0 is
  // pure sphere shading; 0.7 keeps each splat's roundness while a bed's slopes (a crater's
  // walls, a heap's flanks) light like slopes. The bed normal is estimated from a depth
  // pre-pass of the granules, particle_bed_scale radii to each side of a pixel ([1, 32]); where
  // there is none, the terrain's normal under the particle.
  float particle_normal_bend = 0.7f;
  float particle_bed_scale = 4.0f;
  // Granule colour variation: each granule's albedo is scaled by 1 + v u, u uniform in
  // [-1, 1] from a hash of its index (0 = every granule alike), in [0, 0.5].
  float particle_color_variation = 0.12f;
  // Granule brightness gain in [0.5, 2]: spheres lit by a low sun, with the shade of their
  // neighbours below the equator, are darker on average than the smooth heightfield they were
  // cut from; the gain brings a bed's mean brightness back to the terrain's (measured in
  // tests/render/particle_renderer_test.cpp, FadedInPatchLooksLikeTheHeightfield).
  float particle_gain = 1.12f;
  // Screen-space ambient occlusion (shaders/render/ao.frag): radius (m, world) of the
  // neighbourhood a pixel looks at, > 0; strength in [0, 4] (0 = off); samples per pixel in [1, 64].
  float ao_radius = 1.0f;
  float ao_strength = 1.5f;
  int ao_samples = 16;
  // Bodies cast shadows on the terrain and the granules: an orthographic depth map of the
  // bodies seen from the sun, this many texels a side over their bounding sphere; 0 = none,
  // else in [256, 8192].
  int shadow_map_size = 2048;
  // The terrain shadows itself: each terrain pixel marches this many steps toward the sun
  // through the clipmap's heights (steps growing from two sample spacings by a fifth each, so 32
  // reach about 700 spacings), a soft edge from the nearest miss; 0 = none, else in [8, 64].
  int terrain_shadow_steps = 32;
};

// A camera in world coordinates (m), y up.
struct CameraView {
  Eigen::Vector3d position{0, 10, 0};
  Eigen::Vector3d target{1, 0, 1};
  float fov_deg = 60;       // vertical field of view, in (0, 180)
  int width = 128;          // pixels, [1, 16384]
  int height = 96;
  // Clip planes (m); 0 = automatic: far reaches the farthest terrain corner, near = a quarter of
  // the height above the terrain clamped to [0.01, 10].
  float near_m = 0;
  float far_m = 0;
};
// Errors name the field ("camera.fov_deg = 190: must be in (0, 180) degrees").
Status validate(const CameraView& c);

struct RenderStats {
  std::int64_t terrain_triangles = 0;  // clipmap triangles of one terrain pass
  int terrain_passes = 0;              // 1, or 2 with particles (Leach's order)
  int pieces = 0;                      // clipmap pieces drawn per pass
  int culled_pieces = 0;               // pieces skipped (frustum or terrain extent)
  int active_levels = 0;
  std::int64_t texels_uploaded = 0;    // clipmap texels written for this frame (toroidal + dirty)
  std::int64_t particles = 0;          // splats drawn
  int bodies = 0;                      // rigid bodies drawn
  std::int64_t body_triangles = 0;
  bool shadows = false;                // the bodies' shadow map was drawn
  double frame_ms = 0;                 // wall time of the frame including glFinish (CPU time on llvmpipe)
};

// What one frame draws besides the terrain and the particles set.
struct FrameFlags {
  bool bodies = true;     // the bodies set with set_bodies()
  bool body_ids = false;  // bodies unlit in body_id_color(k) (render/body_renderer.hpp), no ambient occlusion: for tests
};

class SceneRenderer {
 public:
  // hf must outlive the renderer; ctx must be current on this thread. Errors name the
  // RendererDef field (clipmap.*), or carry the shader compiler's log.
  static Result<std::unique_ptr<SceneRenderer>> create(gl::Context& ctx, const Heightfield& hf,
                                                       const RendererDef& def = {});
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  // Renders one frame and reads it back (top row first). The context given to create() must be
  // current on the calling thread.
  Result<Image> render(const CameraView& camera, const FrameFlags& flags = {});
  // render() and save_png() (atomic: temporary file + rename). Errors name the path.
  Status render_png(const CameraView& camera, const std::string& path, const FrameFlags& flags = {});

  // Where the world point p (m) lands in render(camera)'s image: pixel coordinates (x to the
  // right, y down, pixel centres at +0.5) and the eye distance (m); nullopt when p is behind
  // the camera. Same matrices as render() (automatic clip planes included).
  struct Projected {
    Eigen::Vector2d pixel;
    double depth_m = 0;
  };
  std::optional<Projected> project(const CameraView& camera, const Eigen::Vector3d& p) const;

  // The heightfield samples in `dirty` changed (a demoted patch, a track): only the clipmap
  // texels that depend on them are rewritten (now; the context must be current).
  void heightfield_changed(GridRegion dirty);

  // Particle patches to draw from now on (replaces the previous set). The buffers are the
  // caller's and must stay alive while set. Errors name the source and field; nothing changes
  // on error.
  Status set_particles(const std::vector<ParticleSource>& sources);
  void clear_particles() { particles_.clear(); }

  // Rigid bodies to draw from now on (replaces the previous set; copied). Errors name the body
  // and field (bodies[k].radius); nothing changes on error.
  Status set_bodies(std::vector<BodyInstance> bodies);
  void clear_bodies() { bodies_.clear(); }
  // Lighter or fuller frames without a new renderer (the viewer's --quality): the ambient
  // occlusion's strength (in [0, 4], 0 = off) and the bodies' shadow map size (0 = none, else
  // in [256, 8192] texels a side), and the terrain's shadow march (steps, 0 = none, else in
  // [8, 64]). Errors name the field; nothing changes then.
  Status set_effects(float ao_strength, int shadow_map_size, int terrain_shadow_steps);

  RenderStats stats() const { return stats_; }
  const RendererDef& def() const { return def_; }
  TerrainRenderer& terrain() { return *terrain_; }
  const std::string& renderer_string() const;  // GL_RENDERER of the context

 private:
  SceneRenderer() = default;
  void ensure_framebuffer(int w, int h);
  struct Matrices {
    Eigen::Matrix4f view, proj;
    Eigen::Vector3f eye;  // local m
  };
  Matrices matrices(const CameraView& cam) const;
  // Draws the bodies' shadow map (when there are bodies to draw and shadows are on).
  ShadowMap shadow_pass(const Eigen::Vector3d& origin);

  gl::Context* ctx_ = nullptr;
  const Heightfield* hf_ = nullptr;
  RendererDef def_;
  std::unique_ptr<TerrainRenderer> terrain_;
  std::unique_ptr<ParticleRenderer> particle_renderer_;
  std::unique_ptr<BodyRenderer> body_renderer_;
  gl::Program ao_program_;
  gl::Program bed_blur_program_;
  std::vector<ParticleSource> particles_;
  std::vector<BodyInstance> bodies_;
  // The scene renders into fbo_ (colour and depth textures); the ambient-occlusion pass reads
  // them and writes ao_fbo_ (colour renderbuffer), which is read back.
  unsigned fbo_ = 0, color_tex_ = 0, depth_tex_ = 0, bed_tex_ = 0, ao_fbo_ = 0, ao_rb_ = 0, empty_vao_ = 0;
  unsigned shadow_fbo_ = 0, shadow_tex_ = 0;
  // The granule bed smoothed (bed_blur.frag): bed_tex_ blurred across into bed_mid_tex_, then
  // down into bed_smooth_tex_ (R32F window depths), through bed_fbo_.
  unsigned bed_fbo_ = 0, bed_mid_tex_ = 0, bed_smooth_tex_ = 0;
  // Smooths bed_tex_ into bed_smooth_tex_ (w x h pixels); radius: m, the drawn sphere radius.
  void smooth_bed(const Eigen::Matrix4f& proj, int w, int h, float radius);
  int fb_w_ = 0, fb_h_ = 0;
  std::int64_t pending_texels_ = 0;  // written by heightfield_changed() since the last frame
  RenderStats stats_;
};

// The number of levels for which the coarsest level covers the whole terrain from any viewer
// position on it: the smallest L with (n - 1) s_0 2^(L-1) >= 2 max(extent_x, extent_z), at most 24.
int auto_levels(const ClipmapDef& def, const Heightfield& hf);

// ---- `sandpatch bench render` ----
// For each terrain size N (N x N samples, 1 m spacing, procedural hills): triangles per frame
// and frame time of the clipmap renderer and of a full-resolution grid of the same terrain,
// same camera, same run. Prints a table; with json the last line is one JSON object
// {"renderer": ..., "results": [{"terrain": N, "clipmap_triangles": ..., "full_grid_triangles": ...,
//   "clipmap_ms": ..., "full_grid_ms": ...}, ...]}. Frame times are wall times with glFinish
// (on llvmpipe they are CPU times).
struct BenchRenderArgs {
  std::vector<int> terrains;  // empty = {1024, 2048, 4096, 8192}
  int frames = 3;             // timed frames per renderer and size (median reported), >= 1
  int width = 640, height = 360;
  bool json = false;
};
// Exit code: 0 ok, 1 runtime failure, 2 bad input. Prints to stdout (errors to stderr).
int run_bench_render(const BenchRenderArgs& args);

}  // namespace sandpatch::render
