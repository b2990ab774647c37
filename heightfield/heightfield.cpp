// Tiled, layered elevation grid. Region views after Huhtiranta §5.1.4 ("terrain object":
// all access through rectangular views of the terrain model); the bilinear surface is the
// one Leach & Marais §5.1 sample when filling a particle patch. Layout: heightfield.hpp.
#include "heightfield/heightfield.hpp"

#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <new>
#include <string>

#include "common/hash.hpp"
#include "common/limits.hpp"

namespace sandpatch {
namespace {

constexpr int kMaxSamples = (1 << 20) + 1;  // per axis; far beyond any terrain we can hold
constexpr int kMaxTileCells = 1 << 16;

int layer_index(Layer l) {
  const int k = static_cast<int>(l);
  assert(k >= 0 && k < kLayerCount);
  return k;
}

}  // namespace

const char* layer_name(Layer l) {
  static const char* const names[kLayerCount] = {"elevation", "material0", "material1", "material2",
                                                 "material3"};
  return names[layer_index(l)];
}

GridRegion intersect(GridRegion a, GridRegion b) {
  const int i0 = std::max(a.i0, b.i0), j0 = std::max(a.j0, b.j0);
  const std::int64_t i1 = std::min(std::int64_t(a.i0) + a.ni, std::int64_t(b.i0) + b.ni);
  const std::int64_t j1 = std::min(std::int64_t(a.j0) + a.nj, std::int64_t(b.j0) + b.nj);
  if (i1 <= i0 || j1 <= j0) return {i0, j0, 0, 0};
  return {i0, j0, int(i1 - i0), int(j1 - j0)};
}

Result<Heightfield> Heightfield::create(const HeightfieldDef& def) {
  // ---- validate every field, reporting all mistakes at once ----
  std::vector<Error> errs;
  auto bad = [&](const char* field, const std::string& value, const char* allowed) {
    errs.push_back(Error{"", field, value, allowed, ""});
  };
  if (def.samples_x < 2 || def.samples_x > kMaxSamples)
    bad("samples_x", std::to_string(def.samples_x), "must be in [2, 1048577]");
  if (def.samples_z < 2 || def.samples_z > kMaxSamples)
    bad("samples_z", std::to_string(def.samples_z), "must be in [2, 1048577]");
  if (!std::isfinite(def.spacing) || !(def.spacing > 0))
    bad("spacing", format_number(def.spacing), "must be finite and > 0 (m)");
  if (!std::isfinite(def.origin_x)) bad("origin_x", format_number(def.origin_x), "must be finite (m)");
  if (!std::isfinite(def.origin_y)) bad("origin_y", format_number(def.origin_y), "must be finite (m)");
  if (!std::isfinite(def.origin_z)) bad("origin_z", format_number(def.origin_z), "must be finite (m)");
  if (def.tile_cells < 1 || def.tile_cells > kMaxTileCells)
    bad("tile_cells", std::to_string(def.tile_cells), "must be in [1, 65536]");
  if (auto e = limits::check_grid_size("", "samples_x × samples_z", def.samples_x, def.samples_z)) errs.push_back(*e);
  if (!std::isfinite(def.initial_height))
    bad("initial_height", format_number(def.initial_height), "must be finite (m)");
  if (errs.empty()) {
    const double ex = double(def.samples_x - 1) * def.spacing, ez = double(def.samples_z - 1) * def.spacing;
    if (!(ex < 1e30 && ez < 1e30))
      bad("spacing", format_number(def.spacing), "(samples - 1) * spacing must fit in a float (m)");
  }
  if (!errs.empty()) return errs;

  // ---- geometry ----
  Heightfield hf;
  hf.nx_ = def.samples_x;
  hf.nz_ = def.samples_z;
  hf.cells_ = def.tile_cells;
  hf.tiles_x_ = (hf.nx_ - 1 + hf.cells_ - 1) / hf.cells_;
  hf.tiles_z_ = (hf.nz_ - 1 + hf.cells_ - 1) / hf.cells_;
  hf.spacing_ = def.spacing;
  hf.origin_ = {def.origin_x, def.origin_y, def.origin_z};
  hf.defaults_ = {def.initial_height, 1.0f, 0.0f, 0.0f, 0.0f};

  // ---- tiles: Elevation allocated now, other layers on first write ----
  const std::size_t ntiles = std::size_t(hf.tiles_x_) * hf.tiles_z_;
  try {
    for (auto& layer : hf.tiles_) {
      layer.resize(ntiles);
      for (int tz = 0; tz < hf.tiles_z_; ++tz)
        for (int tx = 0; tx < hf.tiles_x_; ++tx) {
          Tile& t = layer[hf.tile_index(tx, tz)];
          t.nx = hf.tile_samples_x(tx);
          t.nz = hf.tile_samples_z(tz);
        }
    }
    for (Tile& t : hf.tiles_[0]) {
      const std::size_t n = std::size_t(t.nx) * t.nz;
      t.data.reset(new float[n]);
      std::fill(t.data.get(), t.data.get() + n, def.initial_height);
    }
  } catch (const std::bad_alloc&) {
    return Error{"", "samples_x", std::to_string(def.samples_x) + " x " + std::to_string(def.samples_z),
                 "out of memory allocating the elevation layer (4 bytes per sample)", ""};
  }
  hf.ranges_.assign(ntiles, Range{});
  return hf;
}

// ---- copy / move ----

void Heightfield::copy_from(const Heightfield& o) {
  nx_ = o.nx_; nz_ = o.nz_; cells_ = o.cells_; tiles_x_ = o.tiles_x_; tiles_z_ = o.tiles_z_;
  spacing_ = o.spacing_; origin_ = o.origin_; defaults_ = o.defaults_;
  for (int l = 0; l < kLayerCount; ++l) {
    tiles_[l].clear();
    tiles_[l].resize(o.tiles_[l].size());
    for (std::size_t t = 0; t < o.tiles_[l].size(); ++t) {
      const Tile& src = o.tiles_[l][t];
      Tile& dst = tiles_[l][t];
      dst.nx = src.nx;
      dst.nz = src.nz;
      if (src.data) {
        const std::size_t n = std::size_t(src.nx) * src.nz;
        dst.data.reset(new float[n]);
        std::memcpy(dst.data.get(), src.data.get(), n * sizeof(float));
      }
    }
  }
  std::lock_guard<std::mutex> lock(*o.range_mutex_);
  ranges_ = o.ranges_;
}

Heightfield::Heightfield(const Heightfield& o) { copy_from(o); }
Heightfield& Heightfield::operator=(const Heightfield& o) {
  if (this != &o) copy_from(o);
  return *this;
}
Heightfield::Heightfield(Heightfield&& o) noexcept = default;
Heightfield& Heightfield::operator=(Heightfield&& o) noexcept = default;

// ---- geometry ----

float Heightfield::layer_default(Layer l) const { return defaults_[layer_index(l)]; }

bool Heightfield::contains(GridRegion r) const {
  if (r.empty()) return true;
  // In 64 bits: i0 + ni near INT_MAX must not wrap to a negative end.
  return r.i0 >= 0 && r.j0 >= 0 && std::int64_t(r.i0) + r.ni <= nx_ && std::int64_t(r.j0) + r.nj <= nz_;
}

int Heightfield::tile_samples_x(int tx) const {
  assert(tx >= 0 && tx < tiles_x_);
  return std::min(cells_, nx_ - 1 - tx * cells_) + 1;
}
int Heightfield::tile_samples_z(int tz) const {
  assert(tz >= 0 && tz < tiles_z_);
  return std::min(cells_, nz_ - 1 - tz * cells_) + 1;
}
GridRegion Heightfield::tile_region(int tx, int tz) const {
  return {tx * cells_, tz * cells_, tile_samples_x(tx), tile_samples_z(tz)};
}
const float* Heightfield::tile_data(int tx, int tz) const {
  assert(tx >= 0 && tx < tiles_x_ && tz >= 0 && tz < tiles_z_);
  return tiles_[0][tile_index(tx, tz)].data.get();
}

// ---- point access ----

float Heightfield::layer(Layer l, int i, int j) const {
  assert(i >= 0 && i < nx_ && j >= 0 && j < nz_);
  const int tx = std::min(i / cells_, tiles_x_ - 1), tz = std::min(j / cells_, tiles_z_ - 1);
  const Tile& t = tiles_[layer_index(l)][tile_index(tx, tz)];
  if (!t.data) return defaults_[layer_index(l)];
  return t.data[std::size_t(j - tz * cells_) * t.nx + (i - tx * cells_)];
}

float* Heightfield::writable_tile(Layer l, int tx, int tz) {
  Tile& t = tiles_[layer_index(l)][tile_index(tx, tz)];
  if (!t.data) {
    const std::size_t n = std::size_t(t.nx) * t.nz;
    t.data.reset(new float[n]);
    std::fill(t.data.get(), t.data.get() + n, defaults_[layer_index(l)]);
  }
  return t.data.get();
}

void Heightfield::set_layer(Layer l, int i, int j, float v) {
  assert(i >= 0 && i < nx_ && j >= 0 && j < nz_);
  // A sample on a tile edge lives in up to 2 x 2 tiles; write every copy.
  const int tx0 = i > 0 ? (i - 1) / cells_ : 0, tx1 = std::min(i / cells_, tiles_x_ - 1);
  const int tz0 = j > 0 ? (j - 1) / cells_ : 0, tz1 = std::min(j / cells_, tiles_z_ - 1);
  for (int tz = tz0; tz <= tz1; ++tz)
    for (int tx = tx0; tx <= tx1; ++tx) {
      const int li = i - tx * cells_, lj = j - tz * cells_;
      const Tile& t = tiles_[layer_index(l)][tile_index(tx, tz)];
      if (li < 0 || li >= t.nx || lj < 0 || lj >= t.nz) continue;
      writable_tile(l, tx, tz)[std::size_t(lj) * t.nx + li] = v;
      if (l == Layer::Elevation) ranges_[tile_index(tx, tz)].dirty = true;
    }
}

// ---- bilinear surface ----

namespace {
// Cell index and fraction along one axis: clamps to [0, n-1] samples, NaN reads as 0.
inline void locate(float x, float spacing, int n, int& i, float& u) {
  float f = x / spacing;
  if (!(f > 0)) f = 0;
  if (f > float(n - 1)) f = float(n - 1);
  i = std::min(static_cast<int>(f), n - 2);
  u = f - float(i);
}
}  // namespace

float Heightfield::sample_layer(Layer l, float x, float z) const {
  int i, j;
  float u, v;
  locate(x, spacing_, nx_, i, u);
  locate(z, spacing_, nz_, j, v);
  // The whole cell lies in tile (i / C, j / C): i <= nx-2 keeps i+1 inside it.
  const int tx = i / cells_, tz = j / cells_;
  const Tile& t = tiles_[layer_index(l)][tile_index(tx, tz)];
  if (!t.data) return defaults_[layer_index(l)];
  const float* p = t.data.get() + std::size_t(j - tz * cells_) * t.nx + (i - tx * cells_);
  const float h00 = p[0], h10 = p[1], h01 = p[t.nx], h11 = p[t.nx + 1];
  return (1 - u) * (1 - v) * h00 + u * (1 - v) * h10 + (1 - u) * v * h01 + u * v * h11;
}

Eigen::Vector2f Heightfield::gradient(float x, float z) const {
  int i, j;
  float u, v;
  locate(x, spacing_, nx_, i, u);
  locate(z, spacing_, nz_, j, v);
  const int tx = i / cells_, tz = j / cells_;
  const Tile& t = tiles_[0][tile_index(tx, tz)];
  const float* p = t.data.get() + std::size_t(j - tz * cells_) * t.nx + (i - tx * cells_);
  const float h00 = p[0], h10 = p[1], h01 = p[t.nx], h11 = p[t.nx + 1];
  // d/du and d/dv of the bilinear formula, divided by the spacing for d/dx, d/dz.
  const float dhdx = ((1 - v) * (h10 - h00) + v * (h11 - h01)) / spacing_;
  const float dhdz = ((1 - u) * (h01 - h00) + u * (h11 - h10)) / spacing_;
  return {dhdx, dhdz};
}

Eigen::Vector3f Heightfield::normal(float x, float z) const {
  const Eigen::Vector2f g = gradient(x, z);
  return Eigen::Vector3f(-g.x(), 1.0f, -g.y()).normalized();
}

// ---- regions ----

void Heightfield::read(GridRegion r, float* out, Layer l) const {
  assert(contains(r));
  if (r.empty()) return;
  assert(out);
  const int tx0 = r.i0 / cells_, tx1 = std::min((r.i0 + r.ni - 1) / cells_, tiles_x_ - 1);
  const int tz0 = r.j0 / cells_, tz1 = std::min((r.j0 + r.nj - 1) / cells_, tiles_z_ - 1);
  for (int tz = tz0; tz <= tz1; ++tz)
    for (int tx = tx0; tx <= tx1; ++tx) {
      const GridRegion s = intersect(r, tile_region(tx, tz));
      if (s.empty()) continue;
      const Tile& t = tiles_[layer_index(l)][tile_index(tx, tz)];
      for (int j = s.j0; j < s.j0 + s.nj; ++j) {
        float* dst = out + std::size_t(j - r.j0) * r.ni + (s.i0 - r.i0);
        if (!t.data) {
          std::fill(dst, dst + s.ni, defaults_[layer_index(l)]);
        } else {
          const float* src = t.data.get() + std::size_t(j - tz * cells_) * t.nx + (s.i0 - tx * cells_);
          std::memcpy(dst, src, std::size_t(s.ni) * sizeof(float));
        }
      }
    }
}

void Heightfield::write(GridRegion r, const float* in, Layer l) {
  assert(contains(r));
  if (r.empty()) return;
  assert(in);
  // Every tile touching r, including those that only share r's edge samples.
  const int tx0 = r.i0 > 0 ? (r.i0 - 1) / cells_ : 0, tx1 = std::min((r.i0 + r.ni - 1) / cells_, tiles_x_ - 1);
  const int tz0 = r.j0 > 0 ? (r.j0 - 1) / cells_ : 0, tz1 = std::min((r.j0 + r.nj - 1) / cells_, tiles_z_ - 1);
  for (int tz = tz0; tz <= tz1; ++tz)
    for (int tx = tx0; tx <= tx1; ++tx) {
      const GridRegion s = intersect(r, tile_region(tx, tz));
      if (s.empty()) continue;
      float* data = writable_tile(l, tx, tz);
      const int tnx = tiles_[layer_index(l)][tile_index(tx, tz)].nx;
      for (int j = s.j0; j < s.j0 + s.nj; ++j) {
        const float* src = in + std::size_t(j - r.j0) * r.ni + (s.i0 - r.i0);
        float* dst = data + std::size_t(j - tz * cells_) * tnx + (s.i0 - tx * cells_);
        std::memcpy(dst, src, std::size_t(s.ni) * sizeof(float));
      }
      if (l == Layer::Elevation) ranges_[tile_index(tx, tz)].dirty = true;
    }
}

void Heightfield::fill(GridRegion r, float v, Layer l) {
  assert(contains(r));
  if (r.empty()) return;
  std::vector<float> row(std::size_t(r.ni) * r.nj, v);
  write(r, row.data(), l);
}

// ---- elevation range ----

void Heightfield::update_range(std::size_t t) const {
  Range& rg = ranges_[t];
  if (!rg.dirty) return;
  const Tile& tile = tiles_[0][t];
  const float* p = tile.data.get();
  const std::size_t n = std::size_t(tile.nx) * tile.nz;
  float lo = p[0], hi = p[0];
  for (std::size_t k = 1; k < n; ++k) {
    lo = std::min(lo, p[k]);
    hi = std::max(hi, p[k]);
  }
  rg = {lo, hi, false};
}

float Heightfield::tile_min_height(int tx, int tz) const {
  std::lock_guard<std::mutex> lock(*range_mutex_);
  update_range(tile_index(tx, tz));
  return ranges_[tile_index(tx, tz)].lo;
}
float Heightfield::tile_max_height(int tx, int tz) const {
  std::lock_guard<std::mutex> lock(*range_mutex_);
  update_range(tile_index(tx, tz));
  return ranges_[tile_index(tx, tz)].hi;
}
float Heightfield::min_height() const {
  std::lock_guard<std::mutex> lock(*range_mutex_);
  float lo = std::numeric_limits<float>::infinity();
  for (std::size_t t = 0; t < ranges_.size(); ++t) {
    update_range(t);
    lo = std::min(lo, ranges_[t].lo);
  }
  return lo;
}
float Heightfield::max_height() const {
  std::lock_guard<std::mutex> lock(*range_mutex_);
  float hi = -std::numeric_limits<float>::infinity();
  for (std::size_t t = 0; t < ranges_.size(); ++t) {
    update_range(t);
    hi = std::max(hi, ranges_[t].hi);
  }
  return hi;
}

// ---- bookkeeping ----

bool Heightfield::layer_allocated(Layer l) const {
  for (const Tile& t : tiles_[layer_index(l)])
    if (t.data) return true;
  return false;
}

std::size_t Heightfield::memory_bytes() const {
  std::size_t b = 0;
  for (const auto& layer : tiles_)
    for (const Tile& t : layer)
      if (t.data) b += std::size_t(t.nx) * t.nz * sizeof(float);
  return b;
}

std::uint64_t Heightfield::hash() const {
  Hasher h;
  h.pod(nx_);
  h.pod(nz_);
  h.pod(cells_);
  h.pod(spacing_);
  h.pod(origin_);
  std::vector<float> defaults;
  for (int l = 0; l < kLayerCount; ++l) {
    h.pod(l);
    for (const Tile& t : tiles_[l]) {
      const std::size_t n = std::size_t(t.nx) * t.nz;
      if (t.data) {
        h.bytes(t.data.get(), n * sizeof(float));
      } else {
        defaults.assign(n, defaults_[l]);
        h.bytes(defaults.data(), n * sizeof(float));
      }
    }
  }
  return h.value();
}

}  // namespace sandpatch
