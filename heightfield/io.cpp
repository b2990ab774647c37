// Heightmap import / export (PNG, raw float32, ESRI ASCII grid). Leach & Marais §3 start
// from a heightmap loaded into the terrain manager; the formats here are the common ones
// terrain tools export. PNG goes through libpng directly: reading uses the low-level API
// (so gamma chunks are ignored and sample values arrive untouched), with every setjmp
// confined to small functions that hold only plain C data; writing uses the simplified
// png_image API (16-bit linear greyscale), which needs no setjmp at all.
#include "heightfield/io.hpp"

#include "common/limits.hpp"

#include <png.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <vector>

namespace sandpatch {
namespace {

Error file_error(const std::string& path, std::string field, std::string value, std::string allowed) {
  return Error{path, std::move(field), std::move(value), std::move(allowed), ""};
}

// Heightfield::create errors name a def field; say which file the numbers came from.
std::vector<Error> in_file(const std::string& path, std::vector<Error> errs) {
  for (Error& e : errs)
    if (e.file.empty()) e.file = path;
  return errs;
}

// Checks the import fields that Heightfield::create does not see.
std::vector<Error> check_import(const std::string& path, const HeightmapImport& im) {
  std::vector<Error> errs;
  if (!std::isfinite(im.vertical_scale))
    errs.push_back(file_error(path, "import.vertical_scale", format_number(im.vertical_scale), "must be finite (m)"));
  if (!std::isfinite(im.vertical_offset))
    errs.push_back(file_error(path, "import.vertical_offset", format_number(im.vertical_offset), "must be finite (m)"));
  return errs;
}

HeightfieldDef def_from(const HeightmapImport& im, int nx, int nz) {
  HeightfieldDef d;
  d.samples_x = nx;
  d.samples_z = nz;
  d.spacing = im.spacing;
  d.origin_x = im.origin_x;
  d.origin_y = im.origin_y;
  d.origin_z = im.origin_z;
  d.tile_cells = im.tile_cells;
  return d;
}

// Creates the heightfield and fills it row by row: value(i, j) gives the stored number,
// mapped through offset + scale * value in double.
template <class F>
Result<Heightfield> build(const std::string& path, const HeightfieldDef& def, const HeightmapImport& im, F value) {
  auto created = Heightfield::create(def);
  if (!created) return in_file(path, created.errors());
  Heightfield hf = std::move(created).value();
  std::vector<float> row(static_cast<std::size_t>(def.samples_x));
  for (int j = 0; j < def.samples_z; ++j) {
    for (int i = 0; i < def.samples_x; ++i)
      row[std::size_t(i)] = static_cast<float>(double(im.vertical_offset) + double(im.vertical_scale) * value(i, j));
    hf.write({0, j, def.samples_x, 1}, row.data());
  }
  return hf;
}

// ---- atomic save: temporary file in the same directory, then rename ----

// body writes the content and returns "" or what went wrong.
Status write_atomically(const std::string& path, const std::function<std::string(std::FILE*)>& body) {
  static std::atomic<unsigned> counter{0};
  const std::string tmp = path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (!f)
    return file_error(path, "", "", "cannot create temporary file " + tmp + ": " + std::strerror(errno));
  std::string problem = body(f);
  if (problem.empty() && std::fflush(f) != 0) problem = std::string("write failed: ") + std::strerror(errno);
  if (problem.empty() && std::ferror(f)) problem = "write failed";
  if (problem.empty() && ::fsync(::fileno(f)) != 0) problem = std::string("fsync failed: ") + std::strerror(errno);
  if (std::fclose(f) != 0 && problem.empty()) problem = std::string("close failed: ") + std::strerror(errno);
  if (problem.empty() && std::rename(tmp.c_str(), path.c_str()) != 0)
    problem = std::string("rename from ") + tmp + " failed: " + std::strerror(errno);
  if (!problem.empty()) {
    std::remove(tmp.c_str());
    return file_error(path, "", "", "not written: " + problem);
  }
  return Ok{};
}

bool read_whole_file(const std::string& path, std::string& out, std::string& problem) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) {
    problem = std::string("cannot open: ") + std::strerror(errno);
    return false;
  }
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) {
    std::fclose(f);
    problem = "cannot read file size: " + ec.message();
    return false;
  }
  try {
    out.resize(size);
  } catch (const std::bad_alloc&) {
    std::fclose(f);
    problem = "out of memory reading " + std::to_string(size) + " bytes";
    return false;
  }
  const std::size_t got = size ? std::fread(out.data(), 1, size, f) : 0;
  std::fclose(f);
  if (got != size) {
    problem = "read " + std::to_string(got) + " of " + std::to_string(size) + " bytes";
    return false;
  }
  return true;
}

// ---- PNG reading (low-level libpng). setjmp lives only in the two functions below,
// which hold nothing but plain C data, so the longjmp skips no C++ destructor. ----

struct PngErrorBuffer {
  char message[256] = "";
};

extern "C" void png_error_to_buffer(png_structp png, png_const_charp msg) {
  auto* e = static_cast<PngErrorBuffer*>(png_get_error_ptr(png));
  std::snprintf(e->message, sizeof e->message, "%s", msg ? msg : "libpng error");
  png_longjmp(png, 1);
}
extern "C" void png_ignore_warning(png_structp, png_const_charp) {}

struct PngHeader {
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, color_type = 0, interlace = 0;
};

bool png_read_header(png_structp png, png_infop info, std::FILE* f, PngHeader* h) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_init_io(png, f);
  png_set_sig_bytes(png, 8);
  png_set_user_limits(png, 1u << 20, 1u << 20);  // same bound as Heightfield's samples per axis
  png_read_info(png, info);
  png_get_IHDR(png, info, &h->width, &h->height, &h->bit_depth, &h->color_type, &h->interlace, nullptr, nullptr);
  return true;
}

// Reads grey samples as 8-bit or host-order 16-bit into rows[0..height).
bool png_read_pixels(png_structp png, png_infop info, const PngHeader* h, png_bytep* rows) {
  if (setjmp(png_jmpbuf(png))) return false;
  if (h->bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  if (h->color_type & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
  if (h->bit_depth == 16 && std::endian::native == std::endian::little) png_set_swap(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  png_read_image(png, rows);
  png_read_end(png, nullptr);
  return true;
}

struct PngReadGuard {
  png_structp png = nullptr;
  png_infop info = nullptr;
  std::FILE* f = nullptr;
  ~PngReadGuard() {
    if (png) png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    if (f) std::fclose(f);
  }
};

// ---- ESRI ASCII tokenizer ----

struct Cursor {
  const char* p;
  const char* end;
  int line = 1;
  // Next whitespace-separated token; false at the end of the text.
  bool next(std::string_view& tok, int& tok_line) {
    while (p < end && (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')) {
      if (*p == '\n') ++line;
      ++p;
    }
    if (p >= end) return false;
    const char* b = p;
    while (p < end && !(*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')) ++p;
    tok = std::string_view(b, std::size_t(p - b));
    tok_line = line;
    return true;
  }
};

bool parse_double(std::string_view s, double& v) {
  const char* b = s.data();
  const char* e = s.data() + s.size();
  if (b < e && *b == '+') ++b;  // from_chars does not take a leading '+'
  const auto r = std::from_chars(b, e, v);
  return r.ec == std::errc() && r.ptr == e;
}

std::string lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string shown(std::string_view tok) {  // a token quoted and cut for an error message
  std::string s(tok.substr(0, 40));
  if (tok.size() > 40) s += "...";
  return "'" + s + "'";
}

}  // namespace

// =============================== PNG ===============================

Result<Heightfield> load_png16(const std::string& path, const HeightmapImport& import) {
  if (auto errs = check_import(path, import); !errs.empty()) return errs;
  PngReadGuard g;
  g.f = std::fopen(path.c_str(), "rb");
  if (!g.f) return file_error(path, "", "", std::string("cannot open: ") + std::strerror(errno));
  // ---- signature ----
  unsigned char sig[8];
  if (std::fread(sig, 1, 8, g.f) != 8 || png_sig_cmp(sig, 0, 8) != 0)
    return file_error(path, "", "", "not a PNG file (bad or missing PNG signature)");
  // ---- header ----
  PngErrorBuffer err;
  g.png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &err, png_error_to_buffer, png_ignore_warning);
  if (!g.png) return file_error(path, "", "", "libpng could not create a reader");
  g.info = png_create_info_struct(g.png);
  if (!g.info) return file_error(path, "", "", "libpng could not create a reader");
  PngHeader h;
  if (!png_read_header(g.png, g.info, g.f, &h))
    return file_error(path, "", "", std::string("corrupt or truncated PNG header: ") + err.message);
  if (h.color_type & PNG_COLOR_MASK_COLOR || h.color_type & PNG_COLOR_MASK_PALETTE)
    return file_error(path, "colour type", std::to_string(h.color_type),
                      "must be greyscale (with or without alpha); heightmaps are single-channel");
  if (h.width < 2 || h.height < 2)
    return file_error(path, "size", std::to_string(h.width) + " x " + std::to_string(h.height),
                      "must be at least 2 x 2 pixels");
  // The grid cap from the header alone, before a pixel buffer is allocated.
  if (auto e = limits::check_grid_size(path, "width × height", h.width, h.height)) return *e;
  // ---- pixels ----
  const std::size_t bytes_per_sample = h.bit_depth == 16 ? 2 : 1;
  const std::size_t row_bytes = std::size_t(h.width) * bytes_per_sample;
  std::vector<unsigned char> pixels;
  std::vector<png_bytep> rows;
  try {
    pixels.resize(row_bytes * h.height);
    rows.resize(h.height);
  } catch (const std::bad_alloc&) {
    return file_error(path, "size", std::to_string(h.width) + " x " + std::to_string(h.height),
                      "out of memory reading the image");
  }
  for (png_uint_32 r = 0; r < h.height; ++r) rows[r] = pixels.data() + r * row_bytes;
  if (!png_read_pixels(g.png, g.info, &h, rows.data()))
    return file_error(path, "", "", std::string("corrupt or truncated PNG image data: ") + err.message);
  // ---- heights: row -> z, column -> x ----
  const double vmax = h.bit_depth == 16 ? 65535.0 : double((1 << std::min(h.bit_depth, 8)) - 1);
  const int nx = int(h.width), nz = int(h.height);
  return build(path, def_from(import, nx, nz), import, [&](int i, int j) {
    const unsigned char* p = rows[std::size_t(j)] + std::size_t(i) * bytes_per_sample;
    if (bytes_per_sample == 2) {
      std::uint16_t v;
      std::memcpy(&v, p, 2);
      return double(v) / vmax;
    }
    return double(*p) / vmax;
  });
}

Status save_png16(const std::string& path, const Heightfield& hf, float* out_offset, float* out_scale) {
  // ---- normalise min..max to 0..65535 ----
  const float lo = hf.min_height(), hi = hf.max_height();
  if (!std::isfinite(lo) || !std::isfinite(hi))
    return file_error(path, "heights", format_number(lo) + " .. " + format_number(hi), "must be finite to be saved");
  const double range = double(hi) - double(lo);
  const int nx = hf.samples_x(), nz = hf.samples_z();
  std::vector<png_uint_16> px(std::size_t(nx) * nz);
  std::vector<float> row(static_cast<std::size_t>(nx));
  for (int j = 0; j < nz; ++j) {
    hf.read({0, j, nx, 1}, row.data());
    for (int i = 0; i < nx; ++i) {
      const double t = range > 0 ? (double(row[std::size_t(i)]) - lo) / range : 0.0;
      px[std::size_t(j) * nx + i] = static_cast<png_uint_16>(std::lround(std::clamp(t, 0.0, 1.0) * 65535.0));
    }
  }
  // ---- write through the simplified API ----
  Status st = write_atomically(path, [&](std::FILE* f) -> std::string {
    png_image img;
    std::memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    img.width = png_uint_32(nx);
    img.height = png_uint_32(nz);
    img.format = PNG_FORMAT_LINEAR_Y;  // 16-bit greyscale, native-endian png_uint_16 in memory
    const int ok = png_image_write_to_stdio(&img, f, 0, px.data(), 0, nullptr);
    std::string problem = ok ? "" : std::string("libpng: ") + img.message;
    png_image_free(&img);
    return problem;
  });
  if (!st) return st;
  if (out_offset) *out_offset = lo;
  if (out_scale) *out_scale = static_cast<float>(range);
  return Ok{};
}

// =============================== raw float32 ===============================

Result<Heightfield> load_raw_f32(const std::string& path, int samples_x, int samples_z,
                                 const HeightmapImport& import) {
  if (auto errs = check_import(path, import); !errs.empty()) return errs;
  // Dimensions first, so the size check below cannot overflow.
  std::vector<Error> dim_errs;
  if (samples_x < 2 || samples_x > (1 << 20) + 1)
    dim_errs.push_back(file_error(path, "samples_x", std::to_string(samples_x), "must be in [2, 1048577]"));
  if (samples_z < 2 || samples_z > (1 << 20) + 1)
    dim_errs.push_back(file_error(path, "samples_z", std::to_string(samples_z), "must be in [2, 1048577]"));
  if (!dim_errs.empty()) return dim_errs;
  if (auto e = limits::check_grid_size(path, "samples_x × samples_z", samples_x, samples_z)) return *e;
  // ---- size, checked before anything is read ----
  const std::size_t n = std::size_t(samples_x) * std::size_t(samples_z);
  std::error_code ec;
  const auto size = std::filesystem::file_size(path, ec);
  if (ec) return file_error(path, "", "", "cannot open: " + ec.message());
  if (size != n * 4)
    return file_error(path, "file size", std::to_string(size) + " bytes",
                      "must be samples_x * samples_z * 4 = " + std::to_string(samples_x) + " * " +
                          std::to_string(samples_z) + " * 4 = " + std::to_string(n * 4) + " bytes");
  std::string bytes, problem;
  if (!read_whole_file(path, bytes, problem)) return file_error(path, "", "", problem);
  if (bytes.size() != n * 4) return file_error(path, "", "", "file changed size while being read");
  // ---- decode little-endian, refuse non-finite ----
  std::vector<float> v(n);
  for (std::size_t k = 0; k < n; ++k) {
    std::uint32_t u;
    std::memcpy(&u, bytes.data() + 4 * k, 4);
    if constexpr (std::endian::native == std::endian::big) u = __builtin_bswap32(u);
    std::memcpy(&v[k], &u, 4);
    if (!std::isfinite(v[k]))
      return file_error(path, "sample " + std::to_string(k) + " (i = " + std::to_string(k % samples_x) +
                                  ", j = " + std::to_string(k / samples_x) + ")",
                        format_number(v[k]), "must be finite");
  }
  return build(path, def_from(import, samples_x, samples_z), import,
               [&](int i, int j) { return double(v[std::size_t(j) * samples_x + i]); });
}

Status save_raw_f32(const std::string& path, const Heightfield& hf) {
  return write_atomically(path, [&](std::FILE* f) -> std::string {
    const int nx = hf.samples_x();
    std::vector<float> row(static_cast<std::size_t>(nx));
    std::vector<std::uint32_t> le(static_cast<std::size_t>(nx));
    for (int j = 0; j < hf.samples_z(); ++j) {
      hf.read({0, j, nx, 1}, row.data());
      for (int i = 0; i < nx; ++i) {
        std::uint32_t u;
        std::memcpy(&u, &row[std::size_t(i)], 4);
        if constexpr (std::endian::native == std::endian::big) u = __builtin_bswap32(u);
        le[std::size_t(i)] = u;
      }
      if (std::fwrite(le.data(), 4, le.size(), f) != le.size())
        return std::string("write failed: ") + std::strerror(errno);
    }
    return "";
  });
}

// =============================== ESRI ASCII grid ===============================

Result<Heightfield> load_esri_ascii(const std::string& path, const HeightmapImport& import) {
  if (auto errs = check_import(path, import); !errs.empty()) return errs;
  std::string text, problem;
  if (!read_whole_file(path, text, problem)) return file_error(path, "", "", problem);
  Cursor cur{text.data(), text.data() + text.size()};
  auto at_line = [](int line) { return "line " + std::to_string(line); };

  // ---- header: "key value" pairs until the first token that is not a known key ----
  double ncols = NAN, nrows = NAN, xll = NAN, yll = NAN, cellsize = NAN, nodata = NAN;
  bool x_corner = false, y_corner = false, have_x = false, have_y = false, have_nodata = false;
  std::string_view tok;
  int line = 0;
  bool have_tok = cur.next(tok, line);
  while (have_tok && !tok.empty() && (std::isalpha(static_cast<unsigned char>(tok[0])))) {
    const std::string key = lower(tok);
    if (key == "nan" || key == "inf" || key == "infinity") break;  // data, not a key
    static const char* const keys[] = {"ncols", "nrows", "xllcorner", "xllcenter", "yllcorner",
                                       "yllcenter", "cellsize", "nodata_value"};
    if (std::find(std::begin(keys), std::end(keys), key) == std::end(keys))
      return file_error(path, at_line(line), shown(tok),
                        "unknown header key; allowed: ncols, nrows, xllcorner, xllcenter, yllcorner, yllcenter, "
                        "cellsize, NODATA_value");
    std::string_view val;
    int vline = 0;
    if (!cur.next(val, vline)) return file_error(path, at_line(line) + ": " + key, "", "has no value");
    double v;
    if (!parse_double(val, v) || !std::isfinite(v))
      return file_error(path, at_line(vline) + ": " + key, shown(val), "must be a finite number");
    if (key == "ncols") ncols = v;
    else if (key == "nrows") nrows = v;
    else if (key == "xllcorner" || key == "xllcenter") { xll = v; x_corner = key == "xllcorner"; have_x = true; }
    else if (key == "yllcorner" || key == "yllcenter") { yll = v; y_corner = key == "yllcorner"; have_y = true; }
    else if (key == "cellsize") cellsize = v;
    else { nodata = v; have_nodata = true; }  // nodata_value
    have_tok = cur.next(tok, line);
  }
  std::vector<Error> errs;
  auto need_int = [&](const char* key, double v) {
    if (std::isnan(v)) errs.push_back(file_error(path, key, "", "missing from the header"));
    else if (v != std::floor(v) || v < 2 || v > 1048577)
      errs.push_back(file_error(path, key, format_number(v), "must be an integer in [2, 1048577]"));
  };
  need_int("ncols", ncols);
  need_int("nrows", nrows);
  if (!have_x) errs.push_back(file_error(path, "xllcorner", "", "missing from the header (or xllcenter)"));
  if (!have_y) errs.push_back(file_error(path, "yllcorner", "", "missing from the header (or yllcenter)"));
  if (std::isnan(cellsize)) errs.push_back(file_error(path, "cellsize", "", "missing from the header"));
  else if (!(cellsize > 0)) errs.push_back(file_error(path, "cellsize", format_number(cellsize), "must be > 0 (m)"));
  if (!errs.empty()) return errs;
  if (auto e = limits::check_grid_size(path, "ncols × nrows", std::int64_t(ncols), std::int64_t(nrows))) return *e;
  // The grid's geometry must be a float one: cellsize and the corner within the float range the
  // heightfield keeps (origin and extent in m).
  if (!import.override_spacing && !(cellsize <= 1e4))
    return file_error(path, "cellsize", format_number(cellsize), "must be in (0, 10000] m");
  if (!(std::abs(xll) <= 1e9) || !(std::abs(yll) <= 1e9))
    return file_error(path, std::abs(xll) <= 1e9 ? (y_corner ? "yllcorner" : "yllcenter") : (x_corner ? "xllcorner" : "xllcenter"),
                      format_number(std::abs(xll) <= 1e9 ? yll : xll), "must be in [-1e9, 1e9] m (the scene's world coordinates)");

  // ---- data: nrows x ncols numbers, first row northernmost ----
  const int nc = int(ncols), nr = int(nrows);
  std::vector<float> v;
  try {
    v.resize(std::size_t(nc) * nr);
  } catch (const std::bad_alloc&) {
    return file_error(path, "ncols x nrows", std::to_string(nc) + " x " + std::to_string(nr), "out of memory");
  }
  for (std::size_t k = 0; k < v.size(); ++k) {
    const int r = int(k / std::size_t(nc)), c = int(k % std::size_t(nc));
    auto where = [&] { return at_line(line) + ", row " + std::to_string(r) + ", col " + std::to_string(c); };
    if (!have_tok)
      return file_error(path, "data", std::to_string(k) + " values",
                        "expected nrows * ncols = " + std::to_string(v.size()) + " values (file truncated?)");
    double d;
    if (!parse_double(tok, d)) return file_error(path, where(), shown(tok), "must be a number");
    if (have_nodata && d == nodata)
      return file_error(path, where(), shown(tok), "is NODATA; NODATA cells are not supported (fill them first)");
    const float f = static_cast<float>(double(import.vertical_offset) + double(import.vertical_scale) * d);
    if (!std::isfinite(f)) return file_error(path, where(), shown(tok), "must be a finite height");
    v[k] = f;
    have_tok = cur.next(tok, line);
  }
  if (have_tok)
    return file_error(path, at_line(line), shown(tok),
                      "more values than nrows * ncols = " + std::to_string(v.size()));

  // ---- geometry: sample (0,0) is the centre of the south-west cell ----
  // xllcorner / yllcorner is the outer edge of the grid; the half-cell step inward uses the
  // spacing actually used (the override when given, else cellsize), so the grid's edge stays
  // on the corner whatever the spacing. xllcenter / yllcenter names sample (0,0) itself: no
  // step. The corner / centre value itself is taken as is (m), not rescaled by the override.
  HeightmapImport im = import;
  if (!import.override_spacing) im.spacing = static_cast<float>(cellsize);
  const double half = double(im.spacing) / 2;
  im.origin_x = import.origin_x + xll + (x_corner ? half : 0.0);
  im.origin_z = import.origin_z + yll + (y_corner ? half : 0.0);
  im.vertical_offset = 0;  // already applied above
  im.vertical_scale = 1;
  return build(path, def_from(im, nc, nr), im,
               [&](int i, int j) { return double(v[std::size_t(nr - 1 - j) * nc + i]); });
}

Status save_esri_ascii(const std::string& path, const Heightfield& hf) {
  return write_atomically(path, [&](std::FILE* f) -> std::string {
    const int nx = hf.samples_x(), nz = hf.samples_z();
    std::fprintf(f, "ncols %d\nnrows %d\nxllcenter %.17g\nyllcenter %.17g\ncellsize %.9g\n", nx, nz,
                 hf.origin_x(), hf.origin_z(), double(hf.spacing()));
    std::vector<float> row(static_cast<std::size_t>(nx));
    std::string line;
    for (int j = nz - 1; j >= 0; --j) {  // northernmost (largest z) first
      hf.read({0, j, nx, 1}, row.data());
      line.clear();
      char buf[32];
      for (int i = 0; i < nx; ++i) {
        std::snprintf(buf, sizeof buf, i ? " %.9g" : "%.9g", double(row[std::size_t(i)]));
        line += buf;
      }
      line += '\n';
      if (std::fwrite(line.data(), 1, line.size(), f) != line.size())
        return std::string("write failed: ") + std::strerror(errno);
    }
    return "";
  });
}

}  // namespace sandpatch
