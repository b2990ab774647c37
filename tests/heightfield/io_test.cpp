// Tests heightfield/io.cpp: round trips per format, axis mappings, atomic saves, and
// errors on missing, truncated and corrupt files (each names the file and the problem).
#include "heightfield/io.hpp"

#include <gtest/gtest.h>
#include <png.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <vector>

namespace sandpatch {
namespace {

namespace fs = std::filesystem;

class HeightfieldIo : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandpatch_hf_io_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  void write_text(const std::string& p, const std::string& text) const { std::ofstream(p, std::ios::binary) << text; }
  // Only the named files are in the directory (no temporary files left behind).
  std::size_t file_count() const {
    return std::size_t(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
  }

  fs::path dir_;
};

Heightfield random_field(int nx, int nz, float spacing, std::uint32_t seed, float lo, float hi) {
  HeightfieldDef d;
  d.samples_x = nx;
  d.samples_z = nz;
  d.spacing = spacing;
  d.tile_cells = 8;
  Heightfield hf = *Heightfield::create(d);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(lo, hi);
  for (int j = 0; j < nz; ++j)
    for (int i = 0; i < nx; ++i) hf.set_height(i, j, U(rng));
  return hf;
}

bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

// ---- PNG ----

TEST_F(HeightfieldIo, Png16RoundTripWithinQuantisation) {
  const Heightfield hf = random_field(37, 21, 0.5f, 1, -3.0f, 12.0f);
  float offset = 0, scale = 0;
  ASSERT_TRUE(save_png16(path("h.png"), hf, &offset, &scale).ok());
  EXPECT_EQ(file_count(), 1u);
  EXPECT_EQ(offset, hf.min_height());
  EXPECT_FLOAT_EQ(scale, hf.max_height() - hf.min_height());
  HeightmapImport im;
  im.spacing = 0.5f;
  im.vertical_offset = offset;
  im.vertical_scale = scale;
  im.tile_cells = 16;
  auto r = load_png16(path("h.png"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  ASSERT_EQ(r->samples_x(), 37);
  ASSERT_EQ(r->samples_z(), 21);
  // Rounding to the nearest of 65536 levels: error <= range / 65535 / 2, plus float round-off.
  const float tol = scale / 65535 / 2 + 1e-6f * 12;
  for (int j = 0; j < 21; ++j)
    for (int i = 0; i < 37; ++i) ASSERT_NEAR(r->height(i, j), hf.height(i, j), tol) << i << "," << j;
  // The extremes map exactly to 0 and 65535.
  EXPECT_NEAR(r->min_height(), hf.min_height(), 1e-6f * 12);
  EXPECT_NEAR(r->max_height(), hf.max_height(), 1e-5f * 12);
}

TEST_F(HeightfieldIo, Png8BitAcceptedRowsAreZ) {
  // 3 x 2 8-bit greyscale written with libpng: height = offset + scale * v / 255.
  const unsigned char px[6] = {0, 51, 255, 102, 153, 204};
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = 3;
  img.height = 2;
  img.format = PNG_FORMAT_GRAY;
  ASSERT_TRUE(png_image_write_to_file(&img, path("g8.png").c_str(), 0, px, 0, nullptr));
  HeightmapImport im;
  im.vertical_scale = 10;
  im.vertical_offset = 1;
  auto r = load_png16(path("g8.png"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_FLOAT_EQ(r->height(1, 0), 1 + 10 * 51 / 255.0f);  // row 0 -> z = 0, column 1 -> x = 1
  EXPECT_FLOAT_EQ(r->height(2, 0), 11.0f);
  EXPECT_FLOAT_EQ(r->height(0, 1), 1 + 10 * 102 / 255.0f);  // row 1 -> z = 1
}

TEST_F(HeightfieldIo, PngTruncatedIsAnErrorNamingFile) {
  const Heightfield hf = random_field(64, 64, 1, 2, 0, 1);
  ASSERT_TRUE(save_png16(path("t.png"), hf).ok());
  const auto size = fs::file_size(path("t.png"));
  for (std::uintmax_t keep : {std::uintmax_t(4), std::uintmax_t(20), std::uintmax_t(40), size / 2, size - 13}) {
    fs::copy_file(path("t.png"), path("cut.png"), fs::copy_options::overwrite_existing);
    fs::resize_file(path("cut.png"), keep);
    auto r = load_png16(path("cut.png"), {});
    ASSERT_FALSE(r.ok()) << "kept " << keep << " bytes";
    EXPECT_TRUE(contains(r.message(), path("cut.png"))) << r.message();
    EXPECT_TRUE(contains(r.message(), "truncated") || contains(r.message(), "not a PNG")) << r.message();
  }
}

TEST_F(HeightfieldIo, PngCorruptColourAndMissingAreErrors) {
  // Overwritten bytes in the image data: CRC error, reported, no crash.
  const Heightfield hf = random_field(32, 32, 1, 3, 0, 1);
  ASSERT_TRUE(save_png16(path("c.png"), hf).ok());
  {
    std::ifstream in(path("c.png"), std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const std::size_t idat = bytes.find("IDAT");
    ASSERT_NE(idat, std::string::npos);
    std::fstream f(path("c.png"), std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(std::streamoff(idat + 8));  // inside the compressed image data
    const char junk[16] = {'j', 'u', 'n', 'k', 'j', 'u', 'n', 'k', 'j', 'u', 'n', 'k', 'j', 'u', 'n', 'k'};
    f.write(junk, sizeof junk);
  }
  auto r = load_png16(path("c.png"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("c.png")) && contains(r.message(), "corrupt")) << r.message();

  write_text(path("text.png"), "this is not an image");
  r = load_png16(path("text.png"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("text.png")) && contains(r.message(), "not a PNG")) << r.message();

  const unsigned char rgb[2 * 2 * 3] = {};
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = img.height = 2;
  img.format = PNG_FORMAT_RGB;
  ASSERT_TRUE(png_image_write_to_file(&img, path("rgb.png").c_str(), 0, rgb, 0, nullptr));
  r = load_png16(path("rgb.png"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("rgb.png")) && contains(r.message(), "greyscale")) << r.message();

  r = load_png16(path("missing.png"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("missing.png")) && contains(r.message(), "cannot open")) << r.message();
}

TEST_F(HeightfieldIo, FlatFieldSavesWithZeroScale) {
  Heightfield hf = random_field(4, 4, 1, 1, 0, 0);
  hf.fill(hf.whole(), 2.5f);
  float offset = 0, scale = -1;
  ASSERT_TRUE(save_png16(path("flat.png"), hf, &offset, &scale).ok());
  EXPECT_EQ(offset, 2.5f);
  EXPECT_EQ(scale, 0.0f);
  HeightmapImport im;
  im.vertical_offset = offset;
  im.vertical_scale = scale;
  auto r = load_png16(path("flat.png"), im);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->max_height(), 2.5f);
  EXPECT_EQ(r->min_height(), 2.5f);
}

TEST_F(HeightfieldIo, PngRandomDamageNeverCrashes) {
  // 300 deterministic damaged copies (bytes overwritten, or cut at a random length): each
  // load either succeeds with a valid grid or fails naming the file. Run under the
  // sanitizers (SANDPATCH_SANITIZE) this is a small fuzzer for the libpng error paths.
  const Heightfield hf = random_field(24, 17, 1, 9, 0, 5);
  ASSERT_TRUE(save_png16(path("src.png"), hf).ok());
  std::ifstream in(path("src.png"), std::ios::binary);
  const std::string good((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::mt19937 rng(12345);
  for (int k = 0; k < 300; ++k) {
    std::string bad = good;
    if (k % 3 == 0) {
      bad.resize(std::uniform_int_distribution<std::size_t>(0, good.size() - 1)(rng));
    } else {
      const int flips = 1 + k % 4;
      for (int f = 0; f < flips; ++f)
        bad[std::uniform_int_distribution<std::size_t>(8, good.size() - 1)(rng)] = char(rng());
    }
    write_text(path("bad.png"), bad);
    auto r = load_png16(path("bad.png"), {});
    if (r.ok()) {
      EXPECT_EQ(r->samples_x(), 24);  // damage in an ancillary chunk is ignored
    } else {
      EXPECT_TRUE(contains(r.message(), path("bad.png"))) << r.message();
    }
  }
}

TEST_F(HeightfieldIo, EsriRandomDamageNeverCrashes) {
  const std::string good = "ncols 4\nnrows 3\nxllcorner 1\nyllcorner 2\ncellsize 0.5\nNODATA_value -9999\n"
                           "1 2 3 4\n5 6 7 8\n9 10 11 12\n";
  std::mt19937 rng(777);
  const char alphabet[] = "0123456789 .-+eEnaNidf\n\tx";
  for (int k = 0; k < 300; ++k) {
    std::string bad = good;
    for (int f = 0; f < 1 + k % 5; ++f)
      bad[std::uniform_int_distribution<std::size_t>(0, good.size() - 1)(rng)] =
          alphabet[std::uniform_int_distribution<std::size_t>(0, sizeof alphabet - 2)(rng)];
    write_text(path("bad.asc"), bad);
    auto r = load_esri_ascii(path("bad.asc"), {});
    if (r.ok()) {
      for (int j = 0; j < r->samples_z(); ++j)
        for (int i = 0; i < r->samples_x(); ++i) ASSERT_TRUE(std::isfinite(r->height(i, j)));
    } else {
      EXPECT_TRUE(contains(r.message(), path("bad.asc"))) << r.message();
    }
  }
}

// ---- raw float32 ----

TEST_F(HeightfieldIo, RawRoundTripIsExact) {
  const Heightfield hf = random_field(19, 23, 1, 4, -100, 100);
  ASSERT_TRUE(save_raw_f32(path("h.raw"), hf).ok());
  EXPECT_EQ(fs::file_size(path("h.raw")), 19u * 23 * 4);
  HeightmapImport im;
  im.tile_cells = 8;  // same geometry as random_field, so the hash compares everything
  auto r = load_raw_f32(path("h.raw"), 19, 23, im);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->hash(), hf.hash());
  // Little-endian, x fastest: bytes 4..8 are sample (1, 0).
  std::ifstream f(path("h.raw"), std::ios::binary);
  unsigned char b[8];
  f.read(reinterpret_cast<char*>(b), 8);
  const std::uint32_t u = b[4] | b[5] << 8 | b[6] << 16 | std::uint32_t(b[7]) << 24;
  float v;
  std::memcpy(&v, &u, 4);
  EXPECT_EQ(v, hf.height(1, 0));
}

TEST_F(HeightfieldIo, RawWrongSizeAndNaNAreErrors) {
  const Heightfield hf = random_field(8, 8, 1, 5, 0, 1);
  ASSERT_TRUE(save_raw_f32(path("h.raw"), hf).ok());
  auto r = load_raw_f32(path("h.raw"), 8, 9, {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("h.raw")) && contains(r.message(), "file size = 256 bytes") &&
              contains(r.message(), "288"))
      << r.message();

  std::vector<float> v(8 * 8, 1.0f);
  v[8 * 3 + 5] = std::nanf("");
  std::ofstream(path("nan.raw"), std::ios::binary).write(reinterpret_cast<const char*>(v.data()), 256);
  r = load_raw_f32(path("nan.raw"), 8, 8, {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("nan.raw")) && contains(r.message(), "sample 29 (i = 5, j = 3)") &&
              contains(r.message(), "finite"))
      << r.message();

  r = load_raw_f32(path("missing.raw"), 8, 8, {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("missing.raw")) && contains(r.message(), "cannot open")) << r.message();

  r = load_raw_f32(path("h.raw"), 1, 64, {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), "samples_x = 1")) << r.message();
}

// ---- ESRI ASCII ----

TEST_F(HeightfieldIo, EsriRoundTripWithinPrintedPrecision) {
  HeightfieldDef d;
  d.samples_x = 13;
  d.samples_z = 7;
  d.spacing = 2.5f;
  d.origin_x = 512345.25;
  d.origin_z = 6712345.75;
  d.tile_cells = 8;
  Heightfield hf = *Heightfield::create(d);
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> U(-50, 900);
  for (int j = 0; j < 7; ++j)
    for (int i = 0; i < 13; ++i) hf.set_height(i, j, U(rng));
  ASSERT_TRUE(save_esri_ascii(path("h.asc"), hf).ok());
  EXPECT_EQ(file_count(), 1u);
  HeightmapImport im;
  im.tile_cells = 8;
  auto r = load_esri_ascii(path("h.asc"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  // %.9g prints enough digits to read back the same float: exact, hash included.
  EXPECT_EQ(r->spacing(), 2.5f);
  EXPECT_EQ(r->origin_x(), d.origin_x);
  EXPECT_EQ(r->origin_z(), d.origin_z);
  EXPECT_EQ(r->hash(), hf.hash());
}

TEST_F(HeightfieldIo, EsriAxisMappingNorthIsPlusZ) {
  // First data row is the northernmost = largest z; xllcorner is the cell corner, so
  // sample (0,0) sits half a cell inside it.
  write_text(path("m.asc"),
             "NCOLS 3\nNROWS 2\nXLLCORNER 100\nYLLCORNER 200\nCELLSIZE 10\nNODATA_VALUE -9999\n"
             "1 2 3\n4 5 6\n");
  HeightmapImport im;
  im.vertical_scale = 2;
  im.vertical_offset = 0.5f;
  auto r = load_esri_ascii(path("m.asc"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->spacing(), 10.0f);
  EXPECT_EQ(r->origin_x(), 105.0);
  EXPECT_EQ(r->origin_z(), 205.0);
  EXPECT_EQ(r->height(0, 1), 0.5f + 2 * 1);  // first row, first column: north-west
  EXPECT_EQ(r->height(2, 1), 0.5f + 2 * 3);
  EXPECT_EQ(r->height(0, 0), 0.5f + 2 * 4);  // last row: south
  im.override_spacing = true;
  im.spacing = 1;
  r = load_esri_ascii(path("m.asc"), im);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->spacing(), 1.0f);
}

TEST_F(HeightfieldIo, EsriOverrideSpacingMovesTheHalfCellNotTheCorner) {
  // A 10 m-cell DEM made into a 0.6 m-spaced sand table: the grid's edge stays on the
  // corner, and sample (0,0) sits half of the spacing used (not of cellsize) inside it.
  // A centre-registered axis takes its value as is, whatever the spacing.
  write_text(path("o.asc"),
             "ncols 3\nnrows 2\nxllcorner 100\nyllcenter 200\ncellsize 10\n1 2 3\n4 5 6\n");
  HeightmapImport im;
  im.origin_x = -3;
  im.origin_z = 7;
  im.override_spacing = true;
  im.spacing = 0.6f;
  auto r = load_esri_ascii(path("o.asc"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->spacing(), 0.6f);
  EXPECT_DOUBLE_EQ(r->origin_x(), im.origin_x + 100 + double(im.spacing) / 2);
  EXPECT_DOUBLE_EQ(r->origin_z(), im.origin_z + 200);
  // Without the override the file's cellsize is the spacing and sets the half cell.
  im.override_spacing = false;
  r = load_esri_ascii(path("o.asc"), im);
  ASSERT_TRUE(r.ok()) << r.message();
  EXPECT_EQ(r->spacing(), 10.0f);
  EXPECT_DOUBLE_EQ(r->origin_x(), im.origin_x + 100 + 10.0 / 2);
  EXPECT_DOUBLE_EQ(r->origin_z(), im.origin_z + 200);
}

TEST_F(HeightfieldIo, EsriBadInputIsAnErrorNamingFileAndProblem) {
  struct Case {
    const char* name;
    const char* text;
    const char* problem;
  };
  const Case cases[] = {
      {"garbage.asc", "hello world\n1 2 3\n", "unknown header key"},
      {"nan.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 nan 6\n",
       "line 7, row 1, col 1 = 'nan': must be a finite height"},
      {"nodata.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\nnodata_value -9999\n1 2 3\n4 5 -9999\n",
       "row 1, col 2 = '-9999': is NODATA"},
      {"short.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5\n", "truncated"},
      {"long.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5 6 7\n", "more values"},
      {"word.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5 six\n", "must be a number"},
      {"nocols.asc", "nrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5 6\n", "ncols: missing"},
      {"badcell.asc", "ncols 3\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize -1\n1 2 3\n4 5 6\n", "cellsize = -1"},
      {"frac.asc", "ncols 2.5\nnrows 2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5 6\n", "ncols = 2.5"},
      {"empty.asc", "", "ncols: missing"},
      {"negrows.asc", "ncols 3\nnrows -2\nxllcenter 0\nyllcenter 0\ncellsize 1\n1 2 3\n4 5 6\n", "nrows = -2: must be an integer"},
  };
  auto missing = load_esri_ascii(path("missing.asc"), {});
  ASSERT_FALSE(missing.ok());
  EXPECT_TRUE(contains(missing.message(), path("missing.asc")) && contains(missing.message(), "cannot open"));
  for (const Case& c : cases) {
    write_text(path(c.name), c.text);
    auto r = load_esri_ascii(path(c.name), {});
    ASSERT_FALSE(r.ok()) << c.name;
    EXPECT_TRUE(contains(r.message(), path(c.name))) << r.message();
    EXPECT_TRUE(contains(r.message(), c.problem)) << c.name << ": " << r.message();
  }
}

// ---- saves ----

TEST_F(HeightfieldIo, SaveFailureNamesPathAndLeavesNothing) {
  const Heightfield hf = random_field(4, 4, 1, 6, 0, 1);
  const std::string bad = path("no_such_dir/h.png");
  for (const Status& s : {save_png16(bad, hf), save_raw_f32(bad, hf), save_esri_ascii(bad, hf)}) {
    ASSERT_FALSE(s.ok());
    EXPECT_TRUE(contains(s.message(), bad)) << s.message();
  }
  EXPECT_EQ(file_count(), 0u);
}

TEST_F(HeightfieldIo, SaveReplacesExistingFileWhole) {
  write_text(path("h.raw"), "old contents");
  const Heightfield hf = random_field(5, 5, 1, 7, 0, 1);
  ASSERT_TRUE(save_raw_f32(path("h.raw"), hf).ok());
  EXPECT_EQ(fs::file_size(path("h.raw")), 100u);
  EXPECT_EQ(file_count(), 1u);
}

TEST_F(HeightfieldIo, BadImportParametersNameTheField) {
  const Heightfield hf = random_field(4, 4, 1, 6, 0, 1);
  ASSERT_TRUE(save_raw_f32(path("h.raw"), hf).ok());
  HeightmapImport im;
  im.spacing = -1;
  auto r = load_raw_f32(path("h.raw"), 4, 4, im);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), path("h.raw")) && contains(r.message(), "spacing = -1")) << r.message();
  im.spacing = 1;
  im.vertical_scale = INFINITY;
  r = load_raw_f32(path("h.raw"), 4, 4, im);
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.message(), "import.vertical_scale = inf")) << r.message();
}


// ---- memory bombs (common/limits.hpp, docs/reliability.md) ----

long peak_rss_kib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss;
}

TEST_F(HeightfieldIo, PngHeaderBombIsRefusedBeforeAllocating) {
  // 65 bytes whose header claims 65536 × 65536 16-bit samples (8 GiB of pixels).
  const std::string bomb = std::string(SANDPATCH_SOURCE_DIR) + "/scenes/broken/heightmaps/bomb_65536.png";
  const long before = peak_rss_kib();
  auto r = load_png16(bomb, {});
  ASSERT_FALSE(r.ok());
  EXPECT_LT(peak_rss_kib() - before, 64 * 1024) << "peak memory grew by " << (peak_rss_kib() - before) << " KiB";
  const std::string m = r.errors()[0].message();
  EXPECT_TRUE(contains(m, "bomb_65536.png")) << m;
  EXPECT_TRUE(contains(m, "65536 × 65536")) << m;
  EXPECT_TRUE(contains(m, "at most 268435456 samples")) << m;
}

TEST_F(HeightfieldIo, EsriHeaderBombIsRefusedBeforeAllocating) {
  write_text(path("big.asc"), "ncols 1048577\nnrows 1048577\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3\n");
  const long before = peak_rss_kib();
  auto r = load_esri_ascii(path("big.asc"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_LT(peak_rss_kib() - before, 64 * 1024);
  EXPECT_TRUE(contains(r.errors()[0].message(), "ncols × nrows")) << r.errors()[0].message();
}

TEST_F(HeightfieldIo, RawGridOverTheCapIsRefused) {
  write_text(path("x.raw"), "");
  auto r = load_raw_f32(path("x.raw"), 65536, 65536, {});
  ASSERT_FALSE(r.ok());
  EXPECT_TRUE(contains(r.errors()[0].message(), "at most 268435456 samples")) << r.errors()[0].message();
}

TEST_F(HeightfieldIo, EsriGeometryOutsideTheWorldIsRefused) {
  write_text(path("c.asc"), "ncols 2\nnrows 2\nxllcorner 1e300\nyllcorner 0\ncellsize 1\n1 2\n3 4\n");
  auto r = load_esri_ascii(path("c.asc"), {});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.errors()[0].field, "xllcorner");
  write_text(path("s.asc"), "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1e30\n1 2\n3 4\n");
  auto s = load_esri_ascii(path("s.asc"), {});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.errors()[0].field, "cellsize");
}
}  // namespace
}  // namespace sandpatch
