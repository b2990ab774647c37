// Pre-settled granule tiles kept on disk, so a machine settles each soil once.
//
// Settling a tile (manager/granule_tile.hpp) runs the DEM for seconds of simulated time and
// takes 10-100 s of wall time on two cores: it was most of a scene's start-up. A tile is a
// pure function of its GranuleTileDef and of the code that settles it, so it is stored under
// a key made of
//   - every GranuleTileDef field that changes the result (`threads` does not: the DEM's
//     result does not depend on the thread count),
//   - a hash of the sources that compute a tile (particles/, manager/granule_tile.*), made at
//     build time (cmake/hash_sources.cmake), so any change to the DEM or the tile code
//     invalidates every stored tile, and
//   - the state hash of a short DEM probe run in this process, so a different compiler, flags
//     or instruction set that would settle the same code to different bits does too.
// A tile read back is bit-identical to the one computed: a scene's final state hash does not
// depend on whether its tile came from the cache (tests/manager/tile_cache_test.cpp).
//
// The cache is an optimisation and never an error: an unreadable, truncated or corrupt file
// (checked by magic, version, key, sizes, checksum and finite values) is ignored and the tile
// is settled again and rewritten; a directory that cannot be written only loses the saving.
// Files are written whole (to a temporary name, then renamed), so concurrent processes that
// settle the same tile (ctest -j) never read half a file.
//
// Where: the directory given to cached_granule_tile; tile_cache_dir() resolves the default:
// $SANDPATCH_TILE_CACHE ("off" or empty disables), else $XDG_CACHE_HOME/sandpatch/tiles,
// else $HOME/.cache/sandpatch/tiles, else none (disabled). The terrain manager, with that
// default, also reads the build tree's cache (tile_cache_build_dir: the build settles the
// default scene's tiles into it with `sandpatch check --tiles`), so a first run of a fresh
// build does not settle them; a tile found there is copied into the default directory.
#pragma once

#include <cstdint>
#include <string>

#include "common/error.hpp"
#include "manager/granule_tile.hpp"

namespace sandpatch {

// The default cache directory ("" = no disk cache), from the environment (see above).
std::string tile_cache_dir();

// The build tree's tile cache (CMake: <build>/tile_cache), "" if this binary has none or it
// does not exist. Read only.
std::string tile_cache_build_dir();

// Key of a tile definition: the fields, the source hash and the DEM probe (see above).
std::uint64_t tile_cache_key(const GranuleTileDef& def);

// The file a tile of `key` is stored in, inside `dir`.
std::string tile_cache_path(const std::string& dir, std::uint64_t key);

// Writes `tile` as the file of `key` in `dir` (created if missing), whole or not at all.
// Errors name the path and the system's reason.
Status save_tile(const std::string& dir, std::uint64_t key, const GranuleTile& tile);

// Reads the file of `key` from `dir`. Errors name the path and what is wrong with it
// (missing, wrong magic/version/key, truncated, checksum, non-finite value).
Result<GranuleTile> load_tile(const std::string& dir, std::uint64_t key);

struct TileCacheOutcome {
  enum class Source { Disk, Memory, Settled };
  Source source = Source::Settled;
  std::string note;  // why the disk copy was not used or not written ("" when all went well)
};

// The tile of `def`: from `dir` if a valid copy is there, else from this process's memory
// (shared_granule_tile), else settled now; a tile not found on disk is written to `dir`.
// `dir` empty: no disk cache (shared_granule_tile alone). `fallback` (if not empty): a
// directory read, never written, when `dir` has no copy (the build's, tile_cache_build_dir);
// a tile found there is written to `dir`.
Result<GranuleTile> cached_granule_tile(const GranuleTileDef& def, const std::string& dir,
                                        TileCacheOutcome* outcome = nullptr, const std::string& fallback = {});

}  // namespace sandpatch
