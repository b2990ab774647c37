// Heightmap importers: the first byte picks the format (PNG, raw float32 with dimensions from
// the next four bytes, ESRI ASCII grid); the rest is the file.
#include <cmath>
#include <cstdint>

#include "fuzz/fuzz_util.hpp"
#include "heightfield/io.hpp"

using namespace sandpatch;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::Bytes b{data, size};
  const int format = b.byte() % 3;
  HeightmapImport im;
  im.tile_cells = 1 + b.byte() % 64;
  Result<Heightfield> hf = Error{"", "", "", ""};
  if (format == 0) {
    hf = load_png16(fuzz::scratch_file(b.p, b.n, ".png"), im);
  } else if (format == 1) {
    const int nx = b.take<std::uint16_t>() % 300, nz = b.take<std::uint16_t>() % 300;
    hf = load_raw_f32(fuzz::scratch_file(b.p, b.n, ".raw"), nx, nz, im);
  } else {
    im.override_spacing = b.byte() & 1;
    hf = load_esri_ascii(fuzz::scratch_file(b.p, b.n, ".asc"), im);
  }
  if (hf) {
    // A loaded grid holds finite heights only.
    if (!std::isfinite(hf->min_height()) || !std::isfinite(hf->max_height())) __builtin_trap();
  } else if (hf.errors().empty()) {
    __builtin_trap();
  }
  return 0;
}
