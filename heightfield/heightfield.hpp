// The terrain's elevation grid and its extra layers, stored in square tiles.
//
// Region access (GridRegion, read/write of a rectangle) follows the "terrain object"
// views of Huhtiranta §5.1.4: the simulator reads and writes the terrain only through
// rectangular views; a demoted particle patch is written back through one (Leach &
// Marais §5.2).
//
// Coordinates: SI units, y up, the grid lies in the x–z plane. Sample (i, j) sits at
// local position (x, z) = (i * spacing, j * spacing); i runs along x, j along z. The
// world position of a local point (x, h, z) is (origin_x + x, origin_y + h, origin_z + z):
// the origin is double, everything else is float and relative to it.
//
// Surface (exact formula, documented as Jolt does for its HeightFieldShape): inside the
// cell [i, i+1] x [j, j+1], with u = x/spacing - i and v = z/spacing - j in [0, 1],
//   h(x, z) = (1-u)(1-v) h[i,j] + u(1-v) h[i+1,j] + (1-u)v h[i,j+1] + uv h[i+1,j+1]
// (bilinear). Points outside the grid are clamped to its edge first.
//
// Tiles: the grid is cut into tiles of tile_cells x tile_cells cells. Tile (tx, tz)
// covers samples i in [tx*C, tx*C + tile_samples_x(tx)), j likewise (C = tile_cells);
// neighbouring tiles share their edge row/column, stored in both and kept equal by every
// write. The last tile in each direction may be smaller. Each tile's data is contiguous,
// row-major with x fastest, so it can be handed to btHeightfieldTerrainShape uncopied.
//
// Layers: Elevation is always allocated. Every other layer is allocated lazily, one tile
// at a time, on the first write into that tile; until then it reads as its default value
// (layer_default()). An 8193 x 8193 grid therefore costs 4 bytes x 67 M = 268 MB for
// Elevation, plus only the tiles of other layers that were written.
//
// Thread safety: const methods may be called concurrently (min/max caches are guarded by
// a mutex); writes need exclusive access.
#pragma once

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cassert>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "common/error.hpp"

namespace sandpatch {

struct HeightfieldDef {
  int samples_x = 0;           // samples along x (>= 2)
  int samples_z = 0;           // samples along z (>= 2)
  float spacing = 1.0f;        // metres between neighbouring samples (> 0, finite)
  double origin_x = 0, origin_y = 0, origin_z = 0;  // world position (m) of sample (0,0) at local height 0
  int tile_cells = 256;        // cells per tile edge (>= 1); a tile stores (tile_cells+1)^2 samples, neighbouring tiles share their edge row/column
  float initial_height = 0.0f; // m, local (finite)
};

// Elevation: surface height (m, local); Material0..3: blend weights in [0,1].
enum class Layer { Elevation, Material0, Material1, Material2, Material3 };
inline constexpr int kLayerCount = 5;
const char* layer_name(Layer l);  // "elevation", "material0", ...

// GridRegion: samples [i0, i0+ni) x [j0, j0+nj).
struct GridRegion {
  int i0 = 0, j0 = 0, ni = 0, nj = 0;
  bool empty() const { return ni <= 0 || nj <= 0; }
};
// The intersection of two regions (empty when they do not overlap).
GridRegion intersect(GridRegion a, GridRegion b);

class Heightfield {
 public:
  // Validates def; errors name the field (file is "").
  static Result<Heightfield> create(const HeightfieldDef& def);

  // Value of an unwritten sample of layer l: Elevation = def.initial_height,
  // Material0 = 1, Material1..3 = 0.
  float layer_default(Layer l) const;

  int samples_x() const { return nx_; }
  int samples_z() const { return nz_; }
  float spacing() const { return spacing_; }        // m
  double origin_x() const { return origin_[0]; }    // m, world
  double origin_y() const { return origin_[1]; }
  double origin_z() const { return origin_[2]; }
  float extent_x() const { return float(nx_ - 1) * spacing_; }  // m
  float extent_z() const { return float(nz_ - 1) * spacing_; }  // m
  GridRegion whole() const { return {0, 0, nx_, nz_}; }
  bool contains(GridRegion r) const;  // r inside the grid (an empty r is contained)

  // Elevation at a sample (m, local). 0 <= i < samples_x, 0 <= j < samples_z (asserted).
  float height(int i, int j) const {
    assert(i >= 0 && i < nx_ && j >= 0 && j < nz_);
    const int tx = std::min(i / cells_, tiles_x_ - 1), tz = std::min(j / cells_, tiles_z_ - 1);
    const Tile& t = tiles_[0][std::size_t(tz) * tiles_x_ + tx];
    return t[std::size_t(j - tz * cells_) * t.nx + (i - tx * cells_)];
  }
  void set_height(int i, int j, float h) { set_layer(Layer::Elevation, i, j, h); }  // all tiles sharing the sample
  float layer(Layer l, int i, int j) const;
  void set_layer(Layer l, int i, int j, float v);

  // Bilinear Elevation (m, local) at local (x, z) (m), clamped to the grid; NaN reads as 0.
  float sample(float x, float z) const { return sample_layer(Layer::Elevation, x, z); }
  float sample_layer(Layer l, float x, float z) const;
  // Unit normal of the bilinear surface at (x, z): exact derivative of the formula above,
  // n = normalize(-dh/dx, 1, -dh/dz). On a cell edge the cell with the larger index wins
  // (the last cell at the far grid edge).
  Eigen::Vector3f normal(float x, float z) const;
  // Bilinear surface gradient (dh/dx, dh/dz) (dimensionless) at (x, z).
  Eigen::Vector2f gradient(float x, float z) const;

  // Row-major copy of a region: nj rows of ni values, x fastest. r inside the grid (asserted).
  void read(GridRegion r, float* out, Layer l = Layer::Elevation) const;
  void write(GridRegion r, const float* in, Layer l = Layer::Elevation);
  void fill(GridRegion r, float v, Layer l = Layer::Elevation);

  int tiles_x() const { return tiles_x_; }
  int tiles_z() const { return tiles_z_; }
  int tile_cells() const { return cells_; }
  // Contiguous Elevation of tile (tx, tz): tile_samples_x(tx) * tile_samples_z(tz) floats,
  // row-major with x fastest. Stable until the Heightfield is destroyed or assigned to.
  const float* tile_data(int tx, int tz) const;
  int tile_samples_x(int tx) const;
  int tile_samples_z(int tz) const;
  GridRegion tile_region(int tx, int tz) const;  // the samples tile (tx, tz) covers
  // Elevation range of one tile and of the whole grid (m, local); cached, recomputed after writes.
  float tile_min_height(int tx, int tz) const;
  float tile_max_height(int tx, int tz) const;
  float min_height() const;
  float max_height() const;

  bool layer_allocated(Layer l) const;  // some tile of l has been written
  std::size_t memory_bytes() const;     // bytes held by sample storage

  // FNV-1a (common/hash.hpp) over dims, spacing, tile size, origin and every sample of
  // every layer (defaults included, so a lazily unallocated layer hashes like a written
  // one holding the same values). Byte exact.
  std::uint64_t hash() const;

  Heightfield(const Heightfield& o);
  Heightfield& operator=(const Heightfield& o);
  Heightfield(Heightfield&& o) noexcept;
  Heightfield& operator=(Heightfield&& o) noexcept;
  ~Heightfield() = default;

 private:
  struct Tile {
    std::unique_ptr<float[]> data;  // null: unallocated (reads as the layer default)
    int nx = 0, nz = 0;             // samples in this tile
    float operator[](std::size_t k) const { return data[k]; }
  };
  struct Range {
    float lo = 0, hi = 0;
    bool dirty = true;
  };

  Heightfield() = default;
  void copy_from(const Heightfield& o);
  std::size_t tile_index(int tx, int tz) const { return std::size_t(tz) * tiles_x_ + tx; }
  float* writable_tile(Layer l, int tx, int tz);  // allocates on first use
  void mark_dirty(GridRegion r);
  void update_range(std::size_t t) const;  // caller holds range_mutex_

  int nx_ = 0, nz_ = 0, cells_ = 1, tiles_x_ = 0, tiles_z_ = 0;
  float spacing_ = 1;
  std::array<double, 3> origin_{};
  std::array<float, kLayerCount> defaults_{};
  std::array<std::vector<Tile>, kLayerCount> tiles_;  // per layer, tile_index order
  mutable std::vector<Range> ranges_;                 // Elevation min/max per tile
  mutable std::unique_ptr<std::mutex> range_mutex_ = std::make_unique<std::mutex>();
};

}  // namespace sandpatch
