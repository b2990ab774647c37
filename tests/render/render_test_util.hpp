// Shared by the GL image tests of render/: terrains, reference-image comparison.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <string>

#include "gl/context.hpp"
#include "heightfield/procedural.hpp"
#include "render/image.hpp"
#include "render/render.hpp"

namespace sandpatch::render::test {

inline std::unique_ptr<gl::Context> make_context() {
  auto ctx = gl::Context::create();
  EXPECT_TRUE(ctx.ok()) << ctx.message();
  return ctx.ok() ? std::move(ctx.value()) : nullptr;
}

inline Heightfield terrain(int n, float spacing, const ProceduralHeightsDef& p) {
  HeightfieldDef g;
  g.samples_x = g.samples_z = n;
  g.spacing = spacing;
  g.tile_cells = 128;
  auto hf = make_procedural(g, p);
  EXPECT_TRUE(hf.ok()) << hf.message();
  return std::move(hf.value());
}

inline ProceduralHeightsDef plane(float sx, float sz, float h = 0) {
  ProceduralHeightsDef p;
  p.kind = sx == 0 && sz == 0 ? "flat" : "plane";
  p.height = h;
  p.slope_x = sx;
  p.slope_z = sz;
  return p;
}

inline ProceduralHeightsDef hills(float amplitude, float wavelength) {
  ProceduralHeightsDef p;
  p.kind = "hills";
  p.amplitude = amplitude;
  p.wavelength = wavelength;
  return p;
}

// Pixels exactly equal to the background colour.
inline int background_pixels(const Image& img, const std::array<std::uint8_t, 3>& bg) {
  int count = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const std::uint8_t* p = img.pixel(x, y);
      count += p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2];
    }
  return count;
}

// Reference-image tolerances (8-bit units; docs/rendering.md): the same renderer gives 0; a
// different rasteriser (GPU vs llvmpipe) differs on edges and in noise texture minification.
inline constexpr double kRefMeanAbs = 3.0;
inline constexpr double kRefP99 = 48.0;

inline bool updating_references() {
  const char* e = std::getenv("SANDPATCH_UPDATE_REFERENCES");
  return e && std::string(e) == "1";
}

// Where a test writes a picture for inspection: <test output dir>/<file>, the directory made if
// missing (a test binary may run from a copy of the tree without its build folder).
inline std::string output_path(const std::string& file) {
  std::error_code ec;
  std::filesystem::create_directories(SANDPATCH_TEST_OUTPUT_DIR, ec);
  return std::string(SANDPATCH_TEST_OUTPUT_DIR) + "/" + file;
}

// Compares img with tests/render/reference/<name>.png; with SANDPATCH_UPDATE_REFERENCES=1,
// writes it there instead. The rendering is always written beside the test binary
// (<name>.actual.png) for inspection.
inline void expect_matches_reference(const Image& img, const std::string& name) {
  const std::string ref = std::string(SANDPATCH_TEST_DATA_DIR) + "/reference/" + name + ".png";
  const std::string actual = output_path(name + ".actual.png");
  ASSERT_TRUE(save_png(actual, img).ok());
  if (updating_references()) {
    std::filesystem::create_directories(std::filesystem::path(ref).parent_path());
    auto st = save_png(ref, img);
    ASSERT_TRUE(st.ok()) << st.message();
    std::printf("updated reference %s\n", ref.c_str());
    return;
  }
  auto stored = load_png(ref);
  ASSERT_TRUE(stored.ok()) << stored.message()
                           << "(regenerate with: SANDPATCH_UPDATE_REFERENCES=1 ctest --test-dir <build> -R render_)";
  ASSERT_EQ(stored->width, img.width);
  ASSERT_EQ(stored->height, img.height);
  const ImageDiff d = compare_images(img, stored.value());
  std::printf("%s vs reference: mean %.3f p99 %.1f max %d\n", name.c_str(), d.mean_abs, d.p99, d.max_abs);
  EXPECT_LE(d.mean_abs, kRefMeanAbs) << name << ": see " << actual;
  EXPECT_LE(d.p99, kRefP99) << name << ": see " << actual;
}

}  // namespace sandpatch::render::test
