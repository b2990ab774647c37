// Drawing on an RGBA8 image on the CPU, for `sandpatch view`'s overlay: filled rectangles
// blended over the picture, line segments, and text in a built-in 5 x 7 pixel bitmap font
// (digits, capitals, common punctuation; lower case drawn as capitals). No GL, no font files.
// Everything is clipped to the image: any coordinates are safe.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include <Eigen/Core>

#include "render/image.hpp"

namespace sandpatch::render {

using Rgb = std::array<std::uint8_t, 3>;

// A glyph cell is kGlyphW x kGlyphH font pixels plus one column and one row of spacing; each
// font pixel is drawn as scale x scale image pixels.
inline constexpr int kGlyphW = 5, kGlyphH = 7;
inline constexpr int kCellW = kGlyphW + 1, kCellH = kGlyphH + 2;

// The 7 rows of a character's glyph, bit 4 the leftmost column; characters outside the font
// give '?''s glyph, lower case the capital's.
std::array<std::uint8_t, kGlyphH> glyph(char c);
// Width and height in image pixels of `text` on one line at `scale` (>= 1).
int text_width(std::string_view text, int scale);
inline int line_height(int scale) { return kCellH * scale; }

// Blends `color` over the rectangle [x, x + w) x [y, y + h) with opacity alpha in [0, 1].
void fill_rect(Image& img, int x, int y, int w, int h, Rgb color, float alpha = 1.0f);
// A segment from a to b (pixel coordinates, x right, y down), `thickness` pixels wide (>= 1).
// Non-finite end points draw nothing.
void draw_line(Image& img, Eigen::Vector2d a, Eigen::Vector2d b, Rgb color, int thickness = 1);
// `text` with its top-left corner at (x, y); returns its width in pixels.
int draw_text(Image& img, int x, int y, std::string_view text, Rgb color, int scale = 1);

}  // namespace sandpatch::render
