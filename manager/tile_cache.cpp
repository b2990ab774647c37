// Pre-settled granule tiles kept on disk: see tile_cache.hpp.
#include "manager/tile_cache.hpp"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <system_error>
#include <unistd.h>

#include "common/hash.hpp"
#include "manager/tile_code_hash.hpp"  // generated: SANDPATCH_TILE_CODE_HASH (cmake/hash_sources.cmake)
#include "particles/bed.hpp"
#include "particles/dem.hpp"

namespace sandpatch {
namespace {

constexpr char kMagic[8] = {'S', 'P', 'T', 'I', 'L', 'E', '\n', '\0'};
constexpr std::uint32_t kVersion = 1;        // the file layout below
constexpr std::uint32_t kMaxGranules = 1u << 22;  // a tile holds hundreds; anything near this is corrupt

// State hash of a short deterministic DEM run (12 granules dropped into a walled box, 0.1 s):
// the same sources built differently (compiler, flags, instruction set) that would settle a
// tile to other bits give another probe. Computed once per process (~10 ms).
std::uint64_t dem_probe() {
  static const std::uint64_t value = [] {
    SimulationDef sd;
    sd.max_bodies = 16;
    sd.max_particles = 64;
    sd.particle_radius = 0.01f;
    sd.material.normal_stiffness = 2e4f;
    sd.bounds_min = {0, 0, 0};
    sd.bounds_max = {0.12f, 0.3f, 0.12f};
    sd.side_walls = true;
    sd.max_overlap_fraction = 0;
    sd.threads = 1;
    auto sim = Simulation::create(sd);
    if (!sim) return std::uint64_t(0);
    LatticeBedDef bed;
    bed.min = {0.03f, 0.03f, 0.03f};
    bed.nx = 2, bed.nz = 2, bed.layers = 3;
    bed.seed = 7;
    if (!add_lattice_bed(*sim, bed)) return std::uint64_t(0);
    for (int i = 0; i < 10; ++i)
      if (!sim->step(0.01)) return std::uint64_t(0);
    return sim->state_hash();
  }();
  return value;
}

// Little-endian-agnostic on purpose: the file is a cache for this machine's own build (the
// probe above differs between builds anyway), so values are stored in native layout.
class Writer {
 public:
  template <class T>
  void pod(const T& v) {
    const auto* p = reinterpret_cast<const char*>(&v);
    buf_.insert(buf_.end(), p, p + sizeof(T));
  }
  void vec(Vec3 v) { pod(v.x), pod(v.y), pod(v.z); }
  const std::vector<char>& bytes() const { return buf_; }
 private:
  std::vector<char> buf_;
};

class Reader {
 public:
  Reader(const char* p, std::size_t n) : p_(p), n_(n) {}
  template <class T>
  bool pod(T& v) {
    if (n_ - at_ < sizeof(T)) return false;
    std::memcpy(&v, p_ + at_, sizeof(T));
    at_ += sizeof(T);
    return true;
  }
  bool vec(Vec3& v) { return pod(v.x) && pod(v.y) && pod(v.z); }
  std::size_t at() const { return at_; }
 private:
  const char* p_;
  std::size_t n_, at_ = 0;
};

std::uint64_t checksum(const char* p, std::size_t n) {
  Hasher h;
  h.bytes(p, n);
  return h.value();
}

Error file_error(const std::string& path, const std::string& what) {
  return Error{path, "", "", "", what};
}

}  // namespace

std::string tile_cache_dir() {
  if (const char* e = std::getenv("SANDPATCH_TILE_CACHE")) {
    const std::string v = e;
    return v == "off" ? std::string() : v;
  }
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/sandpatch/tiles";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/sandpatch/tiles";
  return {};
}

std::string tile_cache_build_dir() {
#ifdef SANDPATCH_BUILD_TILE_DIR
  std::error_code ec;
  if (std::filesystem::is_directory(SANDPATCH_BUILD_TILE_DIR, ec)) return SANDPATCH_BUILD_TILE_DIR;
#endif
  return {};
}

std::uint64_t tile_cache_key(const GranuleTileDef& def) {
  Hasher h;
  h.pod(kVersion);
  h.str(SANDPATCH_TILE_CODE_HASH);
  h.pod(dem_probe());
  h.pod(granule_tile_def_hash(def));
  return h.value();
}

std::string tile_cache_path(const std::string& dir, std::uint64_t key) {
  return dir + "/tile-" + Hasher::to_hex(key) + ".bin";
}

Status save_tile(const std::string& dir, std::uint64_t key, const GranuleTile& t) {
  Writer w;
  for (char c : kMagic) w.pod(c);
  w.pod(kVersion);
  w.pod(key);
  w.pod(std::uint32_t(t.granules.size()));
  w.pod(t.period_xz), w.pod(t.period_y), w.pod(t.packing_fraction), w.pod(t.surface_offset);
  w.pod(t.surface_probe), w.pod(t.rebound), w.pod(t.settled_speed), w.pod(t.settle_time);
  const GranuleShape& s = t.shape;
  w.pod(s.radius), w.pod(s.edge_factor), w.pod(s.mass), w.pod(s.inertia), w.pod(s.centre_distance);
  for (const Vec3& o : s.offsets) w.vec(o);
  for (const PlacedGranule& g : t.granules) {
    w.vec(g.position);
    w.pod(g.orientation.x), w.pod(g.orientation.y), w.pod(g.orientation.z), w.pod(g.orientation.w);
  }
  std::vector<char> bytes = w.bytes();
  const std::uint64_t sum = checksum(bytes.data(), bytes.size());
  bytes.insert(bytes.end(), reinterpret_cast<const char*>(&sum), reinterpret_cast<const char*>(&sum) + sizeof sum);

  namespace fs = std::filesystem;
  const std::string path = tile_cache_path(dir, key);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) return file_error(dir, "cannot create the tile cache directory: " + ec.message());
  // A name no other process uses, renamed over the final one: readers see all or nothing.
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    f.write(bytes.data(), std::streamsize(bytes.size()));
    f.close();
    if (!f) {
      fs::remove(tmp, ec);
      return file_error(tmp, "cannot write the tile file");
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ec2;
    fs::remove(tmp, ec2);
    return file_error(path, "cannot rename the tile file into place: " + ec.message());
  }
  return Ok{};
}

Result<GranuleTile> load_tile(const std::string& dir, std::uint64_t key) {
  const std::string path = tile_cache_path(dir, key);
  std::ifstream f(path, std::ios::binary);
  if (!f) return file_error(path, "no such tile file");
  std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  if (bytes.size() < sizeof(kMagic) + sizeof(std::uint64_t)) return file_error(path, "truncated tile file");
  const std::size_t body = bytes.size() - sizeof(std::uint64_t);
  std::uint64_t sum = 0;
  std::memcpy(&sum, bytes.data() + body, sizeof sum);
  if (std::memcmp(bytes.data(), kMagic, sizeof kMagic) != 0) return file_error(path, "not a Sandpatch tile file (magic)");
  if (checksum(bytes.data(), body) != sum) return file_error(path, "checksum mismatch (truncated or corrupt)");

  Reader r(bytes.data() + sizeof kMagic, body - sizeof kMagic);
  std::uint32_t version = 0, count = 0;
  std::uint64_t stored_key = 0;
  if (!r.pod(version) || version != kVersion)
    return file_error(path, "tile file version " + std::to_string(version) + ", this build reads " + std::to_string(kVersion));
  if (!r.pod(stored_key) || stored_key != key) return file_error(path, "tile file holds another key");
  if (!r.pod(count) || count > kMaxGranules) return file_error(path, "granule count " + std::to_string(count) + " out of range");
  GranuleTile t;
  GranuleShape& s = t.shape;
  bool ok = r.pod(t.period_xz) && r.pod(t.period_y) && r.pod(t.packing_fraction) && r.pod(t.surface_offset) &&
            r.pod(t.surface_probe) && r.pod(t.rebound) && r.pod(t.settled_speed) && r.pod(t.settle_time) &&
            r.pod(s.radius) && r.pod(s.edge_factor) && r.pod(s.mass) && r.pod(s.inertia) && r.pod(s.centre_distance);
  for (Vec3& o : s.offsets) ok = ok && r.vec(o);
  t.granules.resize(count);
  for (PlacedGranule& g : t.granules)
    ok = ok && r.vec(g.position) && r.pod(g.orientation.x) && r.pod(g.orientation.y) && r.pod(g.orientation.z) &&
         r.pod(g.orientation.w);
  if (!ok || r.at() != body - sizeof kMagic) return file_error(path, "tile file size does not match its granule count");

  // Every value finite and the periods positive: a tile that passes the checksum but not this
  // was written by a broken build; refuse it rather than fill a patch with NaN.
  bool finite = std::isfinite(t.period_xz) && t.period_xz > 0 && std::isfinite(t.period_y) && t.period_y > 0 &&
                std::isfinite(t.surface_offset) && std::isfinite(t.rebound) && std::isfinite(s.radius) && s.radius > 0 &&
                std::isfinite(s.mass) && s.mass > 0 && std::isfinite(s.inertia) && s.inertia > 0;
  for (const PlacedGranule& g : t.granules)
    finite = finite && std::isfinite(g.position.x + g.position.y + g.position.z) &&
             std::isfinite(g.orientation.x + g.orientation.y + g.orientation.z + g.orientation.w);
  if (!finite) return file_error(path, "tile file holds a non-finite or non-positive value");
  return t;
}

Result<GranuleTile> cached_granule_tile(const GranuleTileDef& def, const std::string& dir, TileCacheOutcome* outcome,
                                        const std::string& fallback) {
  TileCacheOutcome local;
  TileCacheOutcome& out = outcome ? *outcome : local;
  out = {};
  if (dir.empty()) {
    bool reused = false;
    auto t = shared_granule_tile(def, &reused);
    out.source = reused ? TileCacheOutcome::Source::Memory : TileCacheOutcome::Source::Settled;
    return t;
  }
  const std::uint64_t key = tile_cache_key(def);
  auto disk = load_tile(dir, key);
  if (disk) {
    out.source = TileCacheOutcome::Source::Disk;
    return disk;
  }
  // A missing file is the normal first run; anything else is worth a note.
  if (disk.error().detail != "no such tile file") out.note = disk.error().message();
  // A read-only copy (the tiles the build settled, tile_cache_build_dir), kept in `dir` too.
  if (!fallback.empty() && fallback != dir) {
    if (auto b = load_tile(fallback, key)) {
      out.source = TileCacheOutcome::Source::Disk;
      if (Status st = save_tile(dir, key, *b); !st) out.note += (out.note.empty() ? "" : "; ") + st.error().message();
      return b;
    }
  }
  bool reused = false;
  auto t = shared_granule_tile(def, &reused);
  if (!t) return t;
  out.source = reused ? TileCacheOutcome::Source::Memory : TileCacheOutcome::Source::Settled;
  if (Status st = save_tile(dir, key, *t); !st) out.note += (out.note.empty() ? "" : "; ") + st.error().message();
  return t;
}

}  // namespace sandpatch
