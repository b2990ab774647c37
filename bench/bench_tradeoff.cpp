// bench tradeoff: what each knob users turn costs and what it gets wrong (issue 7, "The trade,
// measured"; docs/tradeoff.md).
//
// Three reference cases, each run at every setting of the sweep:
//   pile    the angle of repose of a poured pile (particles/pile.hpp pour_pile, the pour and
//           cone fit of measure_repose on a simulation whose guard substeps at t_c / N): the
//           pile's world volume is fixed, so particle scale s pours 1/s^3 as many granules
//   crater  a sphere dropped into a settled granular bed (measure_crater below, straight on the
//           DEM): crater depth and rim volume from the particle surface before and after
//           (Uehara et al. 2003, PRL 90 194301, for the experiment and its depth law)
//   drop    a Bullet sphere dropped onto a small flat heightfield terrain driven by the real
//           TerrainManager in the frame of manager/run.cpp (bench/tradeoff_drop.hpp): crater
//           depth and volume read from the heightfield after demote_all, what a library user sees
// Error of a setting: relative to the reference (the finest setting of its case) — the pile's
// |angle − angle_ref| / angle_ref, the crater's max(|depth − ref| / ref, |rim − ref| / ref) (the
// rim term only when the reference's rim is at least a granule sphere radius high: lower, it is
// the roughness of the surface), the drop's the same with the crater volume as a third term.
// Cost: wall seconds of the measured phase and the real-time factor (simulated / wall seconds).
// A repeat of one setting with another seed gives each case's noise floor.
//
// Why the crater case runs straight on the DEM: a run pays the pre-settled tile at start-up and
// its patch is sized by the body, so the patch-size knob could not be turned; here one settled
// bed per scale is cut to every patch size, as the manager cuts its tiles. The knobs only the
// manager's path has are turned on the drop case:
//   substeps            the scene's Bullet steps per frame (run.cpp: BulletWorld::step_frame, dt /
//                       substeps each, the patch's force held over all of them)
//   granules_per_slot   slot capacity; a patch that needs more is refused by the manager (its
//                       error names simulation.pool.granules_per_slot): that setting's outcome
//                       is "refused", reported with the message, never an error of the bench
//   LOD on / off        on: the manager's contact prediction places the patch (apron swept,
//                       0.2 and 0.5 m; the default 1 m covers this small terrain whole); off: the
//                       whole terrain as particles from t = 0 (request_patch), kept to the end
// The drop's reference is LOD off (the whole terrain as particles, no patch edge near the
// sphere) at scale 1 and N = 50 with one Bullet substep, the scene default. The substeps rows
// found that the patch's force (BulletWorld::apply_force) reached only the first Bullet
// substep of a frame (Bullet clears applied forces after every stepSimulation): the sphere
// sank 3x as deep at 4 substeps. Fixed by BulletWorld::step_frame; docs/tradeoff.md.
#include "bench/bench_tradeoff.hpp"

#include <omp.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numbers>
#include <set>

#include "bench/bench_util.hpp"
#include "bench/tradeoff_drop.hpp"
#include "gl/context.hpp"
#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "particles/gpu/gl_simulation.hpp"
#include "particles/pile.hpp"

namespace fs = std::filesystem;

namespace sandpatch {

namespace {

using ojson = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

constexpr double kG = 9.81;                // m/s^2
constexpr double kFrame = 1.0 / 120.0;     // s per step() call; the DEM substeps within
constexpr double kSolidFraction = 0.47;    // settled granule beds, spheres' solid fraction (terrain_manager.cpp)
constexpr int kSectors = 8;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

using bench::load_average;
using bench::write_text;


std::string num_id(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

// The contact material of both cases: the peer's (../shared/peers/), mu = 0.5 (docs/dem.md).
Material reference_material() {
  Material m;
  m.density = 2500;
  m.normal_stiffness = 3292;
  m.restitution = 0.3f;
  m.friction = 0.5f;
  return m;
}

// Fibonacci lattice of n points on a sphere of radius rc (body frame).
std::vector<Vec3> fibonacci_sphere(int n, float rc) {
  std::vector<Vec3> p;
  p.reserve(n);
  const double ga = std::numbers::pi * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double y = 1.0 - 2.0 * (i + 0.5) / n, rr = std::sqrt(std::max(0.0, 1.0 - y * y)), t = ga * i;
    p.push_back({float(rc * rr * std::cos(t)), float(rc * y), float(rc * rr * std::sin(t))});
  }
  return p;
}

// Surface per radial bin (m, world) of granule sphere tops about the axis (cx, cz) (sim units in,
// world out: lengths x s); -1 where a bin is empty.
std::vector<double> radial_surface(const std::vector<Vec3>& pos, int count, float r, double cx, double cz, double s,
                                   double bin) {
  std::vector<SurfacePoint> pts;
  pts.reserve(count);
  for (int i = 0; i < count; ++i) {
    const Vec3 x = pos[i];
    SurfacePoint sp;
    const double dx = x.x - cx, dz = x.z - cz;
    sp.s = std::hypot(dx, dz) * s;
    sp.h = (double(x.y) + r) * s;
    const double phi = std::atan2(dz, dx) + std::numbers::pi;
    sp.sector = std::min(kSectors - 1, int(phi / (2 * std::numbers::pi) * kSectors));
    pts.push_back(sp);
  }
  FlankFitDef fd;
  fd.bin = bin;
  fd.sectors = kSectors;
  return fit_flank(pts, fd).surface;
}

// The impact on either backend: the cut patch, a short re-settle, the surface, the sphere, the
// timed drop, the surface again.
template <class Sim>
Result<CraterResult> run_impact(Sim& sim, const CraterDef& d, const SettledBed& bed, double box_lo, double box_hi,
                                double centre) {
  const double s = d.knobs.particle_scale;
  const float r = d.granule_radius;
  const GranuleShape& g = sim.granule_shape();
  const float reach = g.centre_distance + g.radius;
  // granules of the settled bed whose bounding spheres lie inside the patch's walls
  int granules = 0;
  for (std::size_t i = 0; i < bed.position.size(); ++i) {
    const Vec3 x = bed.position[i];
    if (x.x - reach < box_lo || x.x + reach > box_hi || x.z - reach < box_lo || x.z + reach > box_hi) continue;
    auto id = sim.add_granule(x, bed.orientation[i]);
    if (!id) return id.errors();
    ++granules;
  }
  // re-settle 0.1 s: the cut sides and the springs (not carried over) find their rest
  for (int f = 0; f < int(std::lround(0.1 / kFrame)); ++f)
    if (auto st = sim.step(kFrame); !st) return st.errors();
  const double R = d.sphere_radius, bin = d.bin_radii * R;
  const int nbins = std::max(1, int(std::floor((0.5 * (box_hi - box_lo) * s - 0.5 * bin) / bin)));
  auto before = radial_surface(sim.particle_positions(), 4 * granules, r, centre, centre, s, bin);
  // mean surface within 1.5 R of the axis before the drop (m, world; sim units below)
  double top = 0, mean0 = 0;
  int nm = 0;
  for (int k = 0; k < int(before.size()) && k < nbins; ++k)
    if (before[k] >= 0 && (k + 1) * bin <= 1.5 * R) mean0 += before[k], ++nm;
  mean0 = nm ? mean0 / nm : 0;
  {
    const auto pos = sim.particle_positions();
    for (int i = 0; i < 4 * granules; ++i) {
      const double dx = pos[i].x - centre, dz = pos[i].z - centre;
      if (std::hypot(dx, dz) * s <= R) top = std::max(top, double(pos[i].y) + r);
    }
  }
  // the sphere: a shell of granule-sized spheres on its surface, centres R_sim - r from its centre
  const float Rs = float(R / s);
  const float rc = Rs - r;
  const double spacing = 1.8 * r;  // < 2 r: granule spheres cannot pass between shell spheres
  const int n = int(std::ceil(4 * std::numbers::pi * rc * rc / (spacing * spacing * std::sqrt(3.0) / 2)));
  ShellDef sh;
  sh.offsets = fibonacci_sphere(n, rc);
  sh.radii = {r};
  sh.motion = MotionType::Dynamic;
  const double volume = 4.0 / 3.0 * std::numbers::pi * double(Rs) * Rs * Rs;  // sim units: density kept
  sh.mass = float(d.sphere_density * volume);
  const float inertia = float(0.4 * sh.mass * Rs * Rs);
  sh.inertia = {inertia, inertia, inertia};
  sh.position = {float(centre), float(top + Rs + r), float(centre)};
  sh.velocity = {0, -float(std::sqrt(2 * kG * d.drop_height) / s), 0};
  auto body = sim.add_shell(sh);
  if (!body) return body.errors();

  CraterResult out;
  out.granules = granules;
  out.spheres = sim.particle_count();
  const auto t0 = Clock::now();
  const int frames = int(std::lround(d.impact_seconds / kFrame));
  for (int f = 0; f < frames; ++f)
    if (auto st = sim.step(kFrame); !st) return st.errors();
  (void)sim.max_granule_speed();  // GL: waits for the last frame (its status read-back)
  out.wall_seconds = seconds_since(t0);
  out.sim_seconds = frames * kFrame;
  out.final_speed = sim.max_granule_speed() * s;
  out.dt = sim.last_step().substep_dt;
  out.contact_time = sim.contact_time();
  out.sphere_sink = mean0 - (double(sim.body_position(*body).y) - Rs) * s;
  auto after = radial_surface(sim.particle_positions(), 4 * granules, r, centre, centre, s, bin);

  // Δh per bin; the crater run from the axis, then the rim run
  const int K = std::min<int>({nbins, int(before.size()), int(after.size())});
  out.dh.assign(K, -1e300);
  for (int k = 0; k < K; ++k)
    if (before[k] >= 0 && after[k] >= 0) out.dh[k] = after[k] - before[k];
  int k = 0;
  while (k < K && out.dh[k] < -1e299) ++k;  // empty bins at the axis (the sphere sits there)
  for (; k < K && out.dh[k] < 0 && out.dh[k] > -1e299; ++k) {
    const double area = std::numbers::pi * (2 * k + 1) * bin * bin;
    out.depth = std::max(out.depth, -out.dh[k]);
    out.crater_volume += -out.dh[k] * area;
    out.crater_radius = (k + 1) * bin;
  }
  for (; k < K && out.dh[k] > 0; ++k) {
    const double area = std::numbers::pi * (2 * k + 1) * bin * bin;
    out.rim_volume += out.dh[k] * area;
    out.rim_height = std::max(out.rim_height, out.dh[k]);
  }
  return out;
}

}  // namespace

const char* to_string(TradeoffCase c) {
  return c == TradeoffCase::Pile ? "pile" : c == TradeoffCase::Crater ? "crater" : "drop";
}
const char* to_string(TradeoffSweep s) {
  return s == TradeoffSweep::Quick ? "quick" : s == TradeoffSweep::Full ? "full" : "default";
}

DropDef tradeoff_drop_def(TradeoffSweep sweep) {
  DropDef d;
  if (sweep == TradeoffSweep::Quick) d.run_seconds = 1.0;
  return d;
}

int tradeoff_pile_granules(TradeoffSweep sweep) { return sweep == TradeoffSweep::Quick ? 100 : 400; }

std::vector<TradeoffSetting> tradeoff_sweep(TradeoffSweep sweep) {
  std::vector<TradeoffSetting> v;
  auto add = [&](TradeoffCase c, double s, int n, double p, const char* backend = "cpu", std::uint64_t seed = 1,
                 bool ref = false, bool noise = false) {
    TradeoffSetting t;
    t.kind = c;
    t.knobs.particle_scale = s;
    t.knobs.steps_per_contact = n;
    t.knobs.patch_radii = c == TradeoffCase::Crater ? p : 0;
    t.knobs.backend = backend;
    t.knobs.seed = seed;
    t.reference = ref;
    t.noise = noise;
    t.id = std::string(to_string(c)) + "_s" + num_id(s) + "_n" + std::to_string(n) +
           (c == TradeoffCase::Crater ? "_p" + num_id(p) + "_" + backend : "") +
           (seed != 1 ? "_seed" + std::to_string(seed) : "");
    v.push_back(t);
  };
  // the drop case (bench/tradeoff_drop.hpp): through the TerrainManager
  auto drop = [&](double s, int n, int sub, bool lod, double apron, int slot, std::uint64_t seed = 1, bool ref = false,
                  bool noise = false) {
    TradeoffSetting t;
    t.kind = TradeoffCase::Drop;
    t.knobs.particle_scale = s;
    t.knobs.steps_per_contact = n;
    t.knobs.patch_radii = 0;
    t.knobs.substeps = sub;
    t.knobs.granules_per_slot = slot;
    t.knobs.lod = lod;
    t.knobs.lod_apron = lod ? apron : 0;
    t.knobs.seed = seed;
    t.reference = ref;
    t.noise = noise;
    t.id = "drop_s" + num_id(s) + "_n" + std::to_string(n) + "_sub" + std::to_string(sub) +
           (lod ? "_lod" + num_id(apron) : std::string("_lodoff")) + "_slot" + std::to_string(slot) +
           (seed != 1 ? "_seed" + std::to_string(seed) : "");
    v.push_back(t);
  };
  // The drop's rows of the default and full sweeps after their reference: N, substeps with LOD
  // off and on, slot capacities (two refused), particle scale 2.
  auto drop_knob_rows = [&]() {
    drop(1, 20, 1, false, 0, 16384);
    drop(1, 10, 1, false, 0, 16384);
    drop(1, 20, 2, false, 0, 16384);
    drop(1, 20, 1, true, 0.2, 16384);
    drop(1, 20, 2, true, 0.2, 16384);
    drop(1, 20, 4, true, 0.2, 16384);
    drop(1, 20, 1, true, 0.2, 1700);   // fits the LOD patch (1590) ...
    drop(1, 20, 1, false, 0, 1700);    // ... not the whole terrain (1835): refused
    drop(1, 20, 1, true, 0.2, 1024);   // refused
    drop(2, 20, 1, true, 0.2, 16384);
    drop(2, 20, 1, false, 0, 16384);
  };
  using C = TradeoffCase;
  switch (sweep) {
    case TradeoffSweep::Quick:
      add(C::Pile, 1, 50, 0, "cpu", 1, true);
      add(C::Pile, 1, 20, 0);
      add(C::Pile, 1.26, 20, 0);
      add(C::Pile, 1, 10, 0);
      add(C::Crater, 1, 50, 4, "cpu", 1, true);
      add(C::Crater, 1, 20, 4);
      add(C::Crater, 1.5, 20, 4);
      add(C::Crater, 1, 20, 3);
      // the drop at particle scale 2 (212 granules for the whole terrain, 176 for the LOD patch)
      drop(2, 20, 1, false, 0, 16384, 1, true);
      drop(2, 20, 1, true, 0.5, 16384);
      drop(2, 20, 2, true, 0.5, 16384);
      drop(2, 20, 1, false, 0, 192);  // the whole terrain needs 212: refused
      drop(2, 20, 1, true, 0.5, 192);  // the LOD patch fits
      drop(2, 20, 1, false, 0, 16384, 2, false, true);
      drop(2, 20, 1, true, 0.5, 16384, 2, false, true);
      break;
    case TradeoffSweep::Default:
      add(C::Pile, 1, 50, 0, "cpu", 1, true);
      for (double s : {1.0, 1.26, 1.59})
        for (int n : {50, 20, 10})
          if (!(s == 1.0 && n == 50)) add(C::Pile, s, n, 0);
      add(C::Pile, 1, 20, 0, "cpu", 2, false, true);
      add(C::Crater, 1, 50, 6, "cpu", 1, true);
      add(C::Crater, 1, 20, 6);
      add(C::Crater, 1, 10, 6);
      add(C::Crater, 1, 20, 4.5);
      add(C::Crater, 1, 20, 3.5);
      add(C::Crater, 1.5, 20, 6);
      add(C::Crater, 1.5, 10, 6);
      add(C::Crater, 2, 20, 6);
      add(C::Crater, 2, 10, 6);
      add(C::Crater, 2, 10, 4.5);
      add(C::Crater, 2, 20, 6, "gl");
      add(C::Crater, 1, 20, 6, "cpu", 2, false, true);
      // the drop at particle scale 1: 1835 granules for the whole terrain, 1590 for the LOD
      // patch (the apron rounded out to whole tile periods: 0.2 and 0.5 m give the same patch)
      drop(1, 50, 1, false, 0, 16384, 1, true);
      drop_knob_rows();
      drop(1, 20, 1, false, 0, 16384, 2, false, true);
      drop(1, 20, 1, true, 0.2, 16384, 2, false, true);
      break;
    case TradeoffSweep::Full:
      add(C::Pile, 0.79, 100, 0, "cpu", 1, true);
      for (double s : {0.79, 1.0, 1.26, 1.59})
        for (int n : {10, 20, 50, 100})
          if (!(s == 0.79 && n == 100)) add(C::Pile, s, n, 0);
      add(C::Pile, 1, 20, 0, "cpu", 2, false, true);
      add(C::Pile, 1, 20, 0, "cpu", 3, false, true);
      add(C::Crater, 0.75, 100, 10, "cpu", 1, true);
      for (double s : {0.75, 1.0, 1.5, 2.0})
        for (int n : {10, 20, 50})
          add(C::Crater, s, n, 8);
      for (double p : {4.0, 6.0, 10.0}) add(C::Crater, 1, 20, p);
      add(C::Crater, 2, 20, 6, "gl");
      add(C::Crater, 1.5, 20, 6, "gl");
      add(C::Crater, 1, 20, 8, "cpu", 2, false, true);
      add(C::Crater, 1, 20, 8, "cpu", 3, false, true);
      // the drop at particle scale 1: 1835 granules for the whole terrain, 1590 for the LOD
      // patch (the apron rounded out to whole tile periods: 0.2 and 0.5 m give the same patch)
      drop(1, 100, 1, false, 0, 16384, 1, true);
      drop(1, 50, 1, false, 0, 16384);
      drop_knob_rows();
      drop(1, 20, 8, true, 0.2, 16384);
      drop(1.5, 20, 1, true, 0.2, 16384);
      drop(1, 20, 1, true, 0.5, 16384);
      drop(1, 20, 1, true, 1.0, 16384);  // the manager's default apron: the whole terrain here
      drop(1, 20, 1, false, 0, 16384, 2, false, true);
      drop(1, 20, 1, false, 0, 16384, 3, false, true);
      drop(1, 20, 1, true, 0.2, 16384, 2, false, true);
      break;
  }
  return v;
}

std::vector<bool> pareto_front(const std::vector<double>& cost, const std::vector<double>& error) {
  const std::size_t n = std::min(cost.size(), error.size());
  std::vector<bool> front(n, false);
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(cost[i]) || !std::isfinite(error[i])) continue;
    bool dominated = false;
    for (std::size_t j = 0; j < n && !dominated; ++j) {
      if (j == i || !std::isfinite(cost[j]) || !std::isfinite(error[j])) continue;
      dominated = cost[j] <= cost[i] && error[j] <= error[i] && (cost[j] < cost[i] || error[j] < error[i]);
    }
    front[i] = !dominated;
  }
  return front;
}

Result<CraterResult> measure_crater(const CraterDef& d, CraterBeds* beds) {
  auto bad = [](const char* f, double v, const char* allowed) {
    return Error{"", std::string("CraterDef.") + f, format_number(v), allowed, ""};
  };
  const TradeoffKnobs& k = d.knobs;
  if (!(d.sphere_radius > 0)) return bad("sphere_radius", d.sphere_radius, "must be > 0 (m)");
  if (!(d.sphere_density > 0)) return bad("sphere_density", d.sphere_density, "must be > 0 (kg/m^3)");
  if (!(d.drop_height >= 0)) return bad("drop_height", d.drop_height, "must be >= 0 (m)");
  if (!(d.bed_depth_radii > 0)) return bad("bed_depth_radii", d.bed_depth_radii, "must be > 0");
  if (!(d.impact_seconds > 0)) return bad("impact_seconds", d.impact_seconds, "must be > 0 (s)");
  if (!(d.bin_radii > 0)) return bad("bin_radii", d.bin_radii, "must be > 0");
  if (!(k.particle_scale > 0) || !std::isfinite(k.particle_scale))
    return bad("knobs.particle_scale", k.particle_scale, "must be > 0");
  if (k.steps_per_contact < 2) return bad("knobs.steps_per_contact", k.steps_per_contact, "must be >= 2");
  if (!(k.patch_radii >= 2)) return bad("knobs.patch_radii", k.patch_radii, "must be >= 2 (sphere radii)");
  if (k.backend != "cpu" && k.backend != "gl")
    return Error{"", "CraterDef.knobs.backend", k.backend, "cpu or gl", ""};
  const double settle_radii = std::max(k.patch_radii, d.settle_patch_radii);
  const double s = k.particle_scale, R = d.sphere_radius;
  const float r = d.granule_radius;
  auto scale = ParticleScale::create(s);
  if (!scale) return scale.errors();

  SimulationDef base;
  base.particle_radius = r;
  base.material = d.material;
  base.scale = *scale;
  base.gravity_world = {0, float(-kG), 0};
  base.side_walls = true;
  base.sleep_time = 0;  // never sleeps: the cost measured is the work
  base.threads = d.threads;
  base.max_substeps = 100000;
  // As in a patch (terrain_manager.cpp): the sphere lands on granules that give way; the guard's
  // immovable-target bound would refuse it.
  base.max_overlap_fraction = 0;
  const GranuleShape shape = make_granule_shape(r, base.granule_edge_factor, base.material.density);
  const float spacing = 2.0f * (shape.centre_distance + shape.radius) * 1.02f;
  const double Ls = settle_radii * R / s;  // settled box side, sim units
  const double depth = d.bed_depth_radii * R / s;

  // 1. the settled bed (kept in `beds` for the next setting at this scale, seed and size)
  SettledBed local;
  SettledBed* bed = nullptr;
  if (beds)
    for (auto& b : beds->beds)
      if (b.particle_scale == s && b.seed == k.seed && b.patch_radii == settle_radii) bed = &b;
  double setup_s = 0;
  if (!bed) {
    const auto t0 = Clock::now();
    LatticeBedDef lb;
    lb.nx = lb.nz = std::max(1, int(std::floor((Ls - spacing) / spacing)) + 1);
    const double vg = 16.0 / 3.0 * std::numbers::pi * double(r) * r * r;
    lb.count = std::max(1, int(std::lround(Ls * Ls * depth * kSolidFraction / vg)));
    lb.layers = (lb.count + lb.nx * lb.nz - 1) / (lb.nx * lb.nz);
    lb.spacing = spacing;
    lb.min = {float(0.5 * (Ls - (lb.nx - 1) * spacing)), shape.centre_distance + r + 1e-4f,
              float(0.5 * (Ls - (lb.nz - 1) * spacing))};
    lb.seed = k.seed;
    SimulationDef sd = base;
    sd.max_bodies = lb.count;
    sd.max_particles = 4 * lb.count;
    sd.bounds_min = {0, 0, 0};
    sd.bounds_max = {float(Ls), lb.min.y + lb.layers * spacing + 4 * r, float(Ls)};
    // Settled at t_c / 10 whatever the setting's N (stable; the settling is not what is measured,
    // and every setting of this scale starts from the same bed).
    sd.accuracy_steps_per_contact = 10;
    // Settled with mu <= 0.2, as the manager settles its tiles (terrain_manager.cpp): denser, closer
    // to sand at rest, which the sphere then displaces into a rim rather than compacts.
    sd.material.friction = std::min(0.2f, d.material.friction);
    auto sim = Simulation::create(sd);
    if (!sim) return sim.errors();
    if (auto st = add_lattice_bed(*sim, lb); !st) return st.errors();
    // settle: at least 0.4 s, until every granule is slower than 1 cm/s (sim units), at most 2 s
    for (int f = 0; f < int(2.0 / kFrame); ++f) {
      if (auto st = sim->step(kFrame); !st) return st.errors();
      if (sim->time() >= 0.4 && sim->max_granule_speed() < 0.01) break;
    }
    local.particle_scale = s;
    local.seed = k.seed;
    local.patch_radii = settle_radii;
    for (int i = 0; i < sim->body_count(); ++i) {
      local.position.push_back(sim->body_position(BodyId{i}));
      local.orientation.push_back(sim->body_orientation(BodyId{i}));
    }
    local.settle_seconds = seconds_since(t0);
    setup_s += local.settle_seconds;
    if (beds) {
      beds->beds.push_back(std::move(local));
      bed = &beds->beds.back();
    } else {
      bed = &local;
    }
  }

  // 2. the patch: the centre square of side patch_radii R / s, walls at its sides
  const double L = k.patch_radii * R / s, c = 0.5 * Ls, lo = c - 0.5 * L, hi = c + 0.5 * L;
  float top = 0;
  for (const Vec3& x : bed->position) top = std::max(top, x.y);
  SimulationDef pd = base;
  pd.accuracy_steps_per_contact = k.steps_per_contact;
  pd.max_bodies = int(bed->position.size()) + 1;
  const float Rs = float(R / s);
  pd.max_particles = 4 * int(bed->position.size()) + int(8 * std::pow(Rs / r, 2)) + 64;  // shell ~ 4π R²/(0.87 (1.8 r)²)
  pd.bounds_min = {float(lo), 0, float(lo)};
  pd.bounds_max = {float(hi), top + 2.5f * Rs + float(d.drop_height / s), float(hi)};
  const auto t1 = Clock::now();
  Result<CraterResult> res = Error{"", "", "", "", ""};
  if (k.backend == "gl") {
    auto ctx = gl::Context::create();
    if (!ctx) return Error{"", "backend", "gl", "an OpenGL 4.3 context (EGL)", ctx.message()};
    auto sim = gpu::GlSimulation::create(pd);
    if (!sim) return sim.errors();
    res = run_impact(*sim, d, *bed, lo, hi, c);
  } else {
    auto sim = Simulation::create(pd);
    if (!sim) return sim.errors();
    res = run_impact(*sim, d, *bed, lo, hi, c);
  }
  if (!res) return res;
  res->setup_seconds = setup_s + seconds_since(t1) - res->wall_seconds;
  return res;
}

// ---------------------------------------------------------------------------------------------

std::string check_bench_tradeoff_args(const BenchTradeoffArgs& a) {
  if (a.threads < 0) return "bench tradeoff: --threads = " + std::to_string(a.threads) + ": must be >= 0 (0 = all cores)";
  return "";
}

namespace {

struct Row {
  TradeoffSetting set;
  bool ran = false;
  std::string skipped;     // why not run ("" when it ran)
  std::string refused;     // drop: the manager's refusal ("" when it ran)
  double wall_s = 0, sim_s = 0, setup_s = 0;
  double dt = 0, contact_time = 0;
  int granules = 0;
  // pile
  double angle = 0, residual = 0, peak = 0;
  bool at_rest = false;
  int fit_points = 0;
  // crater
  CraterResult crater;
  // drop (through the TerrainManager); drop.refused: the manager refused the setting
  DropResult drop;
  // against the reference
  double error = std::numeric_limits<double>::quiet_NaN();
  double error_a = std::numeric_limits<double>::quiet_NaN();  // pile: angle; crater: depth (relative)
  double error_b = std::numeric_limits<double>::quiet_NaN();  // crater, drop: rim volume (relative)
  double error_v = std::numeric_limits<double>::quiet_NaN();  // drop: crater volume (relative)
  bool pareto = false;
  double scatter = std::numeric_limits<double>::quiet_NaN();  // noise repeats: |x - x_twin| / ref
};

ojson jnum(double v) { return std::isfinite(v) ? ojson(v) : ojson(); }
// A radial profile of Δh (m) per bin; a bin without samples (held as -1e300) becomes null.
ojson dh_json(const std::vector<double>& dh) {
  ojson out = ojson::array();
  for (double v : dh) out.push_back(v > -1e299 ? ojson(v) : ojson());
  return out;
}

}  // namespace

int run_bench_tradeoff(const BenchTradeoffArgs& a) {
  if (std::string e = check_bench_tradeoff_args(a); !e.empty()) {
    std::fprintf(stderr, "%s\n", e.c_str());
    return 2;
  }
  const fs::path out = a.out_dir.empty() ? fs::path("out") / (std::string("bench_tradeoff_") + to_string(a.sweep))
                                         : fs::path(a.out_dir);
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) {
    std::fprintf(stderr, "bench tradeoff: --out = %s: cannot create the directory%s\n", out.string().c_str(),
                 ec ? (": " + ec.message()).c_str() : "");
    return 2;
  }
  const int threads = a.threads > 0 ? a.threads : omp_get_num_procs();
  const double load_before = load_average();
  const Material mat = reference_material();
  const float r = 0.005f;
  const int pile_n = tradeoff_pile_granules(a.sweep);
  CraterDef cd;
  cd.material = mat;
  cd.granule_radius = r;
  cd.threads = threads;
  if (a.sweep == TradeoffSweep::Quick) cd.impact_seconds = 0.2;
  std::vector<Row> rows;
  for (const auto& t : tradeoff_sweep(a.sweep)) rows.push_back(Row{t});
  // the settled bed of each (scale, seed) is the largest patch of the sweep at them
  std::map<std::pair<double, std::uint64_t>, double> settle_size;
  for (const auto& row : rows)
    if (row.set.kind == TradeoffCase::Crater) {
      double& p = settle_size[{row.set.knobs.particle_scale, row.set.knobs.seed}];
      p = std::max(p, row.set.knobs.patch_radii);
    }
  // GL: one probe for a context (llvmpipe without a GPU)
  std::string gl_skip, gl_renderer;
  if (!a.gl) gl_skip = "--no-gl";
  else {
    auto ctx = gl::Context::create();
    if (!ctx) gl_skip = "no OpenGL 4.3 context: " + ctx.message();
    else gl_renderer = (*ctx)->info().gl_renderer;
  }
  std::vector<ojson> skipped;
  skipped.push_back({{"case", "pile"}, {"knob", "backend = gl"},
                     {"reason", "on llvmpipe a 400-granule pile takes tens of minutes (the GL pile is checked against "
                                "the CPU in tests/particles/gpu); the crater's gl setting measures the backend"}});
  skipped.push_back({{"case", "pile"}, {"knob", "patch size"},
                     {"reason", "the pile lies on its own fixed floor disc (0.2 m), not in a patch"}});
  skipped.push_back({{"case", "pile, crater"}, {"knob", "LOD on/off, simulation.substeps, slot capacity"},
                     {"reason", "these two run straight on the DEM, one patch and no Bullet; the drop case turns these "
                                "knobs through the TerrainManager"}});
  skipped.push_back({{"case", "drop"}, {"knob", "backend = gl, patch size"},
                     {"reason", "the crater case measures the backend on the same DEM; the drop's patch size is what "
                                "LOD on (the apron) or off (the whole terrain) makes it"}});

  std::printf("bench tradeoff (%s sweep): %zu settings, %d threads, load %.2f; pile of %d granules at scale 1, crater "
              "of a %.1f cm sphere (rho %.0f kg/m^3) dropped %.0f cm; material k_n %.0f N/m, e %.2f, mu %.2f, r %.1f mm\n",
              to_string(a.sweep), rows.size(), threads, load_before, pile_n, cd.sphere_radius * 100, cd.sphere_density,
              cd.drop_height * 100, mat.normal_stiffness, mat.restitution, mat.friction, r * 1000.0);
  std::fflush(stdout);
  CraterBeds beds;
  for (auto& row : rows) {
    const TradeoffKnobs& k = row.set.knobs;
    if (row.set.kind == TradeoffCase::Pile) {
      // the pile of particles/pile.hpp on a simulation whose guard substeps at t_c / N
      PileDef pd;
      pd.material = mat;
      pd.particle_radius = r;
      pd.granules = std::max(1, int(std::lround(pile_n / std::pow(k.particle_scale, 3))));
      pd.seed = k.seed;
      pd.threads = threads;
      SimulationDef sd = pile_simulation_def(pd);
      sd.accuracy_steps_per_contact = k.steps_per_contact;
      sd.max_substeps = 100000;
      auto sim = Simulation::create(sd);
      if (!sim) {
        std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), sim.message().c_str());
        return 1;
      }
      auto res = pour_pile(*sim, pd);
      if (!res) {
        std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
        return 1;
      }
      row.ran = true;
      row.wall_s = res->wall_seconds;
      row.sim_s = res->sim_seconds;
      row.granules = res->granules;
      row.dt = sim->last_step().substep_dt;
      row.contact_time = sim->contact_time();
      row.angle = res->angle_deg;
      row.residual = res->residual;
      row.peak = res->peak * k.particle_scale;
      row.at_rest = res->at_rest;
      row.fit_points = res->fit_points;
      std::printf("  %-28s %5d granules, dt t_c/%d: angle %6.2f deg (%d bins, %s), %.2f s simulated in %6.1f s wall "
                  "(RTF %.4f)\n",
                  row.set.id.c_str(), row.granules, k.steps_per_contact, row.angle, row.fit_points,
                  row.at_rest ? "at rest" : "NOT at rest", row.sim_s, row.wall_s, row.sim_s / row.wall_s);
    } else if (row.set.kind == TradeoffCase::Drop) {
      DropDef dd = tradeoff_drop_def(a.sweep);
      dd.threads = threads;
      auto res = measure_drop(dd, k);
      if (!res) {
        std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
        return 1;
      }
      row.drop = *res;
      row.setup_s = res->setup_seconds;
      row.dt = res->dt;
      row.contact_time = res->contact_time;
      if (res->refused) {
        // the setting's outcome: the manager refused the patch (slot too small)
        row.refused = res->refusal;
        while (!row.refused.empty() && row.refused.back() == '\n') row.refused.pop_back();
        std::printf("  %-40s refused at t = %.3f s: %s\n", row.set.id.c_str(), res->refused_at, row.refused.c_str());
      } else {
        row.ran = true;
        row.wall_s = res->wall_seconds;
        row.sim_s = res->sim_seconds;
        row.granules = res->granules;
        std::printf("  %-40s %5d granules (%d patch%s), dt t_c/%d, %d Bullet substep%s: depth %5.2f cm, crater %6.0f "
                    "cm^3 (r %.0f cm), rim %6.0f cm^3 (height %.2f cm), sphere sank %.2f cm, far field %+.2f cm, ledger "
                    "%+.2f %%, %s; "
                    "%.2f s simulated in %6.1f s wall (RTF %.4f; DEM %.1f s; set-up %.1f s)\n",
                    row.set.id.c_str(), row.granules, res->patches, res->patches == 1 ? "" : "es", k.steps_per_contact,
                    k.substeps, k.substeps == 1 ? "" : "s", res->depth * 100, res->crater_volume * 1e6,
                    res->crater_radius * 100, res->rim_volume * 1e6, res->rim_height * 100, res->sphere_sink * 100,
                    res->far_field_dh * 100, res->ledger_error_pct, res->asleep_at_end ? "asleep" : "awake", row.sim_s, row.wall_s,
                    row.sim_s / row.wall_s, res->dem_seconds, row.setup_s);
      }
    } else {
      if (k.backend == "gl" && !gl_skip.empty()) {
        row.skipped = gl_skip;
        std::printf("  %-28s skipped: %s\n", row.set.id.c_str(), gl_skip.c_str());
        continue;
      }
      CraterDef d = cd;
      d.knobs = k;
      d.settle_patch_radii = settle_size[{k.particle_scale, k.seed}];
      auto res = measure_crater(d, &beds);
      if (!res) {
        std::fprintf(stderr, "bench tradeoff: %s: %s", row.set.id.c_str(), res.message().c_str());
        return 1;
      }
      row.ran = true;
      row.crater = *res;
      row.wall_s = res->wall_seconds;
      row.sim_s = res->sim_seconds;
      row.setup_s = res->setup_seconds;
      row.granules = res->granules;
      row.dt = res->dt;
      row.contact_time = res->contact_time;
      std::printf("  %-28s %5d granules, dt t_c/%d: depth %5.2f cm, rim %6.1f cm^3 (height %.2f cm), crater r %.1f cm; "
                  "%.2f s simulated in %6.1f s wall (RTF %.4f; set-up %.1f s)\n",
                  row.set.id.c_str(), row.granules, k.steps_per_contact, res->depth * 100, res->rim_volume * 1e6,
                  res->rim_height * 100, res->crater_radius * 100, row.sim_s, row.wall_s, row.sim_s / row.wall_s,
                  row.setup_s);
    }
    std::fflush(stdout);
  }

  // errors against each case's reference; the Pareto front per case (noise repeats left out)
  bool rim_resolved_out = false, drop_rim_resolved = false;
  for (TradeoffCase c : {TradeoffCase::Pile, TradeoffCase::Crater, TradeoffCase::Drop}) {
    const Row* ref = nullptr;
    for (const auto& row : rows)
      if (row.set.kind == c && row.set.reference && row.ran) ref = &row;
    if (!ref) continue;
    // the rim counts only when the reference resolves one: at least a granule sphere radius
    // high (world) — lower, it is the roughness of a granular surface
    const bool rim_resolved =
        (c == TradeoffCase::Crater && ref->crater.rim_volume > 0 &&
         ref->crater.rim_height >= double(r) * ref->set.knobs.particle_scale) ||
        (c == TradeoffCase::Drop && ref->drop.rim_volume > 0 &&
         ref->drop.rim_height >= double(tradeoff_drop_def(a.sweep).granule_radius) * ref->set.knobs.particle_scale);
    if (c == TradeoffCase::Crater) rim_resolved_out = rim_resolved;
    if (c == TradeoffCase::Drop) drop_rim_resolved = rim_resolved;
    auto rel = [](double x, double x_ref) { return x_ref > 0 ? std::abs(x - x_ref) / x_ref : NAN; };
    for (auto& row : rows) {
      if (row.set.kind != c || !row.ran) continue;
      if (c == TradeoffCase::Pile) {
        row.error_a = ref->angle != 0 ? std::abs(row.angle - ref->angle) / std::abs(ref->angle) : NAN;
        row.error = row.error_a;
      } else if (c == TradeoffCase::Crater) {
        row.error_a = rel(row.crater.depth, ref->crater.depth);
        row.error_b = rim_resolved ? rel(row.crater.rim_volume, ref->crater.rim_volume) : NAN;
        row.error = std::isfinite(row.error_b) ? std::max(row.error_a, row.error_b) : row.error_a;
      } else {
        // drop: the worst of depth, crater volume and (when resolved) rim volume
        row.error_a = rel(row.drop.depth, ref->drop.depth);
        row.error_v = rel(row.drop.crater_volume, ref->drop.crater_volume);
        row.error_b = rim_resolved ? rel(row.drop.rim_volume, ref->drop.rim_volume) : NAN;
        row.error = row.error_a;
        for (double e : {row.error_v, row.error_b})
          if (std::isfinite(e)) row.error = std::isfinite(row.error) ? std::max(row.error, e) : e;
      }
    }
    // noise floor: a repeat with another seed against its seed-1 twin (same knobs), relative to the reference
    for (auto& row : rows) {
      if (row.set.kind != c || !row.ran || !row.set.noise) continue;
      for (const auto& twin : rows) {
        const auto &ka = row.set.knobs, &kb = twin.set.knobs;
        if (twin.set.kind != c || !twin.ran || twin.set.noise || ka.particle_scale != kb.particle_scale ||
            ka.steps_per_contact != kb.steps_per_contact || ka.patch_radii != kb.patch_radii ||
            ka.backend != kb.backend || ka.substeps != kb.substeps || ka.lod != kb.lod ||
            ka.lod_apron != kb.lod_apron || ka.granules_per_slot != kb.granules_per_slot)
          continue;
        if (c == TradeoffCase::Pile) {
          row.scatter = std::abs(row.angle - twin.angle) / std::abs(ref->angle);
        } else if (c == TradeoffCase::Crater) {
          const double sd = std::abs(row.crater.depth - twin.crater.depth) / ref->crater.depth;
          const double sr = rim_resolved
                                ? std::abs(row.crater.rim_volume - twin.crater.rim_volume) / ref->crater.rim_volume
                                : NAN;
          row.scatter = std::isfinite(sr) ? std::max(sd, sr) : sd;
        } else {
          double sc = std::abs(row.drop.depth - twin.drop.depth) / ref->drop.depth;
          if (ref->drop.crater_volume > 0)
            sc = std::max(sc, std::abs(row.drop.crater_volume - twin.drop.crater_volume) / ref->drop.crater_volume);
          if (rim_resolved) sc = std::max(sc, std::abs(row.drop.rim_volume - twin.drop.rim_volume) / ref->drop.rim_volume);
          row.scatter = sc;
        }
      }
    }
    std::vector<double> cost, err;
    std::vector<Row*> in;
    for (auto& row : rows)
      if (row.set.kind == c && row.ran && !row.set.noise) {
        in.push_back(&row);
        cost.push_back(row.wall_s / row.sim_s);
        err.push_back(row.error);
      }
    const auto front = pareto_front(cost, err);
    for (std::size_t i = 0; i < in.size(); ++i) in[i]->pareto = front[i];
  }

  // CSV (one row a setting) and JSON
  std::string csv =
      "id,case,particle_scale,steps_per_contact,patch_radii,backend,substeps,granules_per_slot,lod,lod_apron_m,seed,"
      "reference,noise,ran,outcome,granules,dt_s,dt_over_tc,sim_s,wall_s,wall_s_per_sim_s,real_time_factor,angle_deg,"
      "depth_m,crater_volume_m3,rim_volume_m3,rim_height_m,crater_radius_m,error,error_angle_or_depth,error_rim,"
      "error_crater_volume,pareto,skipped\n";
  ojson settings = ojson::array();
  for (const auto& row : rows) {
    const auto& k = row.set.knobs;
    const bool crater = row.set.kind == TradeoffCase::Crater, drop = row.set.kind == TradeoffCase::Drop;
    const std::string outcome = row.ran ? "ok" : !row.refused.empty() ? "refused" : "skipped";
    const double cost = row.ran ? row.wall_s / row.sim_s : NAN, rtf = row.ran ? row.sim_s / row.wall_s : NAN;
    auto f = [](double v) {
      if (!std::isfinite(v)) return std::string();
      char b[40];
      std::snprintf(b, sizeof b, "%.6g", v);
      return std::string(b);
    };
    const bool pile = row.set.kind == TradeoffCase::Pile;
    const double depth = !row.ran ? NAN : crater ? row.crater.depth : drop ? row.drop.depth : NAN;
    const double cvol = !row.ran ? NAN : crater ? row.crater.crater_volume : drop ? row.drop.crater_volume : NAN;
    const double rvol = !row.ran ? NAN : crater ? row.crater.rim_volume : drop ? row.drop.rim_volume : NAN;
    const double rh = !row.ran ? NAN : crater ? row.crater.rim_height : drop ? row.drop.rim_height : NAN;
    const double crad = !row.ran ? NAN : crater ? row.crater.crater_radius : drop ? row.drop.crater_radius : NAN;
    const bool timed = row.ran && row.dt > 0 && row.contact_time > 0;
    std::string why = row.ran ? "" : !row.refused.empty() ? row.refused : row.skipped;
    std::replace(why.begin(), why.end(), '"', '\'');
    std::replace(why.begin(), why.end(), '\n', ' ');
    csv += row.set.id + "," + to_string(row.set.kind) + "," + f(k.particle_scale) + "," +
           std::to_string(k.steps_per_contact) + "," + (crater ? f(k.patch_radii) : "") + "," + k.backend + "," +
           (drop ? std::to_string(k.substeps) : "") + "," + (drop ? std::to_string(k.granules_per_slot) : "") + "," +
           (drop ? (k.lod ? "on" : "off") : "") + "," + (drop && k.lod ? f(k.lod_apron) : "") + "," +
           std::to_string(k.seed) + "," + (row.set.reference ? "1" : "0") + "," + (row.set.noise ? "1" : "0") + "," +
           (row.ran ? "1" : "0") + "," + outcome + "," + std::to_string(row.granules) + "," + f(timed ? row.dt : NAN) +
           "," + f(timed ? row.dt / row.contact_time : NAN) + "," + f(row.ran ? row.sim_s : NAN) + "," +
           f(row.ran ? row.wall_s : NAN) + "," + f(cost) + "," + f(rtf) + "," + f(pile && row.ran ? row.angle : NAN) +
           "," + f(depth) + "," + f(cvol) + "," + f(rvol) + "," + f(rh) + "," + f(crad) + "," + f(row.error) + "," +
           f(row.error_a) + "," + f(row.error_b) + "," + f(row.error_v) + "," + (row.pareto ? "1" : "0") + ",\"" +
           why + "\"\n";
    ojson j = {{"id", row.set.id},
               {"case", to_string(row.set.kind)},
               {"particle_scale", k.particle_scale},
               {"steps_per_contact", k.steps_per_contact},
               {"patch_radii", crater ? ojson(k.patch_radii) : ojson()},
               {"backend", k.backend},
               {"substeps", drop ? ojson(k.substeps) : ojson()},
               {"granules_per_slot", drop ? ojson(k.granules_per_slot) : ojson()},
               {"lod", drop ? ojson(k.lod ? "on" : "off") : ojson()},
               {"lod_apron_m", drop && k.lod ? ojson(k.lod_apron) : ojson()},
               {"seed", k.seed},
               {"reference", row.set.reference},
               {"noise", row.set.noise},
               {"ran", row.ran},
               {"outcome", outcome}};
    if (!row.refused.empty()) {
      // the manager refused the setting: its message names the capacity to raise
      j["refused"] = row.refused;
      j["refused_at_s"] = row.drop.refused_at;
      j["pool_bytes"] = row.drop.pool_bytes;
      j["setup_s"] = row.setup_s;
    } else if (!row.ran) {
      j["skipped"] = row.skipped;
    } else {
      j["granules"] = row.granules;
      j["dt_s"] = timed ? ojson(row.dt) : ojson();
      j["dt_over_tc"] = timed ? ojson(row.dt / row.contact_time) : ojson();
      j["sim_s"] = row.sim_s;
      j["wall_s"] = row.wall_s;
      j["wall_s_per_sim_s"] = cost;
      j["real_time_factor"] = rtf;
      if (crater) {
        j["depth_m"] = row.crater.depth;
        j["rim_volume_m3"] = row.crater.rim_volume;
        j["rim_height_m"] = row.crater.rim_height;
        j["crater_radius_m"] = row.crater.crater_radius;
        j["crater_volume_m3"] = row.crater.crater_volume;
        j["sphere_sink_m"] = row.crater.sphere_sink;
        j["final_speed_m_s"] = row.crater.final_speed;
        j["setup_s"] = row.setup_s;
        j["dh_m"] = dh_json(row.crater.dh);  // Δh per bin of bin_m from the axis
      } else if (drop) {
        j["depth_m"] = row.drop.depth;
        j["crater_volume_m3"] = row.drop.crater_volume;
        j["crater_radius_m"] = row.drop.crater_radius;
        j["rim_volume_m3"] = row.drop.rim_volume;
        j["rim_height_m"] = row.drop.rim_height;
        j["sphere_sink_m"] = row.drop.sphere_sink;
        j["far_field_dh_m"] = row.drop.far_field_dh;
        j["ledger_error_pct"] = row.drop.ledger_error_pct;
        j["patches"] = row.drop.patches;
        j["pool_bytes"] = row.drop.pool_bytes;
        j["dem_wall_s"] = row.drop.dem_seconds;
        j["asleep_at_end"] = row.drop.asleep_at_end;
        j["setup_s"] = row.setup_s;
        j["dh_m"] = dh_json(row.drop.dh);  // mean Δh per radial bin of one sample spacing from the axis
      } else {
        j["angle_deg"] = row.angle;
        j["fit_points"] = row.fit_points;
        j["fit_residual_m"] = row.residual;
        j["pile_height_m"] = row.peak;
        j["at_rest"] = row.at_rest;
      }
      j["error"] = jnum(row.error);
      j[crater || drop ? "error_depth" : "error_angle"] = jnum(row.error_a);
      if (crater || drop) j["error_rim"] = jnum(row.error_b);
      if (drop) j["error_crater_volume"] = jnum(row.error_v);
      j["pareto"] = row.pareto;
      if (row.set.noise) j["seed_scatter"] = jnum(row.scatter);
    }
    settings.push_back(j);
  }
  const double load_after = load_average();
  const DropDef dd0 = tradeoff_drop_def(a.sweep);
  const fs::path csv_path = out / "tradeoff.csv", json_path = out / "tradeoff.json", png_path = out / "tradeoff.png";
  ojson result = {{"bench", "tradeoff"},
                  {"sweep", to_string(a.sweep)},
                  {"csv", csv_path.string()},
                  {"json", json_path.string()},
                  {"plot", ojson()},
                  {"cost", "wall_s_per_sim_s: wall seconds of the measured phase per simulated second (1 / real_time_factor)"},
                  {"error", "pile: |angle - angle_ref| / angle_ref; crater: max(|depth - ref| / ref, |rim volume - ref| / "
                            "ref), the rim term only when the reference's rim is at least a granule sphere radius high "
                            "(cases.crater.rim_in_error); drop: max(|depth - ref| / ref, |crater volume - ref| / ref, "
                            "|rim volume - ref| / ref), the rim term as the crater's (cases.drop.rim_in_error); ref = "
                            "the case's reference setting; a refused setting has no error (outcome refused)"},
                  {"cases",
                   {{"pile", {{"granules_at_scale_1", pile_n}, {"granule_radius_m", r}, {"floor_radius_m", 0.2}}},
                    {"crater", {{"sphere_radius_m", cd.sphere_radius}, {"sphere_density", cd.sphere_density},
                                {"drop_height_m", cd.drop_height}, {"impact_speed_m_s", std::sqrt(2 * kG * cd.drop_height)},
                                {"bed_depth_m", cd.bed_depth_radii * cd.sphere_radius}, {"impact_seconds", cd.impact_seconds},
                                {"bin_m", cd.bin_radii * cd.sphere_radius}, {"granule_radius_m", r},
                                {"rim_in_error", rim_resolved_out}}},
                    {"drop", {{"path", "Bullet sphere onto a flat heightfield through the TerrainManager (bench/tradeoff_drop.hpp); "
                                       "crater measured in the heightfield after demote_all"},
                              {"sphere_radius_m", dd0.sphere_radius}, {"sphere_density", dd0.sphere_density},
                              {"drop_height_m", dd0.drop_height}, {"impact_speed_m_s", std::sqrt(2 * kG * dd0.drop_height)},
                              {"terrain_side_m", dd0.terrain_side}, {"spacing_m", dd0.spacing},
                              {"patch_depth_m", dd0.patch_depth}, {"run_seconds", dd0.run_seconds},
                              {"frame_dt_s", dd0.frame_dt}, {"granule_radius_m", dd0.granule_radius},
                              {"material", {{"normal_stiffness", dd0.stiffness}, {"restitution", dd0.restitution},
                                            {"friction", dd0.friction}, {"density", dd0.granule_density}}},
                              {"rim_in_error", drop_rim_resolved}}},
                    {"material", {{"normal_stiffness", mat.normal_stiffness}, {"restitution", mat.restitution},
                                  {"friction", mat.friction}, {"density", mat.density}}}}},
                  {"settings", settings},
                  {"not_swept", skipped},
                  {"gl_renderer", gl_renderer},
                  {"threads", threads},
                  {"load_average", {load_before, load_after}}};
  std::string plot_note;
  if (!write_text(csv_path, csv) || !write_text(json_path, result.dump(2) + "\n")) {
    std::fprintf(stderr, "bench tradeoff: cannot write %s or %s\n", csv_path.string().c_str(), json_path.string().c_str());
    return 1;
  }
  if (!a.plot_script.empty()) {
    std::fflush(stdout);
    const std::string python = fs::exists("/usr/bin/python3") ? "/usr/bin/python3" : "python3";
    const std::string cmd = python + " '" + a.plot_script + "' '" + json_path.string() + "' '" + png_path.string() +
                            "' 2>&1";
    const int status = std::system(cmd.c_str());
    const int rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    if (rc == 0) {
      result["plot"] = png_path.string();
    } else {
      plot_note = python + " " + a.plot_script + " exited with " + std::to_string(rc) +
                  (rc == 3 ? ": matplotlib missing (apt-get install python3-matplotlib)"
                           : rc == 127 ? ": python3 missing" : "");
      result["plot_note"] = plot_note;
    }
    write_text(json_path, result.dump(2) + "\n");
  } else {
    result["plot_note"] = "no plot asked for (--no-plot)";
  }

  // summary table
  std::printf("\n%-40s %8s %10s %8s %9s %s\n", "setting", "granules", "wall/sim", "RTF", "error", "pareto");
  for (const auto& row : rows) {
    if (!row.refused.empty()) {
      std::printf("%-40s refused: %s\n", row.set.id.c_str(), row.refused.c_str());
      continue;
    }
    if (!row.ran) {
      std::printf("%-40s skipped: %s\n", row.set.id.c_str(), row.skipped.c_str());
      continue;
    }
    std::printf("%-40s %8d %10.2f %8.4f %9.4f %s%s%s\n", row.set.id.c_str(), row.granules, row.wall_s / row.sim_s,
                row.sim_s / row.wall_s, row.error, row.pareto ? "*" : "", row.set.reference ? " (reference)" : "",
                row.set.noise ? " (other seed: noise floor)" : "");
  }
  std::printf("load average %.2f -> %.2f\ndata: %s, %s\n", load_before, load_after, csv_path.string().c_str(),
              json_path.string().c_str());
  if (result["plot"].is_string()) std::printf("plot: %s\n", png_path.string().c_str());
  else std::printf("plot: not made (%s); the data above is written\n", result["plot_note"].get<std::string>().c_str());
  if (a.json) {
    ojson line = {{"bench", "tradeoff"}, {"csv", result["csv"]}, {"plot", result["plot"]}, {"json", result["json"]}};
    ojson list = ojson::array();
    for (const auto& s : settings) {
      ojson e = {{"id", s["id"]}, {"case", s["case"]}, {"ran", s["ran"]}};
      for (const char* key : {"particle_scale", "steps_per_contact", "patch_radii", "backend", "substeps",
                              "granules_per_slot", "lod", "lod_apron_m", "seed", "reference", "noise", "outcome", "wall_s",
                              "wall_s_per_sim_s", "real_time_factor", "error", "seed_scatter", "pareto", "skipped",
                              "refused"})
        if (s.contains(key)) e[key] = s[key];
      list.push_back(e);
    }
    line["settings"] = list;
    if (!plot_note.empty()) line["plot_note"] = plot_note;
    std::printf("%s\n", line.dump().c_str());
  }
  return 0;
}

}  // namespace sandpatch
