// tests render/terrain_renderer.cpp: level textures hold the heightfield at each level's
// vertices; toroidal updates after a move give the same content as a fresh build and write
// only the entering texels; heightfield edits rewrite only the dirty texels.
#include "render/terrain_renderer.hpp"

#include <gtest/gtest.h>

#include "gl/context.hpp"
#include "heightfield/procedural.hpp"

using namespace sandpatch;
using namespace sandpatch::render;

namespace {

std::unique_ptr<gl::Context> make_context() {
  auto ctx = gl::Context::create();
  EXPECT_TRUE(ctx.ok()) << ctx.message();
  return ctx.ok() ? std::move(ctx.value()) : nullptr;
}

Heightfield noise_terrain(int n = 300) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = n;
  g.spacing = 0.5f;
  g.tile_cells = 64;
  ProceduralHeightsDef p;
  p.kind = "noise";
  p.amplitude = 5;
  p.wavelength = 20;
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << hf.message();
  return std::move(hf.value());
}

ClipmapDef test_def() {
  ClipmapDef d;
  d.n = 31;
  d.levels = 5;
  d.base_spacing = 0;  // = heightfield spacing
  return d;
}

// Texel values of one level's window, keyed by the vertex (so different toroidal
// placements compare equal when they hold the same data).
std::vector<float> window_values(const TerrainRenderer& r, int which, int level) {
  const auto tex = r.read_texture(which, level);
  const LevelRect w = r.windows()[std::size_t(level)];
  const int T = r.texture_size(), comps = which == 0 ? 1 : 4;
  std::vector<float> out;
  for (int j = 0; j < w.nz; ++j)
    for (int i = 0; i < w.nx; ++i) {
      const int tx = (((w.x0 + i) % T) + T) % T, tz = (((w.z0 + j) % T) + T) % T;
      for (int c = 0; c < comps; ++c) out.push_back(tex[(std::size_t(tz) * T + tx) * comps + c]);
    }
  return out;
}

}  // namespace

// Every texel of every level's window is the heightfield sampled at the vertex (exactly: the
// same float), including vertices beyond the grid's edge (clamped).
TEST(TerrainRenderer, LevelTexturesHoldTheHeightfield) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = noise_terrain();
  auto r = TerrainRenderer::create(hf, test_def());
  ASSERT_TRUE(r.ok()) << r.message();
  (*r)->update({10.3f, 7.0f, 12.9f});
  for (int l = 0; l < 5; ++l) {
    const auto v = window_values(**r, 0, l);
    const LevelRect w = (*r)->windows()[std::size_t(l)];
    const float s = hf.spacing() * float(1 << l);
    for (int j = 0; j < w.nz; ++j)
      for (int i = 0; i < w.nx; ++i)
        ASSERT_EQ(v[std::size_t(j) * w.nx + i], hf.sample(float(w.x0 + i) * s, float(w.z0 + j) * s)) << l;
  }
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// After a walk, the toroidally updated textures equal a fresh build at the final position, for
// elevation, normals and materials; a one-cell move writes only the L-shaped band.
TEST(TerrainRenderer, ToroidalUpdateMatchesFreshBuild) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  Heightfield hf = noise_terrain();
  hf.fill({40, 40, 30, 20}, 1.0f, Layer::Material2);  // a patch of soil
  auto moved = TerrainRenderer::create(hf, test_def());
  auto fresh = TerrainRenderer::create(hf, test_def());
  ASSERT_TRUE(moved.ok() && fresh.ok());
  const std::int64_t full = (*moved)->update({5.0f, 3.0f, 5.0f});
  EXPECT_EQ(full, 5 * 31 * 31);
  // Small steps, then a jump, then a step back.
  const std::vector<Eigen::Vector3f> path = {{5.6f, 3, 5.2f}, {6.4f, 3, 4.1f}, {9.9f, 3, 8.8f}, {30.2f, 3, 2.5f}, {29.0f, 3, 3.1f}};
  for (const auto& p : path) (*moved)->update(p);
  (*fresh)->update(path.back());
  ASSERT_EQ((*moved)->windows(), (*fresh)->windows());
  for (int which = 0; which < 3; ++which)
    for (int l = 0; l < 5; ++l) EXPECT_EQ(window_values(**moved, which, l), window_values(**fresh, which, l)) << which << " " << l;

  // Level 0 moves by 2 vertices in x when the viewer crosses a 2-cell boundary (1 m at 0.5 m
  // spacing): one 2 x 31 band is written; the other levels do not move.
  auto r = TerrainRenderer::create(hf, test_def());
  (*r)->update({20.1f, 3, 20.1f});
  EXPECT_EQ((*r)->update({21.1f, 3, 20.1f}), 2 * 31);
  EXPECT_EQ((*r)->update({21.2f, 3, 20.2f}), 0);
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Editing the heightfield and reporting the region rewrites only the texels that depend on it,
// and the result equals a fresh build of the edited heightfield.
TEST(TerrainRenderer, DirtyRegionRewritesOnlyThoseTexels) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  Heightfield hf = noise_terrain();
  auto r = TerrainRenderer::create(hf, test_def());
  ASSERT_TRUE(r.ok());
  const Eigen::Vector3f viewer(12, 3, 12);
  (*r)->update(viewer);
  const GridRegion dirty{20, 22, 4, 3};
  hf.fill(dirty, 9.0f);
  const std::int64_t written = (*r)->heightfield_changed(dirty);
  EXPECT_GT(written, 0);
  EXPECT_LT(written, 100);  // a handful per level, not whole levels (5 x 961)
  auto fresh = TerrainRenderer::create(hf, test_def());
  (*fresh)->update(viewer);
  for (int which = 0; which < 3; ++which)
    for (int l = 0; l < 5; ++l) EXPECT_EQ(window_values(**r, which, l), window_values(**fresh, which, l)) << which << " " << l;
  EXPECT_EQ(gl::Context::drain_errors(), "");
}

// Bad definitions come back as errors naming the field.
TEST(TerrainRenderer, BadDefinitionIsRefused) {
  auto ctx = make_context();
  ASSERT_TRUE(ctx);
  const Heightfield hf = noise_terrain(64);
  ClipmapDef d = test_def();
  d.n = 30;
  auto r = TerrainRenderer::create(hf, d);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("clipmap.n"), std::string::npos);
}
