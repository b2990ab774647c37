// Heightmap files: 16-bit greyscale PNG, raw little-endian float32, ESRI ASCII grid.
//
// Axis mappings (docs/heightfield.md):
//   PNG and raw: image row r -> j = r (z = r * spacing), column c -> i = c (x = c * spacing);
//     the first row of the file is z = 0.
//   ESRI ASCII: the first data row is the northernmost, and north is +z: data row r ->
//     j = nrows - 1 - r, column c -> i = c. (x, z) of sample (0, 0) is the centre of the
//     south-west cell: xllcenter / yllcenter, or xllcorner / yllcorner + spacing / 2 (the
//     spacing used: the file's cellsize, or `spacing` with override_spacing).
//   Heights are local (relative to origin_y) in every format; origin_y is never stored.
//
// Saves are atomic: the file is written to a temporary file in the same directory and
// renamed over the target, so a reader never sees half a file; errors name the path.
// Loads never crash on truncated or corrupt files; errors name the file and the problem.
#pragma once

#include <string>

#include "heightfield/heightfield.hpp"
#include "heightfield/procedural.hpp"

namespace sandpatch {

struct HeightmapImport {
  double origin_x = 0, origin_y = 0, origin_z = 0;  // m, world position of sample (0,0); for ESRI added to the file's lower-left centre
  float spacing = 1;          // m between samples (> 0); ESRI: used only when override_spacing
  float vertical_scale = 1;   // m per unit of normalised value (finite); height = offset + scale * value
  float vertical_offset = 0;  // m, local (finite)
  int tile_cells = 256;       // as HeightfieldDef::tile_cells
  bool override_spacing = false;  // ESRI: true = use `spacing` instead of the file's cellsize
};

// 16-bit (or 1/2/4/8-bit) greyscale PNG, optionally with alpha (ignored); colour and
// palette images are refused. height = vertical_offset + vertical_scale * v / vmax with
// vmax = 65535 for 16-bit files and 2^bits - 1 for the others. Sample values are taken
// as stored: gAMA / sRGB / iCCP chunks are ignored (heights are not colours).
Result<Heightfield> load_png16(const std::string& path, const HeightmapImport& import);
// Writes a 16-bit greyscale PNG with v = round((h - min) / (max - min) * 65535) and
// reports the mapping: loading with vertical_offset = *out_offset (m, local) and
// vertical_scale = *out_scale (m) reproduces the heights within out_scale / 65535 / 2.
// A flat field is written as all zeros with scale 0.
Status save_png16(const std::string& path, const Heightfield& hf, float* out_offset = nullptr,
                  float* out_scale = nullptr);

// Little-endian float32, samples_x * samples_z values, rows of samples_x (x fastest).
// height = vertical_offset + vertical_scale * v (computed in double, exact for the defaults).
// The file size must be exactly samples_x * samples_z * 4 bytes; NaN / inf are refused,
// naming the sample.
Result<Heightfield> load_raw_f32(const std::string& path, int samples_x, int samples_z,
                                 const HeightmapImport& import);
Status save_raw_f32(const std::string& path, const Heightfield& hf);

// ESRI ASCII grid. Header keys (any case, any order before the data): ncols, nrows,
// xllcorner | xllcenter, yllcorner | yllcenter, cellsize, optional NODATA_value. A NODATA
// cell is an error naming its row and column (we do not invent terrain). height =
// vertical_offset + vertical_scale * value.
Result<Heightfield> load_esri_ascii(const std::string& path, const HeightmapImport& import);
// Writes xllcenter = origin_x, yllcenter = origin_z (%.17g), cellsize = spacing and the
// heights with %.9g (enough digits to read back the same float), no NODATA_value.
Status save_esri_ascii(const std::string& path, const Heightfield& hf);

}  // namespace sandpatch
