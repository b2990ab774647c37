// Particles -> heightfield by a top-down orthographic depth render (Leach & Marais §5.2).
//
// 1. render():  the patch's spheres are drawn from above into a depth buffer of
//    resolution² texels (default 1024², far finer than the particle spacing), through the
//    one headless EGL context (GPU or llvmpipe). Each sphere writes the depth of its upper
//    surface; the depth test keeps the highest. For the linear orthographic depth z in [0, 1]
//    of a camera at height y_c with near n and far f:  height = y_c − n − z (f − n).
//    The far plane is the patch floor, so a texel no particle covers reads as the floor.
// 2. write_to_heightfield(): each heightfield sample of the region takes the mean height of
//    the texels under its bilinear hat (2 spacings wide, weights falling linearly), the region
//    is smoothed with the 3×3 Gaussian, and then a 3×3 Gaussian band along its border
//    stitches it into the untouched terrain around it.
#pragma once

#include <algorithm>
#include <memory>
#include <vector>

#include "common/error.hpp"
#include "gl/program.hpp"
#include "heightfield/heightfield.hpp"

namespace sandpatch {

// Heights (m, heightfield-local) on a regular grid of texels over [x0, x1] × [z0, z1];
// texel (u, v) has its centre at x0 + (u + ½)(x1 − x0)/width, z0 + (v + ½)(z1 − z0)/height.
struct HeightImage {
  int width = 0, height = 0;
  float x0 = 0, z0 = 0, x1 = 0, z1 = 0;  // m, local
  std::vector<float> h;                 // width × height, u fastest
  float at(int u, int v) const { return h[std::size_t(v) * width + u]; }
  // Mean of the texels whose centres lie in [x − hx, x + hx] × [z − hz, z + hz] (at least the
  // nearest texel).
  float box_mean(float x, float z, float hx, float hz) const;
  // Mean weighted by the bilinear "hat" of a heightfield sample at (x, z) with spacing sp:
  // w = (1 − |x' − x|/sp)(1 − |z' − z|/sp) over the texels within sp (clipped to the image).
  // This is the value of that sample which best fits the image with the heightfield's own
  // bilinear surface (lumped least squares), and it averages granular roughness over 2.25×
  // the effective area of a one-cell box.
  float hat_mean(float x, float z, float sp) const;
};

struct DepthConversionDef {
  int resolution = 1024;  // texels per side of the depth render (Leach & Marais used 1024)
};

class ParticleDepthRenderer {
 public:
  // Needs the GL context (gl::Context) current on the calling thread.
  static Result<std::unique_ptr<ParticleDepthRenderer>> create(const DepthConversionDef& def = {});
  ~ParticleDepthRenderer();
  ParticleDepthRenderer(const ParticleDepthRenderer&) = delete;
  ParticleDepthRenderer& operator=(const ParticleDepthRenderer&) = delete;

  // spheres: n × (x, y, z, radius), m, heightfield-local. The rectangle [x0, x1] × [z0, z1]
  // is imaged; floor_y and top_y (m) bound the heights (top_y above every sphere top).
  // `resolution` texels a side, at most resolution() (0: resolution()).
  Result<HeightImage> render(const float* spheres_xyzr, std::size_t n, float x0, float z0, float x1, float z1,
                             float floor_y, float top_y, int resolution = 0);
  // The same with `width` texels along x and `height` along z (rows), each at most
  // resolution() (0: resolution()).
  Result<HeightImage> render(const float* spheres_xyzr, std::size_t n, float x0, float z0, float x1, float z1,
                             float floor_y, float top_y, int width, int height);

  int resolution() const { return resolution_; }

 private:
  ParticleDepthRenderer() = default;
  int resolution_ = 0;
  gl::Program program_;
  unsigned fbo_ = 0, depth_tex_ = 0, vao_ = 0, ssbo_ = 0;
  std::size_t ssbo_bytes_ = 0;
};

// The same image computed on the CPU (each sphere rasterised over the texels it covers,
// keeping the highest top): the fallback when no GL context can be made, and the reference
// the GL path is tested against.
HeightImage render_heights_cpu(const float* spheres_xyzr, std::size_t n, int resolution, float x0, float z0, float x1,
                               float z1, float floor_y);
// The same with `width` texels along x and `height` along z (rows).
HeightImage render_heights_cpu(const float* spheres_xyzr, std::size_t n, int width, int height, float x0, float z0,
                               float x1, float z1, float floor_y);
// Rows [v0, v1) of that image into `image` (made by render_heights_cpu's caller with every
// texel at the floor, or by an earlier band): a render spread over frames, band by band,
// gives the image of one whole render.
void render_heights_cpu_rows(const float* spheres_xyzr, std::size_t n, HeightImage& image, int v0, int v1);

// The surface a probe ball of radius `probe` (m) resting on the spheres would feel, as
// rendered from spheres drawn with their radius grown by `probe`: lowers every covered
// texel by `probe` (never below `floor_y`). A plain depth render of a granular bed sees
// through every vertical slot between rows of spheres — at the tile seams of a patch fill
// (manager/granule_tile.hpp) down to the floor — while the inflated spheres bridge slots
// narrower than about 2·probe and leave a smooth bed's mean height unchanged up to a
// constant that the fill calibrates (docs/manager.md has the measurements).
void lower_by_probe(HeightImage& image, float floor_y, float probe);
// One texel of it: a covered texel (above the floor) lowered by `probe`, never below the floor.
inline float probe_lowered(float h, float floor_y, float probe) {
  return probe > 0 && h > floor_y ? std::max(floor_y, h - probe) : h;
}

// What the region looked like when its patch was filled: the fill's own granules rendered
// the same way (same rectangle, resolution and probe) and the heightfield's values then.
// A depth render of granules misses the continuous surface they were cut to by a pattern
// of ±0.26 d at the sample scale (whole granules are wider than a heightfield cell); where
// the granules have not moved, the same pattern is in both renders and cancels.
struct RenderBaseline {
  const HeightImage* image = nullptr;          // the fill, rendered
  const std::vector<float>* heights = nullptr; // region's heights at promotion (ni × nj, i fastest)
  float tolerance = 0;                         // m: a smoothed change this large counts as moved
  float rise = 0;                              // m: how far the fill's top rises at rest with nothing on it
                                               // (the cut bed's elastic rebound, GranuleTile::rebound)
};

// Writes `image` into `region` of `hf` (hat-weighted means, 3×3 Gaussian over the region,
// then a Gaussian band of `border_width` samples along the region's border).
// With a baseline, each sample blends two estimates by how far the surface moved:
//   a = G(P)                      Leach & Marais §5.2: the rendered surface, smoothed
//   b = h₀ + G(P − P₀ − rise)     the old height plus the smoothed change of the render
//   h = w b + (1 − w) a,  w = max(0, 1 − |G(P − P₀ − rise)| / tolerance)
// (P, P₀: hat means of the image and of the baseline's image; G: the 3×3 Gaussian, changes
// taken as zero outside the region). Undisturbed ground comes back as it was, so patches
// can come and go over the same place without roughening it; where granules moved (a
// crater, a rim) the rendered surface is taken as Leach takes it.
// What write_to_heightfield wrote at each of its steps (region values, ni × nj, i fastest; m,
// heightfield-local), for the ledger's terms (demotion_ledger.cpp close_ledger): the hat means of the
// image, of the baseline's image (empty without one), and the values after the Gaussian /
// baseline blend (before the border band) and the blend's weights w (empty without a baseline).
struct WriteStages {
  std::vector<float> hat, hat_baseline, blended, weight;
};

// The hat means write_to_heightfield takes of an image over a region (ni × nj, i fastest; m,
// heightfield-local): computed apart (hat_means) they let a demotion spread that work over a
// frame of its own (docs/manager.md "No frame does a whole patch's work").
std::vector<float> hat_means(const HeightImage& image, GridRegion region, float spacing);
struct HatMeans {
  const std::vector<float>* image = nullptr;     // of the image (hat_means), or null: computed here
  const std::vector<float>* baseline = nullptr;  // of the baseline's image, or null: computed here
};

void write_to_heightfield(const HeightImage& image, GridRegion region, Heightfield& hf, int border_width = 1,
                          const RenderBaseline* baseline = nullptr, WriteStages* stages = nullptr,
                          HatMeans means = {});

}  // namespace sandpatch
