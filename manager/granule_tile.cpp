// Pre-settled granule tiles: see granule_tile.hpp.
#include "manager/granule_tile.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <numbers>

#include <Eigen/Geometry>

#include "common/hash.hpp"
#include "particles/bed.hpp"

namespace sandpatch {
namespace {

// Sphere centres of a placed granule.
std::array<Vec3, 4> spheres(const PlacedGranule& g, const GranuleShape& s) {
  std::array<Vec3, 4> out;
  for (int k = 0; k < 4; ++k) out[k] = g.position + rotate(g.orientation, s.offsets[k]);
  return out;
}

// A grid of sphere centres with cells of `cell` m over the box [lo, hi] (points outside it
// fall in its outer cells, so any point may be stored and asked about). Dense: a fill's box
// of a few thousand cells, each a list through `next` (a hash map's 27 look-ups per sphere were
// most of a fill cut's cost).
class SphereGrid {
 public:
  SphereGrid() = default;
  SphereGrid(float cell, Vec3 lo, Vec3 hi) : cell_(cell), lo_(lo) {
    // (at most kMaxCells: a larger box takes larger cells, which finds the same neighbours)
    constexpr double kMaxCells = 1 << 22;
    auto cells = [&](float a, float b) {
      const double n = std::ceil(double(b - a) / double(cell_)) + 1;
      return std::isfinite(n) ? int(std::clamp(n, 1.0, kMaxCells)) : 1;
    };
    for (;;) {
      n_ = {cells(lo.x, hi.x), cells(lo.y, hi.y), cells(lo.z, hi.z)};
      if (double(n_[0]) * n_[1] * n_[2] <= kMaxCells) break;
      cell_ *= 2;
    }
    head_.assign(std::size_t(n_[0]) * n_[1] * n_[2], -1);
  }
  void insert(Vec3 p, int copy = 0) {
    const auto [i, j, k] = index(p);
    const std::size_t c = (std::size_t(k) * n_[1] + j) * n_[0] + i;
    entries_.push_back({p, copy, head_[c]});
    head_[c] = int(entries_.size()) - 1;
  }
  // True when some stored centre of another copy than `copy` (-1: any) is closer than `dist`
  // (at most the cell asked for) to p.
  bool near(Vec3 p, float dist, int copy = -1) const {
    const auto [i, j, k] = index(p);
    for (int c = std::max(0, k - 1); c <= std::min(n_[2] - 1, k + 1); ++c)
      for (int b = std::max(0, j - 1); b <= std::min(n_[1] - 1, j + 1); ++b)
        for (int a = std::max(0, i - 1); a <= std::min(n_[0] - 1, i + 1); ++a)
          for (int e = head_[(std::size_t(c) * n_[1] + b) * n_[0] + a]; e >= 0; e = entries_[std::size_t(e)].next) {
            const Entry& q = entries_[std::size_t(e)];
            if (q.copy != copy && dot(q.p - p, q.p - p) < dist * dist) return true;
          }
    return false;
  }
 private:
  struct Entry {
    Vec3 p;
    int copy;
    int next;  // the cell's next entry, -1 at its end
  };
  std::array<int, 3> index(Vec3 p) const {
    auto at = [&](float x, float o, int n) { return std::clamp(int(std::floor((x - o) / cell_)), 0, n - 1); };
    return {at(p.x, lo_.x, n_[0]), at(p.y, lo_.y, n_[1]), at(p.z, lo_.z, n_[2])};
  }
  float cell_ = 1;
  Vec3 lo_{0, 0, 0};
  std::array<int, 3> n_{1, 1, 1};
  std::vector<int> head_;
  std::vector<Entry> entries_;
};

}  // namespace

float mean_top_height(const std::vector<PlacedGranule>& granules, const GranuleShape& shape, float x0, float z0,
                      float x1, float z1, float step, float floor, float probe) {
  const int nx = std::max(1, int((x1 - x0) / step)), nz = std::max(1, int((z1 - z0) / step));
  std::vector<float> top(std::size_t(nx) * nz, floor);
  const float r = shape.radius + probe;
  for (const auto& g : granules) {
    for (const Vec3& c : spheres(g, shape)) {
      const int i0 = std::max(0, int(std::floor((c.x - r - x0) / step))), i1 = std::min(nx - 1, int((c.x + r - x0) / step));
      const int k0 = std::max(0, int(std::floor((c.z - r - z0) / step))), k1 = std::min(nz - 1, int((c.z + r - z0) / step));
      for (int k = k0; k <= k1; ++k)
        for (int i = i0; i <= i1; ++i) {
          const float x = x0 + (i + 0.5f) * step, z = z0 + (k + 0.5f) * step;
          const float d2 = (x - c.x) * (x - c.x) + (z - c.z) * (z - c.z);
          if (d2 <= r * r) {
            float& t = top[std::size_t(k) * nx + i];
            t = std::max(t, c.y + std::sqrt(r * r - d2) - probe);
          }
        }
    }
  }
  double sum = 0;
  for (float t : top) sum += std::max(t, floor);
  return float(sum / double(top.size()));
}

// The cut's state between steps: the tile (a copy: the set's tiles may grow meanwhile), the
// candidates made so far and the granules kept so far.
struct FillCut::State {
  GranuleTile tile;
  float width = 0, depth = 0;
  std::function<float(float, float)> surface;
  float r = 0, P = 0, Py = 0, bound = 0;
  int cx = 0, cz = 0, cy = 0;
  int next_copy = 0;                  // 1. the next tile copy to make candidates from
  float skip[4] = {1, 0, 1, 0};       // copies wholly within [x0, x1] × [z0, z1] are left out (none)
  std::vector<PlacedGranule> cand;
  std::vector<int> cand_copy;         // which copy of the tile a candidate comes from
  std::vector<std::size_t> order;     // 2. candidates lowest first (empty until sorted)
  bool sorted = false;
  std::size_t next = 0;               // 3. the next candidate (in `order`) to cut
  SphereGrid grid;
  std::vector<PlacedGranule> out;
};

FillCut::FillCut(const GranuleTile& tile, float width, float depth, std::function<float(float, float)> surface)
    : s_(std::make_unique<State>()) {
  State& s = *s_;
  s.tile = tile;
  s.width = width, s.depth = depth;
  s.surface = std::move(surface);
  s.r = tile.shape.radius, s.P = tile.period_xz, s.Py = tile.period_y;
  s.bound = tile.shape.centre_distance + s.r;
  // 1. Candidates: tile copies whose centres lie in the patch and at most one bounding radius
  //    above the surface, lowest first.
  float top = 0;
  const float probe = std::max(s.r, 0.25f * s.P);
  for (float z = 0; z <= depth + probe; z += probe)
    for (float x = 0; x <= width + probe; x += probe) top = std::max(top, s.surface(std::min(x, width), std::min(z, depth)));
  s.cx = int(std::ceil(width / s.P)), s.cz = int(std::ceil(depth / s.P)), s.cy = int(std::ceil(top / s.Py)) + 1;
  // (the kept spheres lie within 0.9 r of the box's sides and floor, and at most a granule's
  // bounding radius above the surface and a sphere radius beyond)
  s.grid = SphereGrid(2.0f * s.r, Vec3{0, 0, 0}, Vec3{width, top + 2.0f * s.bound, depth});
}

void FillCut::skip_copies_within(float x0, float x1, float z0, float z1) {
  s_->skip[0] = x0, s_->skip[1] = x1, s_->skip[2] = z0, s_->skip[3] = z1;
}

FillCut::~FillCut() = default;
FillCut::FillCut(FillCut&&) noexcept = default;
FillCut& FillCut::operator=(FillCut&&) noexcept = default;

bool FillCut::done() const { return s_->sorted && s_->next >= s_->order.size(); }

std::size_t FillCut::granules() const { return s_->out.size(); }

// A candidate cut (its surface sampled, its spheres tested against the granules placed and
// inserted) costs many tile granules made candidates (about 0.6 us against 25 ns on the
// development machine with a hash grid, about 0.35 us with the dense one), so it counts 4
// units: the last part of a car's fill took 2.3-2.9 ms at one unit, and a cut part took
// 0.8-0.9 ms on average at 4 with the hash grid, 0.25 ms with the dense one. (At 16 and the
// hash grid, 0.3 ms, but fills were ready that many frames later: a box driven onto a patch
// just made rose 0.88 granule diameters above its rest on granules, past the 0.75
// Coupling.FastBoxMeetingPatchesDoesNotHop allows.) docs/manager.md "No frame does a whole
// patch's work".
constexpr std::size_t kUnitsPerCandidateCut = 4;

bool FillCut::step(std::size_t work) {
  State& s = *s_;
  const GranuleTile& tile = s.tile;
  const float P = s.P, Py = s.Py, r = s.r;
  std::size_t done_work = 0;
  // Odd copies are mirrored (x -> P - x and/or z -> P - z), so across every seam a granule
  // faces the mirror image of itself: where it touched the settling box's wall, it now
  // touches its image (granule_tile.hpp).
  const Eigen::Matrix3f S = (Eigen::Matrix3f() << 1, 0, 0, 0, 0, 1, 0, 1, 0).finished();  // y<->z: a symmetry of the tetrahedron
  const int copies = s.cx * s.cz * s.cy;
  while (s.next_copy < copies && done_work < work) {
    const int k = s.next_copy++;
    const int a = k % s.cx, c = (k / s.cx) % s.cz, b = k / (s.cx * s.cz);
    if (a * P >= s.skip[0] && (a + 1) * P <= s.skip[1] && c * P >= s.skip[2] && (c + 1) * P <= s.skip[3]) continue;
    const bool mx = a % 2 == 1, mz = c % 2 == 1;
    const Eigen::Matrix3f M = Eigen::Vector3f(mx ? -1.0f : 1.0f, 1.0f, mz ? -1.0f : 1.0f).asDiagonal();
    for (const auto& g : tile.granules) {
      const Vec3 p{a * P + (mx ? P - g.position.x : g.position.x), g.position.y + b * Py,
                   c * P + (mz ? P - g.position.z : g.position.z)};
      if (p.x < 0 || p.x >= s.width || p.z < 0 || p.z >= s.depth) continue;
      if (p.y > s.surface(p.x, p.z) + s.bound) continue;
      Quat q = g.orientation;
      if (mx || mz) {
        const Eigen::Matrix3f R = Eigen::Quaternionf(q.w, q.x, q.y, q.z).toRotationMatrix();
        // One mirror flips handedness: M R S is a rotation again because S maps the
        // tetrahedron onto itself with det S = -1. Two mirrors are a rotation already.
        const Eigen::Quaternionf rq(mx != mz ? Eigen::Matrix3f(M * R * S) : Eigen::Matrix3f(M * R));
        q = {rq.x(), rq.y(), rq.z(), rq.w()};
      }
      s.cand.push_back({p, q});
      s.cand_copy.push_back(k);  // (b cz + c) cx + a
    }
    done_work += tile.granules.size();
  }
  if (s.next_copy < copies) return false;
  if (!s.sorted) {
    if (done_work >= work) return false;
    s.order.resize(s.cand.size());
    for (std::size_t k = 0; k < s.order.size(); ++k) s.order[k] = k;
    std::stable_sort(s.order.begin(), s.order.end(),
                     [&](std::size_t u, std::size_t v) { return s.cand[u].position.y < s.cand[v].position.y; });
    s.sorted = true;
    done_work += s.cand.size();
  }

  // 2. The cut: a granule is kept when its centre lies below surface − surface_offset
  //    (calibrated when the tile is made so the kept bed renders back at the surface) and it
  //    overlaps nothing placed; lowest first.
  // Granules of one copy keep the contacts they had in the settled block (in equilibrium);
  // across a seam, overlaps are those of the wall contacts doubled (a few % of r); a larger
  // one (> 10% of r) is left out.
  const float min_dist = 1.8f * r;
  while (s.next < s.order.size() && done_work < work) {
    const std::size_t idx = s.order[s.next++];
    done_work += kUnitsPerCandidateCut;
    const PlacedGranule& g = s.cand[idx];
    const int copy = s.cand_copy[idx];
    if (g.position.y > s.surface(g.position.x, g.position.z) - tile.surface_offset) continue;
    const auto sph = spheres(g, tile.shape);
    bool clash = false;
    // Inside the patch with at most 10% of r overlap against the floor and the patch's
    // sides (the soil around it holds the granules there).
    // The bottom copies keep their floor contacts as settled (in equilibrium with the weight
    // above them: leaving those granules out would let the whole bed sink by a layer).
    const bool bottom = copy < s.cx * s.cz;
    for (const Vec3& sp : sph)
      clash = clash || (!bottom && sp.y < 0.9f * r) || sp.x < 0.9f * r || sp.x > s.width - 0.9f * r ||
              sp.z < 0.9f * r || sp.z > s.depth - 0.9f * r || s.grid.near(sp, min_dist, copy);
    if (clash) continue;
    for (const Vec3& sp : sph) s.grid.insert(sp, copy);
    s.out.push_back(g);
  }
  return done();
}

std::vector<PlacedGranule> FillCut::take() {
  std::vector<PlacedGranule> out;
  out.swap(s_->out);
  return out;
}

std::vector<PlacedGranule> fill_from_tile(const GranuleTile& tile, float width, float depth,
                                          const std::function<float(float, float)>& surface) {
  FillCut cut(tile, width, depth, surface);
  while (!cut.step(std::numeric_limits<std::size_t>::max())) {
  }
  return cut.take();
}

Result<GranuleTile> make_granule_tile(const GranuleTileDef& def) {
  if (def.columns < 4) return Error{"", "granule_tile.columns", std::to_string(def.columns), "must be >= 4"};
  if (def.layers < 4) return Error{"", "granule_tile.layers", std::to_string(def.layers), "must be >= 4"};
  const GranuleShape shape = make_granule_shape(def.radius, 1.0f, def.material.density);
  const float bound = shape.centre_distance + shape.radius;  // bounding radius of a granule
  float a = 2.0f * bound * 1.02f;                              // lattice spacing (add_lattice_bed's default)
  int columns = def.columns;
  if (def.box_side > 0) {
    columns = int(std::floor(def.box_side / a));
    if (columns < 4)
      return Error{"", "granule_tile.box_side", std::to_string(def.box_side),
                   "must hold at least 4 granules per side (>= " + std::to_string(4 * a) + " m)"};
    a = def.box_side / float(columns);
  }
  const float L = a * float(columns);

  SimulationDef sd;
  sd.max_bodies = columns * columns * def.layers;
  sd.max_particles = 4 * sd.max_bodies;
  sd.particle_radius = def.radius;
  sd.material = def.material;
  if (def.settle_friction >= 0) sd.material.friction = def.settle_friction;
  sd.max_overlap_fraction = 0;  // the lattice falls onto the floor of the box: no body can pass it
  sd.gravity_world = def.gravity;
  sd.bounds_min = {0, 0, 0};
  sd.bounds_max = {L, a * float(def.layers + 2), L};
  sd.floor_height = 0;
  sd.side_walls = true;
  sd.threads = def.threads;
  sd.accuracy_steps_per_contact = def.steps_per_contact;
  // A settling frame takes as many substeps as the contact time asks (fine, stiff granules
  // need more than a game frame's 64): the guard is for frames, not for settling.
  sd.max_substeps = 1 << 20;
  auto sim = Simulation::create(sd);
  if (!sim) return sim.errors();
  LatticeBedDef bed;
  bed.min = {0.5f * a, bound * 1.05f, 0.5f * a};
  bed.nx = bed.nz = columns;
  bed.spacing = a;
  bed.layers = def.layers;
  bed.seed = def.seed;
  bed.jitter = 0.4f;  // a strongly jittered lattice settles without remembering its layers
  if (Status s = add_lattice_bed(*sim, bed); !s) return s.errors();

  // Settle: frames of 1/120 s until every granule is slower than settle_speed.
  GranuleTile tile;
  const double frame = 1.0 / 120.0;
  double t = 0;
  for (; t < def.settle_max_time; t += frame) {
    if (Status s = sim->step(frame); !s) return s.errors();
    if (def.on_progress) def.on_progress(t + frame, def.settle_max_time);
    if (t > 0.25 && sim->max_granule_speed() < def.settle_speed) break;
  }
  tile.settle_time = t;
  tile.settled_speed = float(sim->max_granule_speed());
  tile.shape = shape;
  tile.surface_probe = def.surface_probe;

  // The whole block is the tile (mirrored copies tile it seamlessly); the vertical period
  // stops two bounding radii below the highest granule, under the rough top.
  tile.period_xz = L;
  float ymax = 0;
  for (int b = 0; b < sim->body_count(); ++b) ymax = std::max(ymax, sim->body_position(BodyId{b}).y);
  tile.period_y = ymax - 2.0f * bound;
  for (int b = 0; b < sim->body_count(); ++b) {
    const Vec3 p = sim->body_position(BodyId{b});
    if (p.y >= tile.period_y) continue;
    tile.granules.push_back({p, sim->body_orientation(BodyId{b})});
  }
  const double vg = 4.0 * 4.0 / 3.0 * std::numbers::pi * double(def.radius) * def.radius * def.radius;
  tile.packing_fraction =
      float(double(tile.granules.size()) * vg / (double(tile.period_xz) * tile.period_xz * tile.period_y));

  // Calibrate the cut: flat fills cut at heights spread over the tile's depth must render
  // back, on average, at their heights.
  const float W = 2.0f * tile.period_xz, step = 0.5f * def.radius;
  const int phases = 6;
  for (int it = 0; it < 3; ++it) {
    double err = 0;
    for (int k = 0; k < phases; ++k) {
      const float H = tile.period_y * (0.25f + 0.5f * float(k) / float(phases - 1));
      auto g = fill_from_tile(tile, W, W, [&](float, float) { return H; });
      err += mean_top_height(g, shape, 0.1f * W, 0.1f * W, 0.9f * W, 0.9f * W, step, 0.0f, def.surface_probe) - H;
    }
    tile.surface_offset += float(err / phases);
  }

  // Elastic rebound. The block settled under its own full depth; a fill keeps only the part
  // below the cut, so its contacts unload and the bed rises by their lost overlap (measured
  // 3.6 mm = 0.07 d for k_n = 2e4 N/m, r = 2.5 cm, the round-trip test's soil). A fill cut at
  // 0.7 P_y (patches are about that deep) is run in the settling box with the material's
  // own friction until at rest; the rise of its rendered top is what an undisturbed patch
  // will have risen by when it is demoted (depth_conversion.hpp RenderBaseline::rise).
  {
    const float H = 0.7f * tile.period_y;
    auto g = fill_from_tile(tile, L, L, [&](float, float) { return H; });
    SimulationDef rd = sd;
    rd.material = def.material;
    if (Status st = sim->reset(rd); !st) return st.errors();
    for (const auto& p : g)
      if (auto id = sim->add_granule(p.position, p.orientation); !id) return id.errors();
    const float m0 = mean_top_height(g, shape, 0.1f * L, 0.1f * L, 0.9f * L, 0.9f * L, step, 0.0f, def.surface_probe);
    for (double tr = 0; tr < 1.5; tr += frame) {
      if (Status st = sim->step(frame); !st) return st.errors();
      if (tr > 0.25 && sim->max_granule_speed() < def.settle_speed) break;
    }
    for (int b = 0; b < sim->body_count(); ++b) g[std::size_t(b)] = {sim->body_position(BodyId{b}), sim->body_orientation(BodyId{b})};
    tile.rebound = mean_top_height(g, shape, 0.1f * L, 0.1f * L, 0.9f * L, 0.9f * L, step, 0.0f, def.surface_probe) - m0;
  }
  return tile;
}

std::uint64_t granule_tile_def_hash(const GranuleTileDef& def) {
  Hasher h;
  const Material& m = def.material;
  h.pod(m.density), h.pod(m.normal_stiffness), h.pod(m.restitution), h.pod(m.friction), h.pod(m.shear);
  h.pod(m.tangential_stiffness_ratio), h.pod(m.tangential_damping_ratio);
  // the hysteretic normal spring settles its own tiles; the linear spring's keys stay as they were
  if (m.unloading_stiffness_ratio != 1.0f) h.pod(m.unloading_stiffness_ratio);
  h.pod(def.radius), h.pod(def.columns), h.pod(def.box_side), h.pod(def.layers), h.pod(def.seed);
  h.pod(def.settle_max_time), h.pod(def.settle_speed), h.pod(def.gravity.x), h.pod(def.gravity.y), h.pod(def.gravity.z);
  h.pod(def.surface_probe), h.pod(def.settle_friction), h.pod(def.steps_per_contact);
  return h.value();
}

Result<GranuleTile> shared_granule_tile(const GranuleTileDef& def, bool* reused) {
  const std::uint64_t key = granule_tile_def_hash(def);
  static std::mutex mutex;
  static std::map<std::uint64_t, GranuleTile> memo;
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (auto it = memo.find(key); it != memo.end()) {
      if (reused) *reused = true;
      return it->second;
    }
  }
  if (reused) *reused = false;
  auto t = make_granule_tile(def);
  if (!t) return t;
  std::lock_guard<std::mutex> lock(mutex);
  if (memo.size() >= 8) memo.erase(memo.begin());
  memo.emplace(key, *t);
  return t;
}

}  // namespace sandpatch
