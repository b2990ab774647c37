// tests manager/tile_cache.cpp: a tile read back from disk is the tile that was settled, bit
// for bit; bad files are refused with the reason and replaced; the key follows the definition.
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <unistd.h>

#include "manager/tile_cache.hpp"

using namespace sandpatch;
namespace fs = std::filesystem;

namespace {

GranuleTileDef small_def() {
  GranuleTileDef d;
  d.radius = 0.025f;
  d.material.normal_stiffness = 2.0e4f;
  d.material.density = 2650.0f;
  d.columns = 4;
  d.layers = 4;
  d.settle_max_time = 1.0;
  d.surface_probe = 2.0f * d.radius;
  d.settle_friction = 0.2f;
  return d;
}

// A fresh directory per test (removed at the end).
struct TempDir {
  std::string path;
  explicit TempDir(const char* name)
      : path((fs::temp_directory_path() / (std::string("sandpatch_tile_cache_") + name + "_" + std::to_string(::getpid()))).string()) {
    fs::remove_all(path);
  }
  ~TempDir() { fs::remove_all(path); }
};

bool same_bits(const GranuleTile& a, const GranuleTile& b) {
  auto eq = [](const auto& x, const auto& y) { return std::memcmp(&x, &y, sizeof x) == 0; };
  bool same = eq(a.period_xz, b.period_xz) && eq(a.period_y, b.period_y) && eq(a.packing_fraction, b.packing_fraction) &&
              eq(a.surface_offset, b.surface_offset) && eq(a.surface_probe, b.surface_probe) && eq(a.rebound, b.rebound) &&
              eq(a.settled_speed, b.settled_speed) && eq(a.settle_time, b.settle_time) && eq(a.shape.radius, b.shape.radius) &&
              eq(a.shape.mass, b.shape.mass) && eq(a.shape.inertia, b.shape.inertia) &&
              eq(a.shape.centre_distance, b.shape.centre_distance) && eq(a.shape.offsets, b.shape.offsets) &&
              a.granules.size() == b.granules.size();
  for (std::size_t i = 0; same && i < a.granules.size(); ++i)
    same = eq(a.granules[i].position, b.granules[i].position) && eq(a.granules[i].orientation, b.granules[i].orientation);
  return same;
}

void flip_byte(const std::string& path, std::size_t at) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(std::streamoff(at));
  char c = 0;
  f.read(&c, 1);
  c = char(c ^ 0x5a);
  f.seekp(std::streamoff(at));
  f.write(&c, 1);
}

}  // namespace

// First use settles and writes the file; the second reads it, and what it reads is the
// settled tile to the last bit (so a scene's state hash does not depend on the cache).
TEST(TileCache, DiskCopyIsTheSettledTileBitForBit) {
  TempDir dir("roundtrip");
  const GranuleTileDef d = small_def();
  TileCacheOutcome first, second;
  auto a = cached_granule_tile(d, dir.path, &first);
  ASSERT_TRUE(a.ok()) << a.message();
  EXPECT_NE(first.source, TileCacheOutcome::Source::Disk);
  EXPECT_EQ(first.note, "");
  EXPECT_TRUE(fs::exists(tile_cache_path(dir.path, tile_cache_key(d))));
  auto b = cached_granule_tile(d, dir.path, &second);
  ASSERT_TRUE(b.ok()) << b.message();
  EXPECT_EQ(second.source, TileCacheOutcome::Source::Disk);
  EXPECT_TRUE(same_bits(*a, *b));
  auto settled = make_granule_tile(d);  // settling again gives the same bits (deterministic DEM)
  ASSERT_TRUE(settled.ok());
  EXPECT_TRUE(same_bits(*settled, *b));
  // No temporary file is left behind.
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir.path)) files += e.is_regular_file();
  EXPECT_EQ(files, 1);
}

// A corrupt, truncated or foreign file is refused with the path and the reason, and the
// cache settles the tile again and rewrites a good file.
TEST(TileCache, BadFilesAreRefusedNamedAndReplaced) {
  TempDir dir("bad");
  const GranuleTileDef d = small_def();
  const std::uint64_t key = tile_cache_key(d);
  const std::string path = tile_cache_path(dir.path, key);
  auto good = cached_granule_tile(d, dir.path);
  ASSERT_TRUE(good.ok());
  const auto size = fs::file_size(path);

  flip_byte(path, size / 2);  // inside the granules
  auto r = load_tile(dir.path, key);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find(path), std::string::npos) << r.message();
  EXPECT_NE(r.message().find("checksum"), std::string::npos) << r.message();
  TileCacheOutcome o;
  auto again = cached_granule_tile(d, dir.path, &o);
  ASSERT_TRUE(again.ok());
  EXPECT_NE(o.source, TileCacheOutcome::Source::Disk);
  EXPECT_NE(o.note.find("checksum"), std::string::npos) << o.note;
  EXPECT_TRUE(same_bits(*good, *again));
  EXPECT_TRUE(load_tile(dir.path, key).ok());  // rewritten

  fs::resize_file(path, size - 20);
  r = load_tile(dir.path, key);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("checksum"), std::string::npos) << r.message();

  { std::ofstream f(path, std::ios::binary | std::ios::trunc); f << "PNG\x89 not a tile at all, long enough to be read"; }
  r = load_tile(dir.path, key);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("magic"), std::string::npos) << r.message();

  // A good file stored under another key is refused by its key.
  ASSERT_TRUE(save_tile(dir.path, key, *good).ok());
  fs::copy_file(path, tile_cache_path(dir.path, key + 1));
  r = load_tile(dir.path, key + 1);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.message().find("another key"), std::string::npos) << r.message();

  EXPECT_FALSE(load_tile(dir.path, key + 2).ok());  // missing
}

// A directory that cannot be made still gives the tile; the note names the directory.
TEST(TileCache, UnwritableDirectoryOnlyLosesTheSaving) {
  const GranuleTileDef d = small_def();
  TileCacheOutcome o;
  auto t = cached_granule_tile(d, "/proc/sandpatch_no_such_dir", &o);
  ASSERT_TRUE(t.ok()) << t.message();
  EXPECT_NE(o.note.find("/proc/sandpatch_no_such_dir"), std::string::npos) << o.note;
}

// Every field that changes a settled tile changes the key; the thread count does not.
TEST(TileCache, KeyFollowsTheDefinitionButNotTheThreads) {
  const GranuleTileDef d = small_def();
  const std::uint64_t k = tile_cache_key(d);
  EXPECT_EQ(k, tile_cache_key(d));
  GranuleTileDef t = d;
  t.threads = 2;
  EXPECT_EQ(k, tile_cache_key(t));
  auto differs = [&](auto change) {
    GranuleTileDef c = d;
    change(c);
    return tile_cache_key(c) != k;
  };
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.radius = 0.03f; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.material.friction = 0.6f; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.material.normal_stiffness = 3e4f; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.material.restitution = 0.5f; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.seed = 2; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.layers = 5; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.settle_friction = 0.3f; }));
  EXPECT_TRUE(differs([](GranuleTileDef& c) { c.gravity.y = -9.0f; }));
}

// $SANDPATCH_TILE_CACHE chooses the directory ("off" disables); otherwise the XDG cache.
TEST(TileCache, DirectoryFromTheEnvironment) {
  const char* saved = std::getenv("SANDPATCH_TILE_CACHE");
  const std::string keep = saved ? saved : "";
  ::setenv("SANDPATCH_TILE_CACHE", "off", 1);
  EXPECT_EQ(tile_cache_dir(), "");
  ::setenv("SANDPATCH_TILE_CACHE", "/tmp/x", 1);
  EXPECT_EQ(tile_cache_dir(), "/tmp/x");
  ::unsetenv("SANDPATCH_TILE_CACHE");
  ::setenv("XDG_CACHE_HOME", "/tmp/xdg", 1);
  EXPECT_EQ(tile_cache_dir(), "/tmp/xdg/sandpatch/tiles");
  if (saved) ::setenv("SANDPATCH_TILE_CACHE", keep.c_str(), 1);
}

// A tile the cache directory lacks is read from the read-only fallback (the build's settled
// tiles) rather than settled, bit for bit, and copied into the cache; the fallback is never
// written.
TEST(TileCache, FallbackDirectoryIsReadAndCopiedNeverWritten) {
  TempDir built("fallback_built"), user("fallback_user"), other("fallback_other");
  const GranuleTileDef d = small_def();
  auto settled = cached_granule_tile(d, built.path);  // what a build would have left there
  ASSERT_TRUE(settled.ok()) << settled.message();
  TileCacheOutcome o;
  auto got = cached_granule_tile(d, user.path, &o, built.path);
  ASSERT_TRUE(got.ok()) << got.message();
  EXPECT_EQ(o.source, TileCacheOutcome::Source::Disk) << "read from the fallback, not settled";
  EXPECT_TRUE(same_bits(*settled, *got));
  EXPECT_TRUE(fs::exists(tile_cache_path(user.path, tile_cache_key(d)))) << "copied into the cache";
  // A tile neither has is settled into the cache, not into the fallback.
  GranuleTileDef d2 = d;
  d2.seed += 1;
  auto fresh = cached_granule_tile(d2, other.path, &o, built.path);
  ASSERT_TRUE(fresh.ok()) << fresh.message();
  EXPECT_NE(o.source, TileCacheOutcome::Source::Disk);
  EXPECT_TRUE(fs::exists(tile_cache_path(other.path, tile_cache_key(d2))));
  EXPECT_FALSE(fs::exists(tile_cache_path(built.path, tile_cache_key(d2))));
}
