// tests render/overlay.cpp: the bitmap font, blending, lines and clipping of the viewer's overlay.
#include "render/overlay.hpp"

#include <gtest/gtest.h>

#include <bitset>
#include <climits>
#include <cmath>
#include <set>

using namespace sandpatch::render;

namespace {

Image black(int w, int h) {
  Image img;
  img.width = w, img.height = h;
  img.rgba.assign(std::size_t(w) * h * 4, 0);
  for (std::size_t k = 3; k < img.rgba.size(); k += 4) img.rgba[k] = 255;
  return img;
}

int lit(const Image& img) {
  int n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) n += img.pixel(x, y)[0] != 0;
  return n;
}

}  // namespace

TEST(Overlay, EveryDigitAndCapitalHasItsOwnGlyph) {
  const std::string chars = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.:-+/%()=";
  std::set<std::array<std::uint8_t, kGlyphH>> seen;
  for (char c : chars) {
    const auto g = glyph(c);
    EXPECT_TRUE(seen.insert(g).second) << "glyph of '" << c << "' repeats another";
    for (auto row : g) EXPECT_EQ(row & ~0x1F, 0) << c;  // 5 columns
  }
  EXPECT_EQ(glyph('a'), glyph('A'));
  EXPECT_EQ(glyph('~'), glyph('?'));  // outside the font
  for (auto row : glyph(' ')) EXPECT_EQ(row, 0);
}

// A glyph at scale s lights s² pixels per set font bit, where the font says, and nothing else.
TEST(Overlay, TextLightsExactlyItsGlyphsPixels) {
  Image img = black(40, 30);
  const int w = draw_text(img, 3, 2, "8", {255, 255, 255}, 2);
  EXPECT_EQ(w, kCellW * 2);
  EXPECT_EQ(w, text_width("8", 2));
  int bits = 0;
  for (auto row : glyph('8')) bits += int(std::bitset<8>(row).count());
  EXPECT_EQ(lit(img), bits * 4);
  // '8' has its top row's middle three bits set: pixels (3 + 2..7, 2..3).
  EXPECT_EQ(img.pixel(3 + 2, 2)[0], 255);
  EXPECT_EQ(img.pixel(3 + 7, 3)[0], 255);
  EXPECT_EQ(img.pixel(3 + 0, 2)[0], 0);
}

TEST(Overlay, RectanglesBlendAndClip) {
  Image img = black(10, 10);
  fill_rect(img, 2, 2, 3, 3, {255, 255, 255}, 0.5f);
  EXPECT_EQ(img.pixel(2, 2)[0], 128);  // 0 + 0.5 × 255 rounded
  EXPECT_EQ(img.pixel(5, 5)[0], 0);
  EXPECT_EQ(lit(img), 9);
  // Partly and wholly outside, and sizes that overflow an int: clipped, no crash.
  fill_rect(img, -5, -5, 7, 7, {255, 0, 0});
  EXPECT_EQ(img.pixel(1, 1)[0], 255);
  EXPECT_EQ(img.pixel(2, 2)[0], 128 + 0);  // not reached (x, y < 2 only)
  fill_rect(img, 8, 8, INT_MAX, INT_MAX, {255, 0, 0});
  EXPECT_EQ(img.pixel(9, 9)[0], 255);
  fill_rect(img, INT_MIN, INT_MIN, 5, 5, {255, 0, 0});
  draw_text(img, INT_MAX - 3, 0, "XYZ", {255, 255, 255}, 3);
  Image empty;
  fill_rect(empty, 0, 0, 5, 5, {1, 2, 3});  // no pixels: nothing drawn
  draw_text(empty, 0, 0, "A", {1, 2, 3});
}

TEST(Overlay, LinesJoinTheirEndsAndAreClipped) {
  Image img = black(20, 12);
  draw_line(img, {2.5, 5.5}, {17.5, 5.5}, {255, 255, 255}, 1);
  for (int x = 2; x <= 17; ++x) EXPECT_EQ(img.pixel(x, 5)[0], 255) << x;
  EXPECT_EQ(lit(img), 16);
  // Far-off ends (a point projected just behind the eye) are clipped first: one row, quickly.
  Image far = black(20, 12);
  draw_line(far, {-1e12, 3.5}, {1e12, 3.5}, {255, 255, 255}, 1);
  EXPECT_EQ(lit(far), 20);
  Image none = black(20, 12);
  draw_line(none, {NAN, 1}, {5, 5}, {255, 255, 255}, 3);
  draw_line(none, {-50, -50}, {-40, -60}, {255, 255, 255}, 3);  // wholly outside
  EXPECT_EQ(lit(none), 0);
  // Thickness t: a t-pixel band, its square pen reaching t / 2 (rounded down) past each end.
  Image thick = black(20, 12);
  draw_line(thick, {5.5, 1.5}, {5.5, 10.5}, {255, 255, 255}, 3);
  EXPECT_EQ(lit(thick), 3 * (10 + 2));
  EXPECT_EQ(thick.pixel(4, 0)[0], 255);
  EXPECT_EQ(thick.pixel(7, 5)[0], 0);
}
