// tests render/clipmap.cpp: the footprint tiles each level exactly, levels nest, culling,
// triangle counts independent of terrain size, toroidal and dirty-rectangle bookkeeping.
#include "render/clipmap.hpp"

#include <gtest/gtest.h>

#include <map>
#include <set>

#include "render/camera.hpp"

using namespace sandpatch;
using namespace sandpatch::render;

namespace {

ClipmapDef small_def(int n = 31, int levels = 5) {
  ClipmapDef d;
  d.n = n;
  d.levels = levels;
  d.base_spacing = 1.0f;
  d.height_factor = 0;  // every level active
  return d;
}

// Culling off, a terrain extending far beyond the levels; the viewer at (1000 + x, 1000 + z).
ClipmapView open_view(float x, float z) {
  ClipmapView v;
  v.viewer = {1000 + x, 10, 1000 + z};
  v.cull = false;
  v.extent_x = v.extent_z = 1e9f;
  v.min_height = -1;
  v.max_height = 1;
  v.ground_height = 0;
  return v;
}

// Per level: how many times each cell (level coordinates of its min corner) is covered.
std::map<int, std::map<std::pair<int, int>, int>> coverage(const ClipmapSelection& sel) {
  std::map<int, std::map<std::pair<int, int>, int>> c;
  for (const auto& p : sel.pieces) {
    if (p.kind == PieceKind::DegenerateX || p.kind == PieceKind::DegenerateZ) continue;
    for (int j = 0; j < p.cells_z; ++j)
      for (int i = 0; i < p.cells_x; ++i) ++c[p.level][{p.gx + i, p.gz + j}];
  }
  return c;
}

}  // namespace

// A bad n names the field and the allowed values.
TEST(Clipmap, ValidateNamesTheField) {
  ClipmapDef d;
  d.n = 100;
  auto st = validate(d);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("clipmap.n = 100"), std::string::npos) << st.message();
  d = ClipmapDef{};
  d.levels = 0;
  EXPECT_NE(validate(d).message().find("clipmap.levels"), std::string::npos);
  EXPECT_TRUE(validate(ClipmapDef{}).ok());
}

// The finest level is a complete n x n grid, each cell drawn once; every coarser level covers
// its n x n window minus exactly the finer level's window, each cell once (no gaps, no overlap).
TEST(Clipmap, FootprintTilesEachLevelExactly) {
  for (int n : {15, 31, 63}) {
    const ClipmapDef d = small_def(n, 5);
    for (float vx : {0.0f, 0.5f, 1.3f, 2.7f, -5.2f, 37.9f}) {
      for (float vz : {0.0f, 3.1f, -11.6f}) {
        ClipmapSelection sel;
        select_clipmap(d, open_view(vx, vz), sel);
        auto cov = coverage(sel);
        for (int l = 0; l < d.levels; ++l) {
          const auto& lv = sel.levels[std::size_t(l)];
          ASSERT_EQ(lv.origin_x % 2, 0);
          ASSERT_EQ(lv.origin_z % 2, 0);
          // Expected cells: the window, minus the finer window (in this level's units).
          std::set<std::pair<int, int>> hole;
          if (l > 0) {
            const auto& in = sel.levels[std::size_t(l - 1)];
            for (int j = 0; j < n - 1; j += 2)
              for (int i = 0; i < n - 1; i += 2) hole.insert({(in.origin_x + i) / 2, (in.origin_z + j) / 2});
          }
          int covered = 0;
          for (int j = 0; j < n - 1; ++j) {
            for (int i = 0; i < n - 1; ++i) {
              const std::pair<int, int> c{lv.origin_x + i, lv.origin_z + j};
              const int times = cov[l].count(c) ? cov[l][c] : 0;
              const int want = hole.count(c) ? 0 : 1;
              ASSERT_EQ(times, want) << "n " << n << " level " << l << " cell " << c.first << "," << c.second
                                     << " viewer " << vx << "," << vz;
              covered += times;
            }
          }
          // Nothing outside the window.
          int total = 0;
          for (const auto& [c, t] : cov[l]) total += t;
          EXPECT_EQ(total, covered);
        }
      }
    }
  }
}

// The viewer stays within one cell of each level's centre, and the transition band (alpha = 1
// at distance (n-1)/2 - 1) reaches every border vertex.
TEST(Clipmap, LevelsAreCentredOnTheViewer) {
  const ClipmapDef d = small_def(63, 6);
  for (double v : {-100.7, -3.0, 0.0, 0.99, 1.0, 17.5, 1234.25}) {
    for (int l = 0; l < d.levels; ++l) {
      const double s = level_spacing(d, l);
      const int o = level_origin(d, l, v);
      const double centre = (o + (d.n - 1) / 2.0) * s;
      EXPECT_LE(std::abs(v - centre), s + 1e-9) << "level " << l << " v " << v;
      EXPECT_GE(v / s - o, (d.n - 1) / 2.0 - 1 - 1e-9);
      EXPECT_GE(o + d.n - 1 - v / s, (d.n - 1) / 2.0 - 1 - 1e-9);
    }
  }
}

// Triangles per level are fixed by n: 2 (n-1)^2 for the complete finest level, and
// 2 ((n-1)^2 - (n-1 - ... )) for rings: equal to 2 * (window cells - hole cells) + 2 (n-1).
TEST(Clipmap, TriangleCountIsFixedByTheLayout) {
  const ClipmapDef d = small_def(31, 4);
  ClipmapSelection sel;
  select_clipmap(d, open_view(3.3f, -7.1f), sel);
  const std::int64_t window = 30 * 30, hole = 15 * 15;
  const std::int64_t degenerate = 2 * 30;
  EXPECT_EQ(sel.triangles, 2 * window + degenerate + 3 * (2 * (window - hole) + degenerate));
  EXPECT_EQ(sel.culled_pieces, 0);
}

// Same camera over a 512^2 and an 8192^2 terrain (1 m spacing): the same pieces, the same
// triangles. The far plane (150 m; frustum corners reach ~205 m) keeps the view inside the
// small terrain.
TEST(Clipmap, TriangleCountIndependentOfTerrainSize) {
  ClipmapDef d;
  d.n = 127;
  d.levels = 10;
  d.base_spacing = 1;
  const Eigen::Vector3f eye(256.3f, 25.0f, 255.7f), target(330.0f, 0.0f, 320.0f);
  const Eigen::Matrix4f vp = perspective(60, 4.0f / 3.0f, 0.5f, 150.0f) * look_at(eye, target);
  std::int64_t tris[2];
  std::size_t pieces[2];
  int k = 0;
  for (float extent : {511.0f, 8191.0f}) {
    ClipmapView v;
    v.viewer = eye;
    v.view_proj = vp;
    v.extent_x = v.extent_z = extent;
    v.min_height = -5;
    v.max_height = 5;
    ClipmapSelection sel;
    select_clipmap(d, v, sel);
    tris[k] = sel.triangles;
    pieces[k] = sel.pieces.size();
    ++k;
  }
  EXPECT_EQ(tris[0], tris[1]);
  EXPECT_EQ(pieces[0], pieces[1]);
  EXPECT_GT(tris[0], 0);
  std::printf("clipmap triangles at the test view: %lld (%zu pieces)\n", (long long)tris[0], pieces[0]);
}

// Looking away from most of the clipmap culls most pieces; a box behind the camera is outside.
TEST(Clipmap, FrustumCullingSkipsPiecesOutOfView) {
  ClipmapDef d;
  d.n = 63;
  d.levels = 6;
  d.base_spacing = 1;
  d.height_factor = 0;
  ClipmapView v = open_view(0, 0);
  v.viewer = {1000, 5, 1000};
  v.cull = true;
  v.view_proj = perspective(40, 1.0f, 0.1f, 1000.0f) * look_at(v.viewer, {1010, 4, 1000});
  ClipmapSelection culled, all;
  select_clipmap(d, v, culled);
  v.cull = false;
  select_clipmap(d, v, all);
  EXPECT_LT(culled.triangles, all.triangles / 2);
  EXPECT_GT(culled.culled_pieces, 0);
  const auto planes = frustum_planes(perspective(40, 1.0f, 0.1f, 1000.0f) * look_at({0, 5, 0}, {10, 4, 0}));
  EXPECT_TRUE(box_outside(planes, {-20, -1, -1}, {-10, 1, 1}));   // behind
  EXPECT_FALSE(box_outside(planes, {20, 2, -1}, {30, 5, 1}));     // ahead
}

// The terrain's extent culls pieces beyond it.
TEST(Clipmap, PiecesOutsideTheTerrainAreSkipped) {
  const ClipmapDef d = small_def(31, 5);
  ClipmapView v = open_view(1, 1);
  v.viewer = {1, 10, 1};
  v.extent_x = v.extent_z = 10;
  ClipmapSelection sel;
  select_clipmap(d, v, sel);
  EXPECT_GT(sel.culled_pieces, 0);
  for (const auto& p : sel.pieces) {
    const float s = level_spacing(d, p.level);
    EXPECT_GE((p.gx + p.cells_x) * s, 0);
    EXPECT_LE(p.gx * s, 10);
  }
}

// Fine levels are skipped when the viewer is high above the terrain (Asirvatham's active levels).
TEST(Clipmap, HighViewerSkipsFineLevels) {
  ClipmapDef d = small_def(31, 6);
  d.height_factor = 2.5f;
  ClipmapView v = open_view(0, 0);
  v.viewer.y() = 200;  // 2.5 * 200 = 500 m: level extents 30, 60, 120, 240, 480, 960 m
  ClipmapSelection sel;
  select_clipmap(d, v, sel);
  for (int l = 0; l < 5; ++l) EXPECT_FALSE(sel.levels[std::size_t(l)].active) << l;
  EXPECT_TRUE(sel.levels[5].active && sel.levels[5].finest);
}

// A level that moves by (dx, dz) writes exactly the vertices that entered it, each once.
TEST(Clipmap, ToroidalUpdatesCoverEnteringVerticesOnce) {
  const int n = 31;
  const LevelRect before{10, -4, n, n};
  for (auto [dx, dz] : std::vector<std::pair<int, int>>{{0, 0}, {2, 0}, {0, -2}, {4, 6}, {-2, 2}, {-40, 0}, {100, 100}}) {
    const LevelRect now{before.x0 + dx, before.z0 + dz, n, n};
    std::map<std::pair<int, int>, int> hits;
    const auto rects = toroidal_updates(before, now);
    EXPECT_LE(rects.size(), 2u);
    for (const auto& r : rects)
      for (int j = 0; j < r.nz; ++j)
        for (int i = 0; i < r.nx; ++i) ++hits[{r.x0 + i, r.z0 + j}];
    for (int j = now.z0; j < now.z0 + n; ++j) {
      for (int i = now.x0; i < now.x0 + n; ++i) {
        const bool was = i >= before.x0 && i < before.x0 + n && j >= before.z0 && j < before.z0 + n;
        const std::pair<int, int> key{i, j};
        const int got = hits.count(key) ? hits[key] : 0;
        ASSERT_EQ(got, was ? 0 : 1) << dx << "," << dz;
      }
    }
    std::size_t total = 0;
    for (auto& [c, t] : hits) total += std::size_t(t);
    EXPECT_EQ(total, hits.size());
  }
  EXPECT_EQ(toroidal_updates(LevelRect{}, before), std::vector<LevelRect>{before});
}

// Wrapping a level rectangle into a T x T texture: the pieces cover it once and land on
// distinct texels, at g mod T.
TEST(Clipmap, WrapRectSplitsAtTheTextureEdge) {
  const int T = 32;
  for (const LevelRect r : {LevelRect{-5, 7, 31, 31}, LevelRect{30, 30, 4, 5}, LevelRect{0, 0, 32, 32}, LevelRect{-64, 3, 1, 1}}) {
    std::set<std::pair<int, int>> texels;
    int count = 0;
    for (const auto& t : wrap_rect(r, T)) {
      for (int j = 0; j < t.nz; ++j) {
        for (int i = 0; i < t.nx; ++i) {
          const int gx = r.x0 + t.src_x + i, gz = r.z0 + t.src_z + j;
          EXPECT_EQ(t.tx + i, ((gx % T) + T) % T);
          EXPECT_EQ(t.tz + j, ((gz % T) + T) % T);
          texels.insert({t.tx + i, t.tz + j});
          ++count;
        }
      }
    }
    EXPECT_EQ(count, r.nx * r.nz);
    EXPECT_EQ(texels.size(), std::size_t(count));
  }
}

// A dirty heightfield region maps to the level vertices that read it (one sample of margin),
// clipped to the window; edge regions stand for the clamped outside.
TEST(Clipmap, DirtyRegionMapsToLevelVertices) {
  ClipmapDef d = small_def(31, 3);
  const LevelRect window{-10, -10, 31, 31};
  // Samples [4, 6) x [4, 5) at 1 m: vertices of level 0 in [3, 6] x [3, 5].
  EXPECT_EQ(dirty_level_rect(d, 0, window, 4, 4, 2, 1, 1.0f, 100, 100), (LevelRect{3, 3, 4, 3}));
  // Level 1 (2 m): x in [3, 6] m -> g in [2, 3]; z in [3, 5] m -> g in [2, 2].
  EXPECT_EQ(dirty_level_rect(d, 1, window, 4, 4, 2, 1, 1.0f, 100, 100), (LevelRect{2, 2, 2, 1}));
  // Sample 0 also stands for x < 0: everything left of the window's x = 1 m.
  EXPECT_EQ(dirty_level_rect(d, 0, window, 0, 4, 1, 1, 1.0f, 100, 100), (LevelRect{-10, 3, 12, 3}));
  // Outside the window: nothing.
  EXPECT_TRUE(dirty_level_rect(d, 0, window, 50, 50, 2, 2, 1.0f, 100, 100).empty());
}
