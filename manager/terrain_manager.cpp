// The terrain manager: see terrain_manager.hpp.
#include "manager/terrain_manager.hpp"

#include <algorithm>
#include <unordered_set>
#include <unordered_map>
#include <chrono>
#include <deque>
#include <cmath>
#include <numbers>

#include "common/hash.hpp"
#include "gl/context.hpp"
#include "heightfield/filter.hpp"
#include "manager/depth_conversion.hpp"
#include "manager/granule_tile.hpp"
#include "manager/tile_cache.hpp"
#include "manager/shell.hpp"
#include "particles/backend.hpp"
#include "particles/dem.hpp"
#include "particles/fields.hpp"
#include "particles/gpu/gl_backend.hpp"

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

Vec3 v3(const Eigen::Vector3f& v) { return {v.x(), v.y(), v.z()}; }
Eigen::Vector3f eig(Vec3 v) { return {v.x, v.y, v.z}; }
Quat quat(const Eigen::Quaternionf& q) { return {q.x(), q.y(), q.z(), q.w()}; }

// Trapezoid weights of a sample in a region (½ on edges, ¼ at corners): Σ w h sp² is the
// volume under the bilinear surface.
double trapezoid_weight(int i, int j, const GridRegion& r) {
  const double wi = (i == r.i0 || i == r.i0 + r.ni - 1) ? 0.5 : 1.0;
  const double wj = (j == r.j0 || j == r.j0 + r.nj - 1) ? 0.5 : 1.0;
  return wi * wj;
}

}  // namespace

const char* to_string(PatchEventKind k) {
  switch (k) {
    case PatchEventKind::Requested: return "requested";
    case PatchEventKind::Queued: return "queued";
    case PatchEventKind::Promoted: return "promoted";
    case PatchEventKind::Ready: return "ready";
    case PatchEventKind::Asleep: return "asleep";
    case PatchEventKind::Woke: return "woke";
    case PatchEventKind::Demoted: return "demoted";
  }
  return "?";
}

struct TerrainManager::Impl {
  TerrainManagerDef def;
  Heightfield* hf = nullptr;
  BulletWorld* world = nullptr;
  // Pre-settled tiles (granule_tile.hpp), shallowest first. A fill deeper than a tile's
  // vertical period would stack copies, and the seam leaves voids (measured: surfaces just
  // above a seam render 0.75 d low), so a patch takes the shallowest tile that holds its
  // depth, and a deeper one is settled (and kept) when none does.
  // One set of tiles per particle scale in use (scale_bands): a tile is settled in simulation
  // units, its period a whole number of heightfield cells at its scale, under gravity g / s.
  struct TileSet {
    double scale = 1;                 // world size / simulated size
    int cells = 1;                    // heightfield cells per tile period (patch sides fall on tile walls)
    GranuleTileDef def;
    std::vector<GranuleTile> tiles;   // shallowest first
  };
  std::deque<TileSet> tile_sets;      // made at start-up, one per scale (references stay valid)
  double tiles_settled_ms = 0;
  std::string tile_cache;             // resolved directory ("" = no disk cache)
  std::vector<std::string> tile_cache_notes;  // why a stored tile was not used or not written
  int tiles_from[3] = {};             // tiles by TileCacheOutcome::Source: disk, memory, settled
  Eigen::Vector3d camera = Eigen::Vector3d::Zero();  // m, world: the scale bands' centre
  std::unordered_map<std::int64_t, int> still_frames;
  int lapsed_requests = 0;
  int extensions = 0;       // patches grown under a body heading past their edge  // queued requests dropped because no body predicted contact there any more  // frames each body (index, generation) has been at rest

  // Lattice layers that settle into a tile of at least `depth` (m, sim units) of period_y.
  int tile_layers(double fill_depth) const {
    const GranuleShape shape = make_granule_shape(float(def.material.radius), 1.0f, def.material.density);
    const double layer = 2.0 * (shape.centre_distance + shape.radius) * 0.8;  // settled layer height, about
    return std::max(6, int(std::ceil(fill_depth * 1.6 / layer)) + 3);
  }
  // The shallowest tile of a set whose period holds a fill `depth` (m, sim units) deep.
  Result<const GranuleTile*> tile_for(TileSet& set, double fill_depth) {
    std::vector<GranuleTile>& tiles = set.tiles;
    auto holds = [&](const GranuleTile& t) { return fill_depth - t.surface_offset <= t.period_y; };
    for (const GranuleTile& t : tiles)
      if (holds(t)) return &t;
    GranuleTileDef td = set.def;
    td.layers = tile_layers(1.1 * fill_depth);
    for (int attempt = 0; attempt < 3; ++attempt) {
      const auto t0 = Clock::now();
      TileCacheOutcome from;
      auto t = cached_granule_tile(td, tile_cache, &from);
      if (!from.note.empty()) tile_cache_notes.push_back(from.note);
      ++tiles_from[int(from.source)];
      tiles_settled_ms += ms_since(t0);
      if (!t) return t.errors();
      if (holds(*t)) {
        tiles.push_back(std::move(*t));
        std::sort(tiles.begin(), tiles.end(), [](const GranuleTile& a, const GranuleTile& b) { return a.period_y < b.period_y; });
        return tile_for(set, fill_depth);
      }
      // Too shallow: scale the lattice layers by what this one settled to (a block settles
      // to a depth roughly proportional to its layers, less the rough top) and try again.
      const double got = std::max(1e-6, double(t->period_y) + t->surface_offset);
      td.layers = int(std::ceil(td.layers * 1.05 * (fill_depth + 2.0 * double(t->shape.centre_distance + t->shape.radius)) / got));
    }
    return Error{"", "simulation.patch_depth", std::to_string(fill_depth * set.scale),
                 "no pre-settled granule tile this deep could be made; lower terrain.patch_depth"};
  }
  // m³ (world) of one granule's solid at particle scale s.
  double granule_volume(double s) const {
    return 4.0 * 4.0 / 3.0 * std::numbers::pi * std::pow(double(def.material.radius) * s, 3);
  }
  // The scales patches can take: the bands', or the one particle_scale.
  std::vector<double> scales() const {
    std::vector<double> v;
    for (const auto& b : def.scale_bands)
      if (std::find(v.begin(), v.end(), b.particle_scale) == v.end()) v.push_back(b.particle_scale);
    if (v.empty()) v.push_back(def.particle_scale);
    return v;
  }
  // The scale a request is promoted at (Leach & Marais §4.3, §6.3 scenario 2): its own (a
  // patch growing under a body keeps its scale), else the first band whose max_distance reaches
  // the 3-D distance from the camera to the request's centre on the surface (the last band's
  // beyond), else particle_scale.
  double scale_for(const PatchRequest& r) const {
    if (r.particle_scale > 0) return r.particle_scale;
    if (def.scale_bands.empty()) return def.particle_scale;
    const double x = 0.5 * (r.x0 + r.x1), z = 0.5 * (r.z0 + r.z1);
    const double y = hf->origin_y() + hf->sample(float(x - hf->origin_x()), float(z - hf->origin_z()));
    const double d = (Eigen::Vector3d(x, y, z) - camera).norm();
    for (const auto& b : def.scale_bands)
      if (d <= b.max_distance) return b.particle_scale;
    return def.scale_bands.back().particle_scale;
  }
  TileSet& set_for(double s) {
    for (TileSet& t : tile_sets)
      if (t.scale == s) return t;
    return tile_sets.front();  // not reached: every scale a request can take has a set from create()
  }
  const TileSet& set_for(double s) const { return const_cast<Impl*>(this)->set_for(s); }
  int max_cells() const {
    int c = 1;
    for (const TileSet& t : tile_sets) c = std::max(c, t.cells);
    return c;
  }

  enum class State { Free, Filling, Active, Asleep };
  struct Carried {
    RigidBodyId body;
    sandpatch::BodyId shell;
    bool enabled = true;
    Eigen::Vector3f v0 = Eigen::Vector3f::Zero(), w0 = Eigen::Vector3f::Zero();  // world velocities at the frame start
  };
  struct Ledger {
    double before = 0, active = 0, after = 0;  // m³
    bool closed = false;
  };
  struct Slot {
    std::unique_ptr<DemBackend> sim;
    State state = State::Free;
    int patch = -1;            // id of the patch in the slot
    GridRegion region;         // heightfield samples of the patch
    GridRegion apron;          // region + the band where spilled granules may rest
    Eigen::Vector3d origin;    // m, world: sim (0,0,0)
    double floor_local = 0;    // m, floor height relative to the heightfield origin
    double top_local = 0;      // m, highest surface sample of the region at promotion
    std::vector<PlacedGranule> pending;
    std::size_t uploaded = 0;
    int granules = 0;
    int fade = 0;
    double asleep_for = 0;     // s asleep and untouched
    double fill_ms = 0;
    std::vector<float> before_heights;  // heights of `apron` at promotion
    double scale = 1;          // world size / simulated size of this patch, fixed while it lives
    std::vector<float> fill_spheres;    // the granule spheres as filled (x, y, z, r; m, heightfield-local): the
                                        // demotion renders them too, so its render error cancels where nothing moved
    float fill_rise = 0;                // m, the tile's elastic rebound (GranuleTile::rebound), world
    std::vector<Carried> carried;
    Ledger ledger;
    explicit Slot(std::unique_ptr<DemBackend> s) : sim(std::move(s)) {}
  };
  // The GL context (the GL backend's and the depth render's) outlives the slots: declared first.
  std::unique_ptr<gl::Context> gl;
  std::vector<Slot> slots;
  std::vector<PatchRequest> queue;
  std::vector<PatchEvent> events;
  int next_patch = 0;
  int peak_slots = 0;
  int peak_queue = 0;
  std::vector<nlohmann::ordered_json> ledgers;  // closed ledgers (demoted patches)
  std::vector<GridRegion> dirty;                // written by demotions, not yet taken

  // The demotion's GL depth render (create(): when use_gl and a context could be made; else
  // null, gl_note says why, and demotions render on the CPU).
  std::unique_ptr<ParticleDepthRenderer> depth;
  std::string gl_note;

  // The depth render on GL when def.use_gl: the context (the GL backend's, or a new one) and
  // the renderer; without them gl_note says why and demotions render on the CPU.
  Status make_depth_renderer() {
    if (!def.use_gl) return Ok{};
    if (!gl) {
      auto ctx = gl::Context::create();
      if (!ctx) {
        gl_note = ctx.message();
        return Ok{};
      }
      gl = std::move(*ctx);
    }
    if (Status st = gl->make_current(); !st) return st;
    auto dr = ParticleDepthRenderer::create({def.depth_resolution});
    if (dr) depth = std::move(*dr);
    else gl_note = dr.message();
    return Ok{};
  }

  // The GL backend's context must be current for any slot call (other GL users of the
  // thread, e.g. the image writer, make their own current in between). The CPU backend's
  // slots need none: there the manager's context (made at creation for the depth render) is
  // made current by the depth render alone, as before it was made at the first demotion, so
  // a caller's context current between frames stays current (manager/run.cpp's image writer
  // updates its terrain textures after after_bodies without making its own current: with
  // the manager's context made current every frame, those updates went to the wrong context
  // and the next GL depth render failed with GL_INVALID_OPERATION).
  void current() const {
    if (gl && def.backend == "gl") (void)gl->make_current();
  }
  // m (world): a body's shell joins a patch when the body's lowest point is within half of
  // this above the patch's highest surface point; the simulation's domain reaches this high.
  static constexpr double engage_height = 1.0;
  float radius_world(double s) const { return float(def.material.radius * s); }
  float radius_world(const Slot& slot) const { return radius_world(slot.scale); }

  // World <-> heightfield sample index helpers.
  int sample_i(double x) const { return int(std::floor((x - hf->origin_x()) / hf->spacing())); }
  int sample_j(double z) const { return int(std::floor((z - hf->origin_z()) / hf->spacing())); }

  SimulationDef sim_def(double scale) const {
    SimulationDef sd;
    sd.max_bodies = def.granules_per_slot + 64;
    sd.max_particles = 4 * def.granules_per_slot + def.shell_particles_per_slot;
    sd.particle_radius = def.material.radius;
    sd.material.density = def.material.density;
    sd.material.normal_stiffness = def.material.stiffness;
    sd.material.restitution = def.material.restitution;
    sd.material.friction = def.material.friction;
    sd.material.tangential_stiffness_ratio = def.material.tangential_stiffness_ratio;
    sd.gravity_world = v3(Eigen::Vector3f(def.gravity.cast<float>()));
    sd.sleep_speed = float(def.sleep_speed / scale);
    sd.sleep_time = float(def.sleep_time);
    sd.threads = def.threads;
    // dt <= t_c / N; a frame may take as many substeps as 64 at N = 20 allowed (the same
    // frame length in contact times), so a finer N never refuses a frame a coarser one runs.
    sd.accuracy_steps_per_contact = def.steps_per_contact;
    sd.max_substeps = std::max(64, (64 * def.steps_per_contact + 19) / 20);
    // The DEM's overlap guard refuses a step when a body could overlap something immovable by
    // more than a fraction of r. In a patch a body lands on granules that give way (a 30 kg
    // barrel at 3 m/s on k_n = 2e4 N/m trips it while the bed stops it within 0.2 m:
    // TerrainManager.BarrelLeavesCraterAndRim), and refusing a frame mid-run helps no one; so
    // the guard is off here and the patch floor, 2 granule layers deep at least, stops bodies.
    sd.max_overlap_fraction = 0;
    return sd;
  }

  // ---- activation ----
  // Floor of a patch over `region` (m, heightfield-local): patch_depth below the lowest
  // surface sample, and never below the bedrock under any sample of the region (the DEM's
  // floor is one plane, so it sits at the highest bedrock point: no granule below the
  // bedrock anywhere; where the surface dips below that plane the patch has no granules and
  // its floor holds bodies up to that much above the surface, docs/extremes.md). `lo`, `hi`:
  // the lowest and highest surface samples. A floor at or above `hi`: no soil, no patch.
  double floor_of(const GridRegion& region, float* lo, float* hi) const {
    *lo = std::numeric_limits<float>::max(), *hi = -*lo;
    double bedrock = -std::numeric_limits<double>::infinity();
    for (int j = region.j0; j < region.j0 + region.nj; ++j)
      for (int i = region.i0; i < region.i0 + region.ni; ++i) {
        const float h = hf->height(i, j);
        *lo = std::min(*lo, h);
        *hi = std::max(*hi, h);
        bedrock = std::max({bedrock, double(h) - def.soil_depth, std::min(double(h), def.bedrock_height)});
      }
    return std::max(double(*lo) - def.patch_depth, bedrock);
  }
  // The terrain's world rectangle.
  PatchRequest terrain_rect() const {
    PatchRequest t;
    t.x0 = hf->origin_x();
    t.z0 = hf->origin_z();
    t.x1 = t.x0 + (hf->samples_x() - 1) * double(hf->spacing());
    t.z1 = t.z0 + (hf->samples_z() - 1) * double(hf->spacing());
    return t;
  }
  void clip_to_terrain(PatchRequest& r) const {
    const PatchRequest t = terrain_rect();
    r.x0 = std::max(r.x0, t.x0), r.z0 = std::max(r.z0, t.z0);
    r.x1 = std::min(r.x1, t.x1), r.z1 = std::min(r.z1, t.z1);
  }
  // m: the widest square request that merging may make, so that one slot holds its patch: the
  // side of a patch_depth-deep square of granules_per_slot granules at the first tile's
  // packing, with 20 % to spare, less the rounding out to whole tile periods (region_for:
  // up to one period and a sample on each axis). Requests wider than that are not merged
  // (each single request is still checked against the capacity in promote()).
  double max_merged_side() const {
    const double fill = std::min(def.patch_depth, def.soil_depth);  // m
    // (With scale bands, at the finest scale: the most granules per area.)
    double side = std::numeric_limits<double>::max();
    for (const TileSet& t : tile_sets) {
      const double pf = t.tiles.empty() ? 0.5 : t.tiles.front().packing_fraction;
      const double area = def.granules_per_slot * granule_volume(t.scale) / (pf * std::max(fill, 1e-6)) / 1.2;  // m²
      side = std::min(side, std::sqrt(area) - (max_cells() + 1) * double(hf->spacing()));
    }
    return side;
  }
  // Whether a request can become a patch: its region is on the terrain and has soil above the
  // bedrock. (A body falling just past the terrain's edge, or onto bare rock, asks for a
  // patch that cannot exist; before, promote() failed the whole frame with an error.)
  bool has_soil(const PatchRequest& r) const {
    auto reg = region_for(r, set_for(scale_for(r)).cells);
    if (!reg) return false;
    float lo = 0, hi = 0;
    return floor_of(*reg, &lo, &hi) < hi;
  }
  // Region of heightfield samples for a request, within what one slot can hold.
  Result<GridRegion> region_for(const PatchRequest& r, int tile_cells) const {
    int i0 = std::max(0, sample_i(r.x0)), j0 = std::max(0, sample_j(r.z0));
    int i1 = std::min(hf->samples_x() - 1, sample_i(r.x1) + 1), j1 = std::min(hf->samples_z() - 1, sample_j(r.z1) + 1);
    if (i1 - i0 < 2 || j1 - j0 < 2) return Error{"", "patch request", "", "off the terrain"};
    // Whole tile periods: the patch's sides then fall on the walls the tile was settled
    // against, so the granules along them sit as they settled (granule_tile.hpp).
    auto align = [&](int& a, int& b, int samples) {
      const int cells = b - a, whole = ((cells + tile_cells - 1) / tile_cells) * tile_cells;
      if (whole > samples - 1) return;  // terrain narrower than the rounded patch: keep the cut sides
      a -= (whole - cells) / 2;
      b = a + whole;
      if (a < 0) b -= a, a = 0;
      if (b > samples - 1) a -= b - (samples - 1), b = samples - 1;
    };
    align(i0, i1, hf->samples_x());
    align(j0, j1, hf->samples_z());
    return GridRegion{i0, j0, i1 - i0 + 1, j1 - j0 + 1};
  }

  bool covered(const PatchRequest& r) const {
    for (const Slot& s : slots) {
      if (s.state == State::Free) continue;
      const double sp = hf->spacing();
      const double x0 = hf->origin_x() + s.region.i0 * sp, x1 = x0 + (s.region.ni - 1) * sp;
      const double z0 = hf->origin_z() + s.region.j0 * sp, z1 = z0 + (s.region.nj - 1) * sp;
      if (r.x0 >= x0 && r.x1 <= x1 && r.z0 >= z0 && r.z1 <= z1) return true;
    }
    return false;
  }

  // The world rectangle of a slot's region.
  PatchRequest rect(const Slot& s) const {
    const double sp = hf->spacing();
    PatchRequest p;
    p.x0 = hf->origin_x() + s.region.i0 * sp;
    p.x1 = p.x0 + (s.region.ni - 1) * sp;
    p.z0 = hf->origin_z() + s.region.j0 * sp;
    p.z1 = p.z0 + (s.region.nj - 1) * sp;
    return p;
  }

  bool overlaps_patch(const PatchRequest& r) const {
    for (const Slot& s : slots)
      if (s.state != State::Free && rect(s).overlaps(r)) return true;
    return false;
  }

  // A body in a patch heading past its edge (its predicted contact reaches beyond the
  // region): the patch grows to cover both, if the slot holds the grown patch (estimated from
  // its granules per area, with 20 % to spare). The patch is demoted now (what the body did
  // is written to the heightfield) and the grown request goes to the front of the queue, so
  // it is promoted in this frame from the slot just freed: nothing is lost, and the body
  // stays on particles. Returns whether it did.
  Result<bool> extend(const PatchRequest& r, double time) {
    for (Slot& s : slots) {
      if ((s.state != State::Active && s.state != State::Asleep) || !rect(s).overlaps(r)) continue;
      const PatchRequest a = rect(s);
      // Only when the predicted contact itself (the request without its apron) comes within
      // two granule diameters of the patch's edge: a body settling near the middle whose
      // apron pokes out by a few mm must not make the patch grow.
      // A side of the patch on the terrain's edge cannot be crossed (requests are clipped there).
      const double m = 4.0 * radius_world(s), ap = def.lod.apron, e = 1e-6;
      const int tile_cells = set_for(s.scale).cells;
      const PatchRequest t = terrain_rect();
      const bool in_x0 = a.x0 <= t.x0 + e || r.x0 + ap >= a.x0 + m, in_x1 = a.x1 >= t.x1 - e || r.x1 - ap <= a.x1 - m;
      const bool in_z0 = a.z0 <= t.z0 + e || r.z0 + ap >= a.z0 + m, in_z1 = a.z1 >= t.z1 - e || r.z1 - ap <= a.z1 - m;
      if (in_x0 && in_x1 && in_z0 && in_z1) return false;
      PatchRequest u = r;
      u.x0 = std::min(a.x0, r.x0), u.z0 = std::min(a.z0, r.z0), u.x1 = std::max(a.x1, r.x1), u.z1 = std::max(a.z1, r.z1);
      const double grow = (u.x1 - u.x0 + 2 * hf->spacing() * tile_cells) * (u.z1 - u.z0 + 2 * hf->spacing() * tile_cells) /
                          std::max(1e-9, (a.x1 - a.x0) * (a.z1 - a.z0));
      if (double(s.granules) * grow * 1.2 > double(def.granules_per_slot)) return false;
      if (Status st = demote(s, time, false); !st) return st.errors();
      u.time_to_contact = 0;
      u.particle_scale = s.scale;  // the grown patch keeps its scale
      queue.insert(queue.begin(), u);
      ++extensions;
      return true;
    }
    return false;
  }

  Status promote(Slot& slot, const PatchRequest& req, double time) {
    const auto t0 = Clock::now();
    const double s = scale_for(req);
    TileSet& tset = set_for(s);
    auto reg = region_for(req, tset.cells);
    if (!reg) return reg.errors();
    const GridRegion region = *reg;
    const float sp = hf->spacing();
    float lo = 0, hi = 0;
    const double floor_local = floor_of(region, &lo, &hi);
    if (!(floor_local < hi)) return Error{"", "patch request", "", "no soil above the bedrock there"};
    slot.patch = next_patch++;
    slot.scale = s;
    slot.region = region;
    const int band = 4;  // samples around the region where spilled granules rest on the terrain
    slot.apron = {std::max(0, region.i0 - band), std::max(0, region.j0 - band), 0, 0};
    slot.apron.ni = std::min(hf->samples_x(), region.i0 + region.ni + band) - slot.apron.i0;
    slot.apron.nj = std::min(hf->samples_z(), region.j0 + region.nj + band) - slot.apron.j0;
    slot.floor_local = floor_local;
    slot.top_local = hi;
    slot.origin = {hf->origin_x() + region.i0 * double(sp), hf->origin_y() + floor_local,
                   hf->origin_z() + region.j0 * double(sp)};
    slot.before_heights.resize(std::size_t(slot.apron.ni) * slot.apron.nj);
    hf->read(slot.apron, slot.before_heights.data());

    // The simulation: unit scale, patch-relative; the terrain around the region as a grid.
    SimulationDef sd = sim_def(s);
    const float W = float((region.ni - 1) * double(sp) / s), D = float((region.nj - 1) * double(sp) / s);
    const float top = float((hi - floor_local) / s);
    sd.bounds_min = {0, 0, 0};
    // Room above the surface for bodies' shells (spheres above the grid would all share its
    // top layer of cells and slow the search); shells engage only within `engage_height`.
    sd.bounds_max = {W, top + float(engage_height / s) + 2.0f * float(def.material.radius), D};
    sd.floor_height = 0;
    auto sc = ParticleScale::create(s, {slot.origin.x(), slot.origin.y(), slot.origin.z()});
    if (!sc) return sc.errors();
    sd.scale = *sc;
    TerrainGrid& tg = sd.terrain;
    tg.nx = slot.apron.ni;
    tg.nz = slot.apron.nj;
    tg.x0 = float((slot.apron.i0 - region.i0) * double(sp) / s);
    tg.z0 = float((slot.apron.j0 - region.j0) * double(sp) / s);
    tg.spacing = float(sp / s);
    tg.heights.resize(slot.before_heights.size());
    for (std::size_t k = 0; k < tg.heights.size(); ++k) tg.heights[k] = float((slot.before_heights[k] - floor_local) / s);
    tg.fill_min_x = 0;
    tg.fill_min_z = 0;
    tg.fill_max_x = W;
    tg.fill_max_z = D;
    if (Status st = slot.sim->reset(sd); !st) return st.errors();

    // Granules from the pre-settled tile, cut to the surface.
    auto surface = [&](float x, float z) {
      const double xl = region.i0 * double(sp) + x * s, zl = region.j0 * double(sp) + z * s;
      return float((hf->sample(float(xl), float(zl)) - floor_local) / s);
    };
    auto tile_r = tile_for(tset, top);
    if (!tile_r) return tile_r.errors();
    const GranuleTile& tile = **tile_r;
    slot.pending = fill_from_tile(tile, W, D, surface);
    if (int(slot.pending.size()) > def.granules_per_slot) {
      return Error{"", "simulation.pool.granules_per_slot", std::to_string(def.granules_per_slot),
                   "too small: the patch around the contact at (" + std::to_string(0.5 * (req.x0 + req.x1)) + ", " +
                       std::to_string(0.5 * (req.z0 + req.z1)) + ") needs " + std::to_string(slot.pending.size()) +
                       " granules; raise it, or lower terrain.soil_depth / coarsen the granules"};
    }
    // The fill's spheres, heightfield-local (m), for the demotion's render baseline.
    slot.fill_rise = float(tile.rebound * s);
    slot.fill_spheres.clear();
    slot.fill_spheres.reserve(16 * slot.pending.size());
    for (const PlacedGranule& g : slot.pending)
      for (const Vec3& o : tile.shape.offsets) {
        const auto w = sc->position_to_world(g.position + rotate(g.orientation, o));
        slot.fill_spheres.insert(slot.fill_spheres.end(), {float(w[0] - hf->origin_x()), float(w[1] - hf->origin_y()),
                                                           float(w[2] - hf->origin_z()), radius_world(s)});
      }
    slot.uploaded = 0;
    slot.granules = 0;
    slot.fade = 0;
    slot.asleep_for = 0;
    slot.carried.clear();
    slot.state = State::Filling;
    // Ledger: volume between the floor and the surface over the region.
    double v = 0;
    for (int j = region.j0; j < region.j0 + region.nj; ++j)
      for (int i = region.i0; i < region.i0 + region.ni; ++i)
        v += trapezoid_weight(i, j, region) * (hf->height(i, j) - floor_local);
    slot.ledger = Ledger{};
    slot.ledger.before = v * double(sp) * sp;
    slot.ledger.active = double(slot.pending.size()) * granule_volume(s) / tile.packing_fraction;
    slot.fill_ms = ms_since(t0);
    events.push_back({PatchEventKind::Promoted, slot.patch, time, slot.fill_ms, int(slot.pending.size())});
    return Ok{};
  }

  // Uploads up to `budget` pending granules; the patch is Ready when all are in.
  Status upload(Slot& slot, std::size_t budget, double time) {
    const auto t0 = Clock::now();
    const std::size_t end = std::min(slot.pending.size(), slot.uploaded + budget);
    for (; slot.uploaded < end; ++slot.uploaded) {
      const PlacedGranule& g = slot.pending[slot.uploaded];
      auto id = slot.sim->add_granule(g.position, g.orientation);
      if (!id) return id.errors();
      ++slot.granules;
    }
    slot.fill_ms += ms_since(t0);
    if (slot.uploaded == slot.pending.size()) {
      slot.pending.clear();
      slot.pending.shrink_to_fit();
      slot.state = State::Active;
      events.push_back({PatchEventKind::Ready, slot.patch, time, slot.fill_ms, slot.granules});
    }
    return Ok{};
  }

  // ---- coupling ----
  // Whether a body's bounds reach into a slot's region (and down to its granules).
  // `inside`: the footprint lies within the patch's DEM terrain, the filled region and the
  // apron around it, where the simulation's terrain grid is solid up to the surface.
  bool engages(const Slot& s, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, bool* inside) const {
    const double sp = hf->spacing();
    const double x0 = hf->origin_x() + s.region.i0 * sp, x1 = x0 + (s.region.ni - 1) * sp;
    const double z0 = hf->origin_z() + s.region.j0 * sp, z1 = z0 + (s.region.nj - 1) * sp;
    const double surface_top = hf->origin_y() + s.top_local;
    const bool overlap = lo.x() < x1 && hi.x() > x0 && lo.z() < z1 && hi.z() > z0 && lo.y() < surface_top + 0.5 * engage_height;
    // Within the filled region the granules carry the body; a body across the region's edge
    // rests partly on the terrain grid outside it. Both are in the DEM, so a body anywhere over
    // the DEM's terrain (region + apron) is carried by the DEM alone: with the heightfield too,
    // a body at rest across the edge was held by Bullet at the heightfield's surface while its
    // shell (which keeps its own state while the body rests) settled lower into the granules,
    // so the DEM's force pulled the body down by up to its weight and the heightfield pushed
    // back twice it (measured, ExtremesManager.HundredBodiesAtOnceOnTwoSlots: -19.6 N and
    // +39.2 N on a 2 kg sphere), and the patch never slept.
    const double ax0 = hf->origin_x() + s.apron.i0 * sp, ax1 = hf->origin_x() + (s.apron.i0 + s.apron.ni - 1) * sp;
    const double az0 = hf->origin_z() + s.apron.j0 * sp, az1 = hf->origin_z() + (s.apron.j0 + s.apron.nj - 1) * sp;
    // Outside the region the DEM's ground is the higher of its floor plane and the terrain
    // grid, so it is the heightfield only where the surface is above the floor (not over bare
    // rock below a flat bedrock's floor, docs/extremes.md): there the heightfield stays on
    // (ExtremesManager.FlatBedrockMeetingTheSurface: a body held up on the floor plane over the
    // rock pushed granules onto it, which raised the rock by 11 cm).
    const double margin = 2.0 * radius_world(s);
    *inside = lo.x() > x0 + margin && hi.x() < x1 - margin && lo.z() > z0 + margin && hi.z() < z1 - margin;
    if (!*inside && lo.x() > ax0 + margin && hi.x() < ax1 - margin && lo.z() > az0 + margin && hi.z() < az1 - margin) {
      bool faithful = true;
      const int i0 = std::max(0, int(std::floor((lo.x() - hf->origin_x()) / sp)));
      const int i1 = std::min(hf->samples_x() - 1, int(std::ceil((hi.x() - hf->origin_x()) / sp)));
      const int j0 = std::max(0, int(std::floor((lo.z() - hf->origin_z()) / sp)));
      const int j1 = std::min(hf->samples_z() - 1, int(std::ceil((hi.z() - hf->origin_z()) / sp)));
      for (int j = j0; j <= j1 && faithful; ++j)
        for (int i = i0; i <= i1 && faithful; ++i) faithful = hf->height(i, j) > s.floor_local;
      *inside = faithful;
    }
    return overlap;
  }

  // One carrier per body. A body over two patches at once (resting across the seam of
  // adjacent patches) had a shell in both, and each DEM, supporting it on its granules and on
  // its terrain grid outside its region, gave Bullet the full support force: measured in
  // ExtremesManager.HundredBodiesAtOnceOnTwoSlots, 30.6 N + 18.3 N upwards on a 2 kg sphere
  // (weight 19.6 N), which bounced at 0.24-0.34 m/s and kept both patches awake. Now a
  // body is carried by the ready patch that holds most of its footprint (the one carrying it
  // keeps it while it holds at least half as much as another: no flip-flop), and only that
  // patch sets its heightfield collision. Key: (index << 32 | generation) -> slot index.
  std::unordered_map<std::int64_t, int> carrier;
  // Bodies a demotion set down on the new heights, until this simulated time (s): their first
  // Bullet step on the changed heightfield falls g dt (0.16 m/s) before the contact holds them,
  // which asked for a new patch at once; promoted under bodies sunk into the old one's crater,
  // it threw them out of its fill at 1-3 m/s (measured in the hundred-bodies case). Until then
  // they ask for no patch and no patch takes them up.
  std::unordered_map<std::int64_t, double> set_down_until;
  double now = 0;  // s, simulated time of the frame being run
  bool settling(RigidBodyId b) const {
    const auto it = set_down_until.find(body_key(b));
    return it != set_down_until.end() && now < it->second;
  }
  static std::int64_t body_key(RigidBodyId b) { return (std::int64_t(b.index) << 32) | std::uint32_t(b.generation); }
  void choose_carriers() {
    std::unordered_map<std::int64_t, int> next;
    for (RigidBodyId b : world->bodies()) {
      Eigen::Vector3d lo, hi;
      world->bounds(b, &lo, &hi);
      const auto prev = carrier.find(body_key(b));
      int best = -1;
      double best_area = -1, prev_area = -1;
      for (int k = 0; k < int(slots.size()); ++k) {
        const Slot& sl = slots[std::size_t(k)];
        if (sl.state != State::Active && sl.state != State::Asleep) continue;
        bool inside = false;
        if (!engages(sl, lo, hi, &inside)) continue;
        const PatchRequest r = rect(sl);
        const double area = std::max(0.0, std::min(hi.x(), r.x1) - std::max(lo.x(), r.x0)) *
                            std::max(0.0, std::min(hi.z(), r.z1) - std::max(lo.z(), r.z0));
        if (area > best_area) best = k, best_area = area;
        if (prev != carrier.end() && prev->second == k) prev_area = area;
      }
      if (best < 0) continue;
      if (prev_area >= 0 && prev_area >= 0.5 * best_area) {
        next[body_key(b)] = prev->second;
        continue;
      }
      // A body lying on the terrain is not taken up by a patch it is not in yet: it lies where
      // its last patch or the heightfield left it, at or below the surface the new patch's fill
      // was cut to (sunk into the granules of a patch just demoted), and the top granules of a
      // fill reach about a granule radius above that surface; a shell started there was thrown
      // out at 1-3 m/s (measured in the hundred-bodies case). It is taken when it moves.
      if (lying(b, lo, hi) || settling(b)) {
        if (prev_area >= 0) next[body_key(b)] = prev->second;  // nor handed to another one
        continue;
      }
      next[body_key(b)] = best;
    }
    carrier.swap(next);
  }
  // A body lying on the terrain: its lowest point within one granule diameter (at the coarsest
  // scale) of the surface under its centre, slower than 10 sleep_speed (m/s; Bullet's contacts
  // on the heightfield jitter resting bodies at about sleep_speed).
  bool lying(RigidBodyId b, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) const {
    const BodyState st = world->state(b);
    const double reach = 0.5 * (hi - lo).norm(), slow = 10.0 * def.sleep_speed;
    if (st.linear_velocity.norm() >= slow || st.angular_velocity.norm() * reach >= slow) return false;
    double s_max = 0;
    for (double sc : scales()) s_max = std::max(s_max, sc);
    const double cx = 0.5 * (lo.x() + hi.x()) - hf->origin_x(), cz = 0.5 * (lo.z() + hi.z()) - hf->origin_z();
    const double surface = hf->origin_y() + hf->sample(float(cx), float(cz));
    return lo.y() < surface + 2.0 * def.material.radius * s_max;
  }
  // Whether slot `k` carries body b (see `carrier`).
  bool carries(int k, RigidBodyId b) const {
    const auto it = carrier.find(body_key(b));
    return it != carrier.end() && it->second == k;
  }
  bool carried_anywhere(RigidBodyId b) const { return carrier.count(body_key(b)) > 0; }

  Status couple_before(Slot& slot, double dt) {
    const double s = slot.scale;
    const int self = int(&slot - slots.data());
    // Bodies removed from the world since the last frame: their shells leave the patch.
    for (auto it = slot.carried.begin(); it != slot.carried.end();) {
      if (world->alive(it->body)) {
        ++it;
        continue;
      }
      if (Status e = slot.sim->set_body_enabled(it->shell, false); !e) return e.errors();
      it = slot.carried.erase(it);
    }
    for (RigidBodyId b : world->bodies()) {
      Eigen::Vector3d lo, hi;
      world->bounds(b, &lo, &hi);
      bool inside = false;
      const bool touch = engages(slot, lo, hi, &inside) && carries(self, b);
      auto it = std::find_if(slot.carried.begin(), slot.carried.end(),
                             [&](const Carried& c) { return c.body.index == b.index && c.body.generation == b.generation; });
      if (!touch && it == slot.carried.end()) continue;
      const BodyState st = world->state(b);
      const bool fresh = it == slot.carried.end();
      if (fresh) {
        auto pts = shell_points(b, s);
        if (!pts) return pts.errors();
        ShellDef sh;
        for (const auto& p : *pts) sh.offsets.push_back(v3(p));
        sh.radii = {def.material.radius};
        sh.motion = MotionType::Dynamic;
        sh.mass = world->mass(b);  // the body enters with its own mass (mass ratio 1)
        sh.inertia = v3(Eigen::Vector3f(world->principal_inertia(b) / float(s * s)));
        sh.position = slot.sim->def().scale.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
        sh.orientation = quat(st.orientation);
        auto id = slot.sim->add_shell(sh);
        if (!id) return id.errors();
        slot.carried.push_back({b, *id, true, Eigen::Vector3f::Zero(), Eigen::Vector3f::Zero()});
        it = slot.carried.end() - 1;
      }
      Carried& c = *it;
      const bool reenabled = touch && !c.enabled;  // parked until now: its state must be set
      if (touch != c.enabled) {
        if (Status e = slot.sim->set_body_enabled(c.shell, touch); !e) return e.errors();
        c.enabled = touch;
      }
      // Only the carrier decides the heightfield collision; a body no patch carries meets it.
      if (touch) world->set_terrain_collision(b, !inside);
      else if (!carried_anywhere(b)) world->set_terrain_collision(b, true);
      if (!touch) continue;
      // The shell starts the frame where Bullet has the body.
      c.v0 = st.linear_velocity;
      c.w0 = st.angular_velocity;
      // A body at rest keeps the shell's own state: setting it wakes the patch and restarts
      // its sleep clock (a patch carrying a resting body never fell asleep before this).
      Eigen::Vector3d blo, bhi;
      world->bounds(b, &blo, &bhi);
      const double reach = 0.5 * (bhi - blo).norm();
      const bool at_rest = st.linear_velocity.norm() <= def.sleep_speed && st.angular_velocity.norm() * reach <= def.sleep_speed;
      if (at_rest && !fresh && !reenabled) continue;
      const Vec3 p = slot.sim->def().scale.position_to_sim({st.position.x(), st.position.y(), st.position.z()});
      if (Status e = slot.sim->set_body_state(c.shell, p, quat(st.orientation), v3(Eigen::Vector3f(st.linear_velocity / float(s))),
                                             v3(st.angular_velocity));
          !e)
        return e.errors();
      if (st.linear_velocity.norm() > def.sleep_speed) slot.sim->wake();
    }
    (void)dt;
    return Ok{};
  }

  // While a patch sleeps, the bodies it carries rest on it: Bullet gets their weight back as
  // the support force, so they stay where the patch left them.
  void hold_resting_bodies(Slot& slot) {
    for (const Carried& c : slot.carried)
      if (c.enabled && world->alive(c.body))
        world->apply_force(c.body, -world->mass(c.body) * def.gravity.cast<float>(), Eigen::Vector3f::Zero());
  }

  void couple_after(Slot& slot, double dt) {
    const double s = slot.scale;
    for (const Carried& c : slot.carried) {
      if (!c.enabled || !world->alive(c.body)) continue;
      // Mean contact force and torque over the frame from the shell's change of momentum.
      const Eigen::Vector3f v1 = eig(slot.sim->body_velocity(c.shell)) * float(s);
      const Eigen::Vector3f w1 = eig(slot.sim->body_angular_velocity(c.shell));
      const float m = world->mass(c.body);
      const Eigen::Vector3f f = m * ((v1 - c.v0) / float(dt) - def.gravity.cast<float>());
      const Eigen::Matrix3f R = world->state(c.body).orientation.toRotationMatrix();
      const Eigen::Matrix3f I = R * world->principal_inertia(c.body).asDiagonal() * R.transpose();
      const Eigen::Vector3f t = I * (w1 - c.w0) / float(dt);
      world->apply_force(c.body, f, t);
    }
  }

  // Appends the slot's granule spheres (x, y, z, r; m, heightfield-local). Granules are the
  // first bodies of a patch, so their spheres have the first 4 × granules particle ids.
  void granule_spheres(const Slot& slot, std::vector<float>& xyzr) const {
    const std::vector<Vec3> pos = slot.sim->particle_positions();
    const std::size_t n = std::min(pos.size(), std::size_t(4) * std::size_t(slot.granules));
    const float rw = radius_world(slot);
    for (std::size_t k = 0; k < n; ++k) {
      const auto w = slot.sim->def().scale.position_to_world(pos[k]);
      xyzr.insert(xyzr.end(), {float(w[0] - hf->origin_x()), float(w[1] - hf->origin_y()), float(w[2] - hf->origin_z()), rw});
    }
  }

  // A body's shell: its surface sampled at the granule sphere spacing (sim units). Meshes go
  // through their signed distance field (0.2–0.9 s for a few thousand triangles), cached by
  // sample_shell per mesh; before_bodies asks once for every new body, so the cost falls in
  // the frame the body appears, not in the frame it first touches a patch.
  Result<std::vector<Eigen::Vector3f>> shell_points(RigidBodyId b, double scale) const {
    RigidShape shape = world->definition(b).shape;
    const float inv = float(1.0 / scale);
    shape.radius *= inv;
    shape.height *= inv;
    shape.half_extents *= inv;
    for (auto& v : shape.vertices) v *= inv;
    return sample_shell(shape, 1.5f * def.material.radius, def.material.radius, def.shell_particles_per_slot);
  }
  std::unordered_set<std::int64_t> shells_sampled;  // bodies whose shell was sampled ahead (index << 32 | generation)

  // ---- demotion ----
  // `gl_ok`: the depth render may use GL (false: the CPU depth render, same contract). A
  // patch grown mid-frame (extend) is demoted on the CPU: demoting on GL there left the
  // manager's context in a state where the next GL depth render failed with
  // GL_INVALID_OPERATION (measured on llvmpipe; cause not found yet).
  Status demote(Slot& slot, double time, bool gl_ok = true) {
    const auto t0 = Clock::now();
    const double sp = hf->spacing();
    // Granule spheres in heightfield-local coordinates (m), now and as filled.
    std::vector<float> xyzr;
    granule_spheres(slot, xyzr);
    std::vector<float> filled = slot.fill_spheres;
    // Spheres grown by the probe radius, tops lowered by it after the render (lower_by_probe).
    const float rw = radius_world(slot);
    const float probe = float(def.surface_probe) * rw;
    for (std::size_t k = 3; k < xyzr.size(); k += 4) xyzr[k] += probe;
    for (std::size_t k = 3; k < filled.size(); k += 4) filled[k] += probe;
    float top = float(slot.floor_local) + rw + probe;
    for (std::size_t k = 1; k < xyzr.size(); k += 4) top = std::max(top, xyzr[k] + rw + probe);
    for (std::size_t k = 1; k < filled.size(); k += 4) top = std::max(top, filled[k] + rw + probe);
    const GridRegion& a = slot.apron;
    const float x0 = float((a.i0 - 0.5) * sp), z0 = float((a.j0 - 0.5) * sp);
    const float x1 = float((a.i0 + a.ni - 0.5) * sp), z1 = float((a.j0 + a.nj - 0.5) * sp);
    const int res = def.depth_resolution;
    bool on_gl = false;
    const float du = (x1 - x0) / float(res), dv = (z1 - z0) / float(res);
    const double rx0 = slot.region.i0 * sp, rx1 = (slot.region.i0 + slot.region.ni - 1) * sp;
    const double rz0 = slot.region.j0 * sp, rz1 = (slot.region.j0 + slot.region.nj - 1) * sp;
    // The surface of a set of (grown) spheres over the apron, as the heightfield will take it.
    auto render = [&](const std::vector<float>& spheres) -> Result<HeightImage> {
      HeightImage img;
      if (depth && gl_ok) {
        if (Status st = gl->make_current(); !st) return st.errors();
        auto r = depth->render(spheres.data(), spheres.size() / 4, x0, z0, x1, z1, float(slot.floor_local), top + 1.0f);
        if (!r) return r.errors();
        img = std::move(*r);
        on_gl = true;
      } else {
        img = render_heights_cpu(spheres.data(), spheres.size() / 4, res, x0, z0, x1, z1, float(slot.floor_local));
      }
      lower_by_probe(img, float(slot.floor_local), probe);
      // Outside the filled region the terrain was there before: particles add to it, an
      // empty texel keeps it (texels inside the region with no particle read the floor).
      for (int v = 0; v < res; ++v)
        for (int u = 0; u < res; ++u) {
          const float x = x0 + (u + 0.5f) * du, z = z0 + (v + 0.5f) * dv;
          float& h = img.h[std::size_t(v) * res + u];
          // An empty texel reads the floor. Where the old surface lies below it (bare rock under
          // the bedrock plane, floor_of), the rock stays: it is not raised to the floor.
          const bool empty = h <= float(slot.floor_local);
          if (x >= rx0 && x <= rx1 && z >= rz0 && z <= rz1) {
            if (empty) h = std::min(h, hf->sample(x, z));
            continue;
          }
          h = empty ? hf->sample(x, z) : std::max(h, hf->sample(x, z));
        }
      return img;
    };
    auto img = render(xyzr);
    if (!img) return img.errors();
    auto was = slot.fill_spheres.empty() ? Result<HeightImage>(HeightImage{}) : render(filled);
    if (!was) return was.errors();
    // Where the surface did not move, the heights of before the promotion come back exactly
    // (write_to_heightfield's RenderBaseline; docs/manager.md "Round trip").
    const RenderBaseline base{&*was, &slot.before_heights, rw, slot.fill_rise};
    const bool have_base = !slot.fill_spheres.empty() && slot.before_heights.size() == std::size_t(a.ni) * a.nj;
    write_to_heightfield(*img, a, *hf, 1, have_base ? &base : nullptr);
    // The patch's own edge inside the apron: particles on one side, old terrain (or what
    // spilled onto it) on the other; the same Gaussian band stitches it.
    smooth_border_band(*hf, slot.region, 1);
    // A body the patch carried stays at rest on the new surface: under its footprint the
    // heights are kept below its lowest point (the Gaussian lifts a narrow crater's floor,
    // and Bullet would push the body out with a kick that asked for a new patch).
    for (const Carried& c : slot.carried) {
      if (!c.enabled || !world->alive(c.body)) continue;  // (a disabled shell: another patch carries it)
      Eigen::Vector3d lo, hi;
      world->bounds(c.body, &lo, &hi);
      const float floor_at = float(lo.y() - hf->origin_y());
      // (the samples of the triangles under it: one more sample around its bounds; within
      // the written apron)
      const int i0 = std::max(a.i0, int(std::floor((lo.x() - hf->origin_x()) / sp))), i1 = std::min(a.i0 + a.ni - 1, int(std::ceil((hi.x() - hf->origin_x()) / sp)));
      const int j0 = std::max(a.j0, int(std::floor((lo.z() - hf->origin_z()) / sp))), j1 = std::min(a.j0 + a.nj - 1, int(std::ceil((hi.z() - hf->origin_z()) / sp)));
      for (int j = j0; j <= j1; ++j)
        for (int i = i0; i <= i1; ++i)
          if (hf->height(i, j) > floor_at) hf->set_height(i, j, floor_at);
      BodyState st = world->state(c.body);
      st.linear_velocity.setZero();
      st.angular_velocity.setZero();
      world->set_state(c.body, st);
    }
    world->terrain_changed();
    // Every body over the written heights (those it carried, and those resting on the
    // heightfield there: Bullet's contacts with the changed tiles are made again, and such a
    // body first falls g dt) is given 0.1 s (6 frames) to settle before it may ask for a patch.
    {
      const double wx0 = hf->origin_x() + (a.i0 - 1) * sp, wx1 = hf->origin_x() + (a.i0 + a.ni) * sp;
      const double wz0 = hf->origin_z() + (a.j0 - 1) * sp, wz1 = hf->origin_z() + (a.j0 + a.nj) * sp;
      for (RigidBodyId b : world->bodies()) {
        Eigen::Vector3d lo, hi;
        world->bounds(b, &lo, &hi);
        if (lo.x() < wx1 && hi.x() > wx0 && lo.z() < wz1 && hi.z() > wz0) set_down_until[body_key(b)] = time + 0.1;
      }
    }
    // The border band reaches one sample beyond the apron.
    GridRegion d{std::max(0, a.i0 - 1), std::max(0, a.j0 - 1), 0, 0};
    d.ni = std::min(hf->samples_x(), a.i0 + a.ni + 1) - d.i0;
    d.nj = std::min(hf->samples_z(), a.j0 + a.nj + 1) - d.j0;
    dirty.push_back(d);
    // Ledger: region above the floor plus what spilled onto the apron.
    double after = 0;
    for (int j = a.j0; j < a.j0 + a.nj; ++j)
      for (int i = a.i0; i < a.i0 + a.ni; ++i) {
        const bool in = i >= slot.region.i0 && i < slot.region.i0 + slot.region.ni && j >= slot.region.j0 &&
                        j < slot.region.j0 + slot.region.nj;
        const double h0 = slot.before_heights[std::size_t(j - a.j0) * a.ni + (i - a.i0)];
        after += in ? trapezoid_weight(i, j, slot.region) * (hf->height(i, j) - slot.floor_local)
                    : (hf->height(i, j) - h0) * (1.0 - 0.0);
      }
    slot.ledger.after = after * sp * sp;
    const double err = slot.ledger.before > 0 ? 100.0 * (slot.ledger.after - slot.ledger.before) / slot.ledger.before : 0;
    ledgers.push_back({{"patch", slot.patch},
                       {"particle_scale", slot.scale},
                       {"region", {slot.region.i0, slot.region.j0, slot.region.ni, slot.region.nj}},
                       {"granules", slot.granules},
                       {"volume_before_m3", slot.ledger.before},
                       {"volume_active_m3", slot.ledger.active},
                       {"volume_after_m3", slot.ledger.after},
                       {"error_pct", err},
                       {"depth_render", on_gl ? "gl" : "cpu"}});
    for (const Carried& c : slot.carried)
      if (c.enabled && world->alive(c.body)) world->set_terrain_collision(c.body, true);
    events.push_back({PatchEventKind::Demoted, slot.patch, time, ms_since(t0), slot.granules});
    slot.state = State::Free;
    slot.granules = 0;
    slot.carried.clear();
    slot.patch = -1;
    return Ok{};
  }
};

Result<std::unique_ptr<TerrainManager>> TerrainManager::create(const TerrainManagerDef& def, Heightfield& hf,
                                                               BulletWorld& world) {
  std::vector<Error> errs;
  auto bad = [&](const char* field, double v, const char* allowed) {
    errs.push_back(Error{"", field, std::to_string(v), allowed});
  };
  if (!(def.particle_scale > 0) || !std::isfinite(def.particle_scale)) bad("particle_scale", def.particle_scale, "must be > 0");
  for (std::size_t k = 0; k < def.scale_bands.size(); ++k) {
    const auto& b = def.scale_bands[k];
    const std::string f = "scale_bands[" + std::to_string(k) + "]";
    if (!(b.particle_scale > 0) || !std::isfinite(b.particle_scale))
      errs.push_back(Error{"", f + ".particle_scale", std::to_string(b.particle_scale), "must be > 0 and finite"});
    const double prev = k == 0 ? 0.0 : def.scale_bands[k - 1].max_distance;
    if (!(b.max_distance > prev) || !std::isfinite(b.max_distance))
      errs.push_back(Error{"", f + ".max_distance", std::to_string(b.max_distance),
                           "must be finite and greater than " + std::string(k == 0 ? "0 m" : "the previous band's (" + std::to_string(prev) + " m)")});
  }
  if (!def.camera.allFinite()) errs.push_back(Error{"", "camera", "", "must be finite (m, world)"});
  if (def.slots < 1) bad("pool.slots", def.slots, "must be >= 1");
  if (def.steps_per_contact < 2 || def.steps_per_contact > 1000)
    bad("steps_per_contact", def.steps_per_contact, "must be in [2, 1000] (the DEM substep is t_c / N)");
  if (def.granules_per_slot < 16) bad("pool.granules_per_slot", def.granules_per_slot, "must be >= 16");
  if (!(def.patch_depth > 0)) bad("patch_depth", def.patch_depth, "must be > 0 (m)");
  if (!(def.surface_probe >= 0 && def.surface_probe <= 4)) bad("surface_probe", def.surface_probe, "must be in [0, 4] sphere radii");
  if (def.fill_granules_per_frame < 1) bad("fill_granules_per_frame", def.fill_granules_per_frame, "must be >= 1");
  if (!errs.empty()) return errs;

  std::unique_ptr<TerrainManager> m(new TerrainManager());
  m->impl_ = std::make_unique<Impl>();
  Impl& I = *m->impl_;
  I.def = def;
  I.tile_cache = def.tile_cache == "off" ? std::string() : def.tile_cache.empty() ? tile_cache_dir() : def.tile_cache;
  I.hf = &hf;
  I.world = &world;
  I.camera = def.camera;
  // The first pre-settled tile of every scale, for patches patch_depth deep plus half as much
  // relief (granule_tile.hpp); deeper patches settle deeper tiles when they come (tile_for).
  for (double scale : I.scales()) {
    Impl::TileSet& set = I.tile_sets.emplace_back();
    set.scale = scale;
    GranuleTileDef& td = set.def;
    td.radius = def.material.radius;
    td.material = I.sim_def(scale).material;
    td.gravity = v3(Eigen::Vector3f((def.gravity / scale).cast<float>()));
    td.seed = def.seed;
    td.threads = def.threads;
    {
      // The tile's period: a whole number of heightfield cells near 6 lattice spacings.
      const GranuleShape shape = make_granule_shape(def.material.radius, 1.0f, def.material.density);
      const double a = 2.0 * (shape.centre_distance + shape.radius) * 1.02 * scale;  // m, world
      set.cells = std::max(1, int(std::ceil(6.0 * a / hf.spacing())));
      td.box_side = float(set.cells * double(hf.spacing()) / scale);
    }
    td.surface_probe = float(def.surface_probe) * def.material.radius;
    // Settled with μ ≤ 0.2 the block packs denser (solid fraction of the spheres 0.527 against
    // 0.472 at μ = 0.5, same settling time; μ = 0 did not come to rest in 4 s), closer to sand
    // at rest, which a body then displaces (a crater with a rim) rather than compacts.
    td.settle_friction = std::min(0.2f, def.material.friction);
    // The first tile holds a patch of up to 2 tile periods anywhere on this terrain: its fill
    // depth is the patch depth plus the terrain's relief over such a window (bounded from the
    // min/max of blocks of one period; 3 × 3 blocks cover any window of 2 periods). Settling
    // a deeper tile when a patch comes costs seconds in that frame (measured: 24.8 s on the
    // default scene under load), so start-up pays it.
    double relief = 0;
    {
      const int B = set.cells, bx = (hf.samples_x() + B - 1) / B, bz = (hf.samples_z() + B - 1) / B;
      std::vector<float> lo(std::size_t(bx) * bz, std::numeric_limits<float>::max()), hi(lo.size(), -std::numeric_limits<float>::max());
      for (int j = 0; j < hf.samples_z(); ++j)
        for (int i = 0; i < hf.samples_x(); ++i) {
          const std::size_t k = std::size_t(j / B) * bx + std::size_t(i / B);
          lo[k] = std::min(lo[k], hf.height(i, j));
          hi[k] = std::max(hi[k], hf.height(i, j));
        }
      for (int cj = 0; cj < bz; ++cj)
        for (int ci = 0; ci < bx; ++ci) {
          float a = std::numeric_limits<float>::max(), b = -a;
          for (int j = cj; j < std::min(bz, cj + 3); ++j)
            for (int i = ci; i < std::min(bx, ci + 3); ++i) {
              a = std::min(a, lo[std::size_t(j) * bx + i]);
              b = std::max(b, hi[std::size_t(j) * bx + i]);
            }
          relief = std::max(relief, double(b - a));
        }
    }
    // (At most the patch depth again of relief: steeper terrain settles deeper tiles when a
    // patch there needs one, rather than making every start-up slow.)
    const double depth0 = std::min(def.patch_depth, def.soil_depth);
    if (auto t = I.tile_for(set, (depth0 + std::min(relief, depth0)) / scale); !t) return t.errors();
  }
  // The pool: every slot allocated now at full capacity, on the chosen backend.
  if (def.backend == "gl") {
    auto ctx = gl::Context::create();
    if (!ctx) return Error{"", "simulation.backend", "gl", "needs an OpenGL 4.3 context", ctx.message()};
    I.gl = std::move(*ctx);
  } else if (def.backend != "cpu") {
    return Error{"", "simulation.backend", def.backend, "must be cpu or gl"};
  }
  // A slot's fixed capacity: its domain (grid cells) and terrain grid are sized for the
  // widest patch it can hold, a single layer of granules 2 bounding radii thick.
  // With scale bands: the finest scale's domain is the tallest (sim units), the coarsest's
  // terrain grid the widest (samples).
  const std::vector<double> all_scales = I.scales();
  const double s_min = *std::min_element(all_scales.begin(), all_scales.end());
  const double s_max = *std::max_element(all_scales.begin(), all_scales.end());
  SimulationDef cap = I.sim_def(s_min);
  {
    const GranuleShape shape = make_granule_shape(def.material.radius, 1.0f, def.material.density);
    const double bound = shape.centre_distance + shape.radius;  // sim units
    const double vg = 4.0 * 4.0 / 3.0 * std::numbers::pi * std::pow(double(shape.radius), 3);
    const float side = float(std::sqrt(def.granules_per_slot * vg / (0.5 * 2.0 * bound)));
    const float height = float((def.patch_depth + 0.5 + Impl::engage_height) / s_min);
    cap.bounds_min = {0, 0, 0};
    cap.bounds_max = {side, height, side};
    const int n = int(std::ceil(side * s_max / hf.spacing())) + 9;
    cap.terrain.nx = cap.terrain.nz = n;
    cap.terrain.spacing = float(hf.spacing() / s_max);
    cap.terrain.heights.assign(std::size_t(n) * n, 0.0f);
    cap.terrain.fill_max_x = cap.terrain.fill_max_z = side;
  }
  for (int k = 0; k < def.slots; ++k) {
    if (def.backend == "gl") {
      auto sim = gpu::GlSimulation::create(cap);
      if (!sim) return sim.errors();
      I.slots.emplace_back(gpu::make_gl_backend(std::move(*sim)));
    } else {
      auto sim = Simulation::create(cap);
      if (!sim) return sim.errors();
      I.slots.emplace_back(make_cpu_backend(std::move(*sim)));
    }
  }
  // The demotion's depth render on GL, decided now (without a context it renders on the CPU).
  if (Status st = I.make_depth_renderer(); !st) return st.errors();
  return m;
}

TerrainManager::~TerrainManager() {
  if (impl_ && impl_->gl) (void)impl_->gl->make_current();  // GL slots and the depth renderer free their objects in it
}

Status TerrainManager::before_bodies(double time, double dt, Profile& profile) {
  Impl& I = *impl_;
  I.current();
  I.now = time;
  for (auto it = I.set_down_until.begin(); it != I.set_down_until.end();)
    it = it->second <= time ? I.set_down_until.erase(it) : std::next(it);
  {
    auto timer = profile.time(Stage::Lod);
    std::vector<BodyMotion> motions;
    for (RigidBodyId b : I.world->bodies()) {
      if (I.shells_sampled.insert((std::int64_t(b.index) << 32) | std::uint32_t(b.generation)).second) {
        for (const Impl::TileSet& set : I.tile_sets) {
          auto pts = I.shell_points(b, set.scale);  // warms sample_shell's cache (meshes), per scale
          if (!pts) return pts.errors();
        }
      }
      BodyMotion m;
      I.world->bounds(b, &m.lo, &m.hi);
      const BodyState st = I.world->state(b);
      m.velocity = st.linear_velocity.cast<double>();
      // A body at rest for two frames in a row (a free body cannot be: gravity moves it)
      // lies on the terrain and disturbs nothing: it asks for no patch. Without this rule a
      // resting body asked again after every demotion and a queue never drained.
      const double reach = 0.5 * (m.hi - m.lo).norm();
      const bool still = st.linear_velocity.norm() <= I.def.sleep_speed && st.angular_velocity.norm() * reach <= I.def.sleep_speed;
      int& frames_still = I.still_frames[(std::int64_t(b.index) << 32) | std::uint32_t(b.generation)];
      frames_still = still ? frames_still + 1 : 0;
      if (frames_still >= 2 || I.settling(b)) continue;
      // A body lying on the heightfield (slow, at the surface) that no patch carries asks for
      // none either: a patch would not take it up (Impl::lying), and its requests made patches
      // come and go under it.
      if (!I.carried_anywhere(b) && I.lying(b, m.lo, m.hi)) continue;
      motions.push_back(m);
    }
    // Requests are clipped to the terrain: a body landing at its edge asks for what exists
    // (before, a request reaching past the edge was never `covered` by the clipped patch and
    // made it `extend` - demote and promote again - every frame). Merged requests stay within
    // what one slot holds (before: unbounded, and bodies landing side by side merged into one
    // patch no slot could hold, an error mid-run).
    auto predicted = predict_contacts(*I.hf, motions, I.def.gravity, I.def.lod);
    for (auto& r : predicted) I.clip_to_terrain(r);
    auto reqs = merge_requests(std::move(predicted), I.max_merged_side());
    // A queued request lapses when no body predicts a contact there any more (its body came
    // to rest on the heightfield meanwhile); requests made with request_patch() stay.
    for (auto it = I.queue.begin(); it != I.queue.end();) {
      bool live = it->bodies.empty();
      for (const auto& r : reqs) live = live || it->overlaps(r);
      if (live) {
        ++it;
      } else {
        it = I.queue.erase(it);
        ++I.lapsed_requests;
      }
    }
    for (auto& r : reqs) {
      if (I.covered(r) || !I.has_soil(r)) continue;
      if (I.overlaps_patch(r)) {
        if (auto e = I.extend(r, time); !e) return e.errors();
        continue;
      }
      bool queued = false;
      for (const auto& q : I.queue) queued = queued || q.overlaps(r);
      if (!queued) {
        I.queue.push_back(r);
        I.events.push_back({PatchEventKind::Requested, -1, time, 0, 0});
      }
    }
    std::stable_sort(I.queue.begin(), I.queue.end(), [](const PatchRequest& p, const PatchRequest& q) {
      if (p.time_to_contact != q.time_to_contact) return p.time_to_contact < q.time_to_contact;
      return p.speed > q.speed;
    });
  }
  {
    auto timer = profile.time(Stage::Activation);
    // Serve the queue while slots are free.
    for (auto it = I.queue.begin(); it != I.queue.end();) {
      auto free = std::find_if(I.slots.begin(), I.slots.end(), [](const Impl::Slot& s) { return s.state == Impl::State::Free; });
      if (free == I.slots.end()) break;
      if (I.overlaps_patch(*it) || !I.has_soil(*it)) {
        it = I.queue.erase(it);
        continue;
      }
      if (Status s = I.promote(*free, *it, time); !s) return s;
      it = I.queue.erase(it);
    }
    I.peak_queue = std::max(I.peak_queue, int(I.queue.size()));
    int used = 0;
    for (auto& s : I.slots) {
      used += s.state != Impl::State::Free;
      if (s.state != Impl::State::Filling) continue;
      // Never let a body land on a patch that is not ready: upload the rest now if a contact
      // is due within two frames.
      std::size_t budget = std::size_t(I.def.fill_granules_per_frame);
      for (RigidBodyId b : I.world->bodies()) {
        Eigen::Vector3d lo, hi;
        I.world->bounds(b, &lo, &hi);
        bool inside = false;
        const Eigen::Vector3d v = I.world->state(b).linear_velocity.cast<double>();
        const Eigen::Vector3d ahead = 2.0 * dt * v;
        if (I.engages(s, lo + ahead.cwiseMin(0.0), hi + ahead.cwiseMax(0.0), &inside)) budget = s.pending.size();
      }
      if (Status st = I.upload(s, budget, time); !st) return st;
    }
    I.peak_slots = std::max(I.peak_slots, used);
  }
  {
    auto timer = profile.time(Stage::Dem);
    I.choose_carriers();
    for (auto& s : I.slots) {
      if (s.state != Impl::State::Active && s.state != Impl::State::Asleep) continue;
      if (Status st = I.couple_before(s, dt); !st) return st;
      if (s.sim->asleep()) {
        I.hold_resting_bodies(s);
        continue;
      }
      if (s.state == Impl::State::Asleep) {
        s.state = Impl::State::Active;
        s.asleep_for = 0;
        I.events.push_back({PatchEventKind::Woke, s.patch, time, 0, s.granules});
      }
      if (Status st = s.sim->step(dt); !st) return st;
      I.couple_after(s, dt);
      s.fade = std::min(s.fade + 1, I.def.fade_frames);
    }
  }
  return Ok{};
}

Status TerrainManager::after_bodies(double time, double dt, Profile& profile) {
  Impl& I = *impl_;
  I.current();
  {
    auto timer = profile.time(Stage::Sleep);
    for (auto& s : I.slots) {
      if (s.state == Impl::State::Active && s.sim->asleep()) {
        s.state = Impl::State::Asleep;
        // The bodies it carries stop with it (they keep no residual drift while it sleeps).
        for (const auto& c : s.carried)
          if (c.enabled && I.world->alive(c.body)) {
            BodyState b = I.world->state(c.body);
            b.linear_velocity.setZero();
            b.angular_velocity.setZero();
            I.world->set_state(c.body, b);
          }
        I.events.push_back({PatchEventKind::Asleep, s.patch, time + dt, 0, s.granules});
      }
      if (s.state == Impl::State::Asleep) s.asleep_for += dt;
    }
  }
  {
    auto timer = profile.time(Stage::Demotion);
    for (auto& s : I.slots)
      if (s.state == Impl::State::Asleep && s.asleep_for >= I.def.idle_timeout)
        if (Status st = I.demote(s, time + dt); !st) return st;
  }
  return Ok{};
}

void TerrainManager::set_camera(const Eigen::Vector3d& position) { impl_->camera = position; }

void TerrainManager::request_patch(double x0, double z0, double x1, double z1, double time) {
  PatchRequest r;
  r.x0 = x0;
  r.z0 = z0;
  r.x1 = x1;
  r.z1 = z1;
  r.time_to_contact = 0;
  impl_->queue.push_back(r);
  impl_->events.push_back({PatchEventKind::Requested, -1, time, 0, 0});
}

int TerrainManager::ready_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.state == Impl::State::Active || s.state == Impl::State::Asleep;
  return n;
}

Status TerrainManager::demote_all(double time, Profile& profile) {
  auto timer = profile.time(Stage::Demotion);
  impl_->current();
  for (auto& s : impl_->slots) {
    if (s.state == Impl::State::Filling) {
      if (Status st = impl_->upload(s, s.pending.size(), time); !st) return st;
    }
    if (s.state != Impl::State::Free)
      if (Status st = impl_->demote(s, time); !st) return st;
  }
  return Ok{};
}

int TerrainManager::active_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.state != Impl::State::Free;
  return n;
}

int TerrainManager::granules() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.granules;
  return n;
}

std::vector<GridRegion> TerrainManager::take_dirty_regions() {
  std::vector<GridRegion> out;
  out.swap(impl_->dirty);
  return out;
}

int TerrainManager::queued_requests() const { return int(impl_->queue.size()); }

int TerrainManager::filling_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.state == Impl::State::Filling;
  return n;
}

int TerrainManager::asleep_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.state == Impl::State::Asleep;
  return n;
}

std::int64_t TerrainManager::pool_bytes() const {
  // Bytes per particle / per body: components × 4 bytes summed over the field lists.
#define SANDPATCH_FIELD_BYTES(type, name, n, hashed, unit) +std::int64_t(n) * std::int64_t(sizeof(type))
  constexpr std::int64_t particle_bytes = 0 SANDPATCH_PARTICLE_FIELDS(SANDPATCH_FIELD_BYTES);
  constexpr std::int64_t body_bytes = 0 SANDPATCH_BODY_FIELDS(SANDPATCH_FIELD_BYTES);
#undef SANDPATCH_FIELD_BYTES
  const SimulationDef sd = impl_->sim_def(impl_->def.particle_scale);
  std::int64_t fills = 0;  // the fills' spheres kept for the demotion's render baseline
  for (const auto& s : impl_->slots) fills += std::int64_t(s.fill_spheres.capacity() * sizeof(float));
  return std::int64_t(impl_->slots.size()) *
             (std::int64_t(sd.max_particles) * particle_bytes + std::int64_t(sd.max_bodies) * body_bytes) +
         fills;
}

std::uint64_t TerrainManager::state_hash() const {
  Hasher h;
  impl_->current();
  for (const auto& s : impl_->slots) {
    h.pod(int(s.state));
    if (s.state != Impl::State::Free) h.pod(s.sim->state_hash());
  }
  return h.value();
}

const std::vector<PatchEvent>& TerrainManager::events() const { return impl_->events; }

std::vector<TerrainManager::PatchInfo> TerrainManager::patches() const {
  std::vector<PatchInfo> out;
  for (const auto& s : impl_->slots) {
    if (s.state == Impl::State::Free) continue;
    PatchInfo p;
    p.patch = s.patch;
    p.region = s.region;
    p.origin = s.origin;
    p.particle_scale = s.scale;
    p.granule_radius_world = double(s.sim->def().particle_radius) * p.particle_scale;
    p.steps_per_contact = s.sim->def().accuracy_steps_per_contact;
    p.granules = s.granules;
    p.ready = s.state == Impl::State::Active || s.state == Impl::State::Asleep;
    p.asleep = s.state == Impl::State::Asleep;
    out.push_back(p);
  }
  return out;
}

void TerrainManager::particles(std::vector<float>& xyzr) const {
  xyzr.clear();
  const Impl& I = *impl_;
  I.current();
  for (const auto& s : I.slots)
    if (s.state != Impl::State::Free) I.granule_spheres(s, xyzr);
}

gl::Context* TerrainManager::gl_context() const { return impl_->def.backend == "gl" ? impl_->gl.get() : nullptr; }

std::vector<TerrainManager::GpuParticles> TerrainManager::gpu_particles() const {
  std::vector<GpuParticles> out;
  for (const auto& s : impl_->slots) {
    if (s.state == Impl::State::Free || s.sim->gpu_particle_buffer() == 0) continue;
    GpuParticles g;
    g.buffer = s.sim->gpu_particle_buffer();
    g.count = s.sim->particle_count();
    g.origin = s.origin;
    g.scale = float(s.scale);
    g.fade = impl_->def.fade_frames > 0 ? std::min(1.0f, float(s.fade) / float(impl_->def.fade_frames)) : 1.0f;
    out.push_back(g);
  }
  return out;
}

std::vector<std::pair<std::size_t, float>> TerrainManager::particle_groups() const {
  std::vector<std::pair<std::size_t, float>> out;
  for (const auto& s : impl_->slots) {
    if (s.state == Impl::State::Free) continue;
    const float fade = impl_->def.fade_frames > 0 ? float(s.fade) / float(impl_->def.fade_frames) : 1.0f;
    out.emplace_back(std::size_t(4) * std::size_t(s.granules), std::min(1.0f, fade));
  }
  return out;
}

nlohmann::ordered_json TerrainManager::report() const {
  const Impl& I = *impl_;
  using ojson = nlohmann::ordered_json;
  ojson r;
  double before = 0, after = 0;
  for (const auto& l : I.ledgers) {
    before += l["volume_before_m3"].get<double>();
    after += l["volume_after_m3"].get<double>();
  }
  r["ledger"] = {{"patches", I.ledgers},
                 {"total", {{"volume_before_m3", before},
                            {"volume_after_m3", after},
                            {"error_pct", before > 0 ? 100.0 * (after - before) / before : 0.0}}}};
  ojson conv = ojson::array();
  for (const auto& e : I.events)
    if (e.kind == PatchEventKind::Promoted || e.kind == PatchEventKind::Ready || e.kind == PatchEventKind::Demoted)
      conv.push_back({{"kind", to_string(e.kind)}, {"patch", e.patch}, {"time_s", e.time}, {"wall_ms", e.wall_ms},
                      {"granules", e.granules}});
  r["conversions"] = conv;
  int used = 0;
  for (const auto& s : I.slots) used += s.state != Impl::State::Free;
  r["pool"] = {{"slots", int(I.slots.size())},
               {"slots_used", used},
               {"peak_slots_used", I.peak_slots},
               {"granules_per_slot", I.def.granules_per_slot},
               {"steps_per_contact", I.def.steps_per_contact},
               {"shell_particles_per_slot", I.def.shell_particles_per_slot},
               {"queued_requests", int(I.queue.size())},
               {"peak_queued_requests", I.peak_queue},
               {"lapsed_requests", I.lapsed_requests},
               {"extensions", I.extensions}};
  nlohmann::ordered_json tiles = nlohmann::ordered_json::array();
  for (const Impl::TileSet& set : I.tile_sets)
    for (const GranuleTile& t : set.tiles)
    tiles.push_back({{"particle_scale", set.scale},
                     {"granules", t.granules.size()},
                     {"period_xz_m", t.period_xz * set.scale},
                     {"period_y_m", t.period_y * set.scale},
                     {"packing_fraction", t.packing_fraction},
                     {"settle_time_s", t.settle_time},
                     {"settled_speed_m_s", t.settled_speed}});
  r["tile"] = tiles.front();  // the shallowest (made at start-up)
  r["tile"]["tiles"] = tiles;
  r["tile"]["settle_wall_ms_all_tiles"] = I.tiles_settled_ms;
  r["tile"]["cache"] = {{"dir", I.tile_cache},
                        {"from_disk", I.tiles_from[int(TileCacheOutcome::Source::Disk)]},
                        {"from_memory", I.tiles_from[int(TileCacheOutcome::Source::Memory)]},
                        {"settled", I.tiles_from[int(TileCacheOutcome::Source::Settled)]},
                        {"notes", I.tile_cache_notes}};
  if (!I.gl_note.empty()) r["depth_render_note"] = I.gl_note;
  return r;
}

}  // namespace sandpatch
