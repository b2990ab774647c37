// PNG I/O through libpng's simplified (png_image) API, which needs no setjmp.
#include "render/image.hpp"

#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>

namespace sandpatch::render {

Status save_png(const std::string& path, const Image& img) {
  if (img.width <= 0 || img.height <= 0 || img.rgba.size() != std::size_t(img.width) * img.height * 4)
    return Error{path, "", "", "", "image to save has no pixels or a wrong buffer size"};
  png_image pi;
  std::memset(&pi, 0, sizeof pi);
  pi.version = PNG_IMAGE_VERSION;
  pi.width = png_uint_32(img.width);
  pi.height = png_uint_32(img.height);
  pi.format = PNG_FORMAT_RGBA;
  // Encode to memory first so a failure leaves no file at all.
  png_alloc_size_t size = 0;
  if (!png_image_write_to_memory(&pi, nullptr, &size, 0, img.rgba.data(), 0, nullptr)) {
    std::string msg = pi.message;
    png_image_free(&pi);
    return Error{path, "", "", "", "PNG encoding failed: " + msg};
  }
  std::vector<std::uint8_t> bytes(size);
  if (!png_image_write_to_memory(&pi, bytes.data(), &size, 0, img.rgba.data(), 0, nullptr)) {
    std::string msg = pi.message;
    png_image_free(&pi);
    return Error{path, "", "", "", "PNG encoding failed: " + msg};
  }
  bytes.resize(size);
  static std::atomic<unsigned> counter{0};
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f) return Error{path, "", "", "", "cannot create temporary file " + tmp + ": " + std::strerror(errno)};
  std::string problem;
  if (std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) problem = std::string("write failed: ") + std::strerror(errno);
  if (std::fclose(f) != 0 && problem.empty()) problem = std::string("close failed: ") + std::strerror(errno);
  if (problem.empty() && std::rename(tmp.c_str(), path.c_str()) != 0)
    problem = std::string("rename from ") + tmp + " failed: " + std::strerror(errno);
  if (!problem.empty()) {
    std::remove(tmp.c_str());
    return Error{path, "", "", "", problem};
  }
  return Ok{};
}

Result<Image> load_png(const std::string& path) {
  png_image pi;
  std::memset(&pi, 0, sizeof pi);
  pi.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&pi, path.c_str())) {
    std::string msg = pi.message;
    png_image_free(&pi);
    return Error{path, "", "", "", "cannot read PNG: " + msg};
  }
  pi.format = PNG_FORMAT_RGBA;
  Image img;
  img.width = int(pi.width);
  img.height = int(pi.height);
  img.rgba.resize(PNG_IMAGE_SIZE(pi));
  if (!png_image_finish_read(&pi, nullptr, img.rgba.data(), 0, nullptr)) {
    std::string msg = pi.message;
    png_image_free(&pi);
    return Error{path, "", "", "", "cannot decode PNG: " + msg};
  }
  return img;
}

ImageDiff compare_images(const Image& a, const Image& b, const std::vector<std::uint8_t>* mask) {
  assert(a.width == b.width && a.height == b.height);
  std::vector<int> err;
  err.reserve(std::size_t(a.width) * a.height);
  for (int y = 0; y < a.height; ++y) {
    for (int x = 0; x < a.width; ++x) {
      if (mask && !(*mask)[std::size_t(y) * a.width + x]) continue;
      const std::uint8_t *p = a.pixel(x, y), *q = b.pixel(x, y);
      int e = 0;
      for (int c = 0; c < 3; ++c) e = std::max(e, std::abs(int(p[c]) - int(q[c])));
      err.push_back(e);
    }
  }
  ImageDiff d;
  if (err.empty()) return d;
  double sum = 0;
  int over = 0;
  for (int e : err) {
    sum += e;
    d.max_abs = std::max(d.max_abs, e);
    over += e > 32;
  }
  d.mean_abs = sum / double(err.size());
  d.frac_over_32 = double(over) / double(err.size());
  const std::size_t k = std::min(err.size() - 1, std::size_t(0.99 * double(err.size())));
  std::nth_element(err.begin(), err.begin() + std::ptrdiff_t(k), err.end());
  d.p99 = err[k];
  return d;
}

}  // namespace sandpatch::render
