// RGBA8 images: PNG files (libpng's simplified API) written atomically, and per-pixel error
// statistics for comparing a rendering with a stored reference.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/error.hpp"

namespace sandpatch::render {

// Row-major RGBA8, top row first (as in a PNG file).
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgba;  // width * height * 4 bytes
  const std::uint8_t* pixel(int x, int y) const { return &rgba[(std::size_t(y) * width + x) * 4]; }
};

// Writes an 8-bit RGBA PNG through a temporary file in the same directory renamed over
// `path`, so readers never see half a file. Errors name the path.
Status save_png(const std::string& path, const Image& image);
// Reads any PNG as 8-bit RGBA (sRGB). Errors name the path and libpng's message.
Result<Image> load_png(const std::string& path);

// Per-pixel error statistics over the R, G and B channels, in 8-bit units (0..255).
// The per-pixel error is the largest absolute difference of the three channels.
struct ImageDiff {
  double mean_abs = 0;      // mean over pixels of the per-pixel error
  double p99 = 0;           // 99th percentile of the per-pixel error
  int max_abs = 0;          // largest per-pixel error
  double frac_over_32 = 0;  // fraction of pixels whose error exceeds 32
};
// a and b must have the same size (asserted). An optional mask (width * height bytes, nonzero
// = counted) restricts the statistics to some pixels.
ImageDiff compare_images(const Image& a, const Image& b, const std::vector<std::uint8_t>* mask = nullptr);

}  // namespace sandpatch::render
