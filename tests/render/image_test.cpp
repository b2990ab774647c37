// tests render/image.cpp: PNG round trip, atomic save, error statistics.
#include "render/image.hpp"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>

using namespace sandpatch::render;

namespace {
Image gradient(int w, int h) {
  Image img{w, h, std::vector<std::uint8_t>(std::size_t(w) * h * 4)};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      std::uint8_t* p = &img.rgba[(std::size_t(y) * w + x) * 4];
      p[0] = std::uint8_t(x * 255 / (w - 1));
      p[1] = std::uint8_t(y * 255 / (h - 1));
      p[2] = std::uint8_t((x + y) & 255);
      p[3] = 255;
    }
  return img;
}
}  // namespace

// Saved and loaded back byte for byte; no temporary file left behind.
TEST(Image, PngRoundTripIsExact) {
  const auto dir = std::filesystem::temp_directory_path() / "sandpatch_image_test";
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "g.png").string();
  const Image img = gradient(37, 21);
  ASSERT_TRUE(save_png(path, img).ok());
  auto back = load_png(path);
  ASSERT_TRUE(back.ok()) << back.message();
  EXPECT_EQ(back->width, 37);
  EXPECT_EQ(back->height, 21);
  EXPECT_EQ(back->rgba, img.rgba);
  int files = 0;
  for (auto& e : std::filesystem::directory_iterator(dir)) files += e.path().filename().string().find(".tmp-") != std::string::npos;
  EXPECT_EQ(files, 0);
  std::filesystem::remove_all(dir);
}

// Errors name the path; a bad directory leaves nothing.
TEST(Image, ErrorsNameThePath) {
  auto st = save_png("/nonexistent-dir/x.png", gradient(4, 4));
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("/nonexistent-dir/x.png"), std::string::npos);
  auto r = load_png("/nonexistent-dir/y.png");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("/nonexistent-dir/y.png"), std::string::npos);
}

// Statistics: identical images give zero; one pixel off by 100 in a 10x10 image gives
// mean 1, max 100, p99 100 (the 99th percentile of 100 values is the largest).
TEST(Image, CompareGivesErrorStatistics) {
  Image a = gradient(10, 10), b = a;
  auto d = compare_images(a, b);
  EXPECT_EQ(d.mean_abs, 0);
  EXPECT_EQ(d.max_abs, 0);
  b.rgba[4 * 55 + 1] = std::uint8_t(b.rgba[4 * 55 + 1] >= 100 ? b.rgba[4 * 55 + 1] - 100 : b.rgba[4 * 55 + 1] + 100);
  d = compare_images(a, b);
  EXPECT_DOUBLE_EQ(d.mean_abs, 1.0);
  EXPECT_EQ(d.max_abs, 100);
  EXPECT_EQ(d.p99, 100);
  EXPECT_DOUBLE_EQ(d.frac_over_32, 0.01);
  std::vector<std::uint8_t> mask(100, 1);
  mask[55] = 0;
  EXPECT_EQ(compare_images(a, b, &mask).max_abs, 0);
}
