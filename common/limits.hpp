// Resource limits of one run or one Terrain: each follows from a stated cap, is checked before
// anything of that size is allocated, and its error names the number to lower
// (docs/reliability.md lists them with the extremes they were tested at).
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "common/error.hpp"

namespace sandpatch::limits {

// ---- heightfield grids ----
// Memory cap of one elevation grid: 1 GiB of float32 heights (4 bytes a sample). Every grid
// (heightmap files, procedural generators, a game's array) is refused past it, from its
// dimensions alone (a PNG's header, an ESRI grid's ncols / nrows), before pixels are read.
inline constexpr std::uint64_t kMaxGridBytes = std::uint64_t(1) << 30;
inline constexpr std::uint64_t kMaxGridSamples = kMaxGridBytes / 4;  // 268435456 = 16384 × 16384

// ---- the patch pool ----
// Every slot is allocated at full capacity when patches are enabled. A granule costs about
// 1 KiB of DEM state (4 spheres of 104 bytes in the field lists of particles/fields.hpp, a
// body of 140 bytes, and the CPU backend's per-sphere sort, contact and boundary arrays), so
// a 4 GiB pool cap gives slots × granules_per_slot ≤ 2^22 = 4194304 granules (the largest
// shipped scene, leach_3_ten_bodies_paper, holds 983040).
inline constexpr std::uint64_t kMaxPoolBytes = std::uint64_t(4) << 30;
inline constexpr std::uint64_t kPoolBytesPerGranule = 1024;
inline constexpr std::uint64_t kMaxPoolGranules = kMaxPoolBytes / kPoolBytesPerGranule;

// ---- meshes ----
// An OBJ is read whole by the loader: files over 256 MiB and meshes over 2^21 triangles (the
// signed-distance shell and the convex hull are built from every triangle) are refused.
inline constexpr std::uint64_t kMaxMeshFileBytes = std::uint64_t(256) << 20;
inline constexpr std::uint64_t kMaxMeshTriangles = std::uint64_t(1) << 21;
// Scaled mesh extent (m) per axis: the same bound as a box's full width (2 × 1e4 m).
inline constexpr double kMaxMeshExtent = 2e4;

// ---- bodies ----
// Fastest body speed accepted at creation (m/s), scene files and the library alike: beyond it
// one 1/60 s frame moves a body further than the contact prediction can follow.
inline constexpr double kMaxBodySpeed = 1e3;
inline constexpr double kMaxBodySpin = 1e4;  // rad/s
// Body masses in kg: Bullet stores them as float; the lower bound keeps 1 / mass finite.
inline constexpr double kMinBodyMass = 1e-6;
inline constexpr double kMaxBodyMass = 1e9;

// ---- scene text ----
// Deepest nesting of arrays and objects a scene file may have (the deepest real scene has 5):
// the JSON reader recurses per level, so a deeper text is refused before it is built.
inline constexpr int kMaxJsonDepth = 256;

// Samples of an nx × nz grid, refused past kMaxGridSamples: nullopt when it fits, else the
// error (fields "samples_x × samples_z", the product and what to lower). `file` and the field
// names are the caller's ("ncols × nrows", "width × height").
inline std::optional<Error> check_grid_size(const std::string& file, const std::string& field, std::int64_t nx,
                                            std::int64_t nz) {
  if (nx <= 0 || nz <= 0) return std::nullopt;  // the caller's own range check reports these
  const double n = double(nx) * double(nz);
  if (n <= double(kMaxGridSamples)) return std::nullopt;
  return Error{file, field,
               std::to_string(nx) + " × " + std::to_string(nz) + " = " + format_number(n) + " samples (" +
                   format_number(n * 4.0 / double(1 << 20)) + " MiB of heights)",
               "must be at most " + std::to_string(kMaxGridSamples) + " samples (" +
                   std::to_string(kMaxGridBytes >> 20) + " MiB at 4 bytes a sample, e.g. 16384 × 16384)",
               "lower the sample count (or downsample the heightmap) so that the product is at most " +
                   std::to_string(kMaxGridSamples)};
}

}  // namespace sandpatch::limits
