// Pre-settled granule configurations (docs/manager.md "Pre-settled tiles"; the
// "pregenerated particle configurations" Leach & Marais name as future work, §7).
//
// A block of granules is settled once, at start-up, in a walled box of side P; it becomes a
// tile that repeats in x and z with every other copy mirrored, so that across each seam a
// granule faces its own mirror image and touches it where it touched the box's wall (the
// seam holds like the wall did: no gaps, overlaps of a few % of r), and in y with period P_y
// (a flat cut below the rough top). A patch is filled by repeating the tile
// over the patch and keeping the granules whose centres lie below the surface minus
// `surface_offset`, calibrated when the tile is made so that the kept bed's top (what the
// top-down depth render of §5.2 averages to) renders back at the surface. A smooth cut
// leaves no granule hanging over a removed one. Granules of different tile copies that would
// overlap (at the seams) are left out. The patch starts near rest because every granule came
// from a bed at rest (its contacts' tangential springs start at zero, so it creeps by about
// a spring's stretch before friction holds it).
// Fills deeper than P_y stack copies of the tile; the flat-floor layer of one copy does not
// interlock with the cut top of the copy below, which leaves gaps at the seam (measured:
// surfaces cut just above a seam render up to 0.35 d low), so the tile is made at least as
// deep as the deepest patch. Everything here is in simulation units (unit particle scale).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <vector>

#include "common/error.hpp"
#include "particles/dem.hpp"

namespace sandpatch {

struct GranuleTileDef {
  Material material;            // contact parameters of the granules
  float radius = 0.025f;        // m, sphere radius r
  int columns = 8;              // granules per side of the settling box
  float box_side = 0;           // m, side of the settling box (the tile's horizontal period); 0: columns lattice spacings.
                                // The manager makes it a whole number of heightfield cells so patch sides fall on tile walls.
  int layers = 10;              // lattice layers before settling
  std::uint64_t seed = 1;
  double settle_max_time = 4.0; // s of simulated settling at most
  float settle_speed = 0.003f;  // m/s: settled when every granule is slower
  Vec3 gravity{0.0f, -9.81f, 0.0f};  // m/s², sim units
  int threads = 0;
  // N of the settling runs (dt <= t_c / N). Part of the tile's key. The manager keeps the
  // DEM's default 20 whatever N its patches run at: the tile is a bed at rest, whose contacts
  // balance the weight at any N, so patches at N = 10 and N = 50 share one tile rather than
  // each settling their own at start-up (seconds to minutes).
  int steps_per_contact = 20;
  float surface_probe = 0;      // m, probe radius of the surface the cut is calibrated against (depth_conversion.hpp lower_by_probe)
  // Called after every settling frame with the simulated seconds settled so far and
  // settle_max_time (a bound: settling stops earlier once at rest). Not part of the key.
  std::function<void(double settled_s, double max_s)> on_progress;
  float settle_friction = -1;   // μ while settling (< 0: the material's). Lower packs denser; the packing then
                                // also holds with the material's higher μ.
};

struct PlacedGranule {
  Vec3 position;
  Quat orientation;
};

struct GranuleTile {
  float period_xz = 0;          // m, horizontal repeat
  float period_y = 0;           // m, vertical repeat
  std::vector<PlacedGranule> granules;  // centres in [0, P_xz) × [0, P_y) × [0, P_xz)
  float packing_fraction = 0;   // granule solid volume / tile volume (measured)
  float surface_offset = 0;     // m, granule centres are cut this far below the surface (calibrated)
  float surface_probe = 0;      // m, the probe radius the calibration used
  GranuleShape shape;
  double settle_time = 0;       // s simulated to settle
  float rebound = 0;            // m: how far a fill's rendered top rises as the cut bed unloads (measured)
  float settled_speed = 0;      // m/s, max granule speed when captured
};

// Settles the block and calibrates the cut. Errors name the GranuleTileDef field.
Result<GranuleTile> make_granule_tile(const GranuleTileDef& def);
// The same, remembered for the life of the process (up to 8 definitions): terrains made
// one after another with the same soil (a game's levels, repeated runs, tests) settle their
// tile once. The result does not depend on `threads` (the DEM's result does not), so it is
// not part of the key. `reused` (optional) tells whether it came from memory.
Result<GranuleTile> shared_granule_tile(const GranuleTileDef& def, bool* reused = nullptr);
// Hash of every field of `def` that changes the settled tile (all but `threads`): the key of
// shared_granule_tile's memory and part of the disk cache's key (manager/tile_cache.hpp).
std::uint64_t granule_tile_def_hash(const GranuleTileDef& def);

// Granules filling [0, W] × [0, D] from the floor y = 0 up to surface(x, z) (m), repeated from
// the tile; no two granules overlap (spheres closer than 1.8 r are rejected).
std::vector<PlacedGranule> fill_from_tile(const GranuleTile& tile, float width, float depth,
                                          const std::function<float(float x, float z)>& surface);

// The same fill cut in steps, for a promotion spread over frames (docs/manager.md "No frame
// does a whole patch's work"): step(work) goes on for at most about `work` units (a unit is
// one granule of a tile copy made a candidate; a candidate cut counts 4, the sort of the
// candidates one each and is done whole) and returns whether the cut is done;
// take() then gives the granules fill_from_tile gives, in its order. `surface` is called
// during the steps (what it reads must not change between them).
class FillCut {
 public:
  FillCut(const GranuleTile& tile, float width, float depth, std::function<float(float x, float z)> surface);
  // Leaves out the tile copies (columns of copies across x and z, every layer) that lie
  // wholly within [x0, x1] × [z0, z1] (m, as width and depth): granules the caller will not
  // place, far enough from the rest that no decision about them changes what is kept
  // elsewhere (a candidate is tested only against granules of other copies, closer than 1.8 r,
  // and a copy is a tile period across). Before the first step.
  void skip_copies_within(float x0, float x1, float z0, float z1);
  ~FillCut();
  FillCut(FillCut&&) noexcept;
  FillCut& operator=(FillCut&&) noexcept;
  bool step(std::size_t work);
  bool done() const;
  std::size_t granules() const;  // kept so far
  std::vector<PlacedGranule> take();

 private:
  struct State;
  std::unique_ptr<State> s_;
};

// Mean height of the top of the spheres over [x0, x1] × [z0, z1], sampled on a grid of
// `step` m (what a top-down depth render averages to); `floor` where no sphere is. With
// `probe` > 0 the spheres are grown by `probe` and the tops lowered by it (the surface of
// depth_conversion.hpp's lower_by_probe).
float mean_top_height(const std::vector<PlacedGranule>& granules, const GranuleShape& shape, float x0, float z0,
                      float x1, float z1, float step, float floor, float probe = 0);

}  // namespace sandpatch
