// bench tradeoff, the crater case: a sphere dropped into a settled granular bed straight on the
// DEM (measure_crater, bench/bench_tradeoff.hpp; docs/tradeoff.md). One settled bed per scale
// and seed is cut to every patch size, as the manager cuts its tiles.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <string>
#include <vector>

#include "bench/tradeoff_internal.hpp"
#include "gl/context.hpp"
#include "particles/bed.hpp"
#include "particles/dem.hpp"
#include "particles/gpu/gl_simulation.hpp"
#include "particles/pile.hpp"

namespace sandpatch {

namespace {

using tradeoff_internal::Clock;
using tradeoff_internal::kFrame;
using tradeoff_internal::kG;
using tradeoff_internal::seconds_since;

constexpr double kSolidFraction = 0.47;    // settled granule beds, spheres' solid fraction (terrain_manager.cpp)
constexpr int kSectors = 8;

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
  const double t_release = sim.time();

  CraterResult out;
  out.granules = granules;
  out.spheres = sim.particle_count();
  const auto t0 = Clock::now();
  const double fdt = d.frame_dt;
  const int frames = int(std::lround(d.impact_seconds / fdt));
  if constexpr (requires(Sim& x) { x.set_energy_ledger(true); }) {
    if (d.trace) {
      // energies of the simulation (sim units: J of the world at particle scale 1)
      const double gs = -double(sim.def().scale.gravity_to_sim(sim.def().gravity_world).y);
      const double mg = double(g.mass);
      auto bed_sums = [&](double* ke, double* pe) {
        *ke = *pe = 0;
        for (int i = 0; i < granules; ++i) {
          const Vec3 v = sim.body_velocity(BodyId{i}), w = sim.body_angular_velocity(BodyId{i});
          *ke += 0.5 * mg * double(dot(v, v)) + 0.5 * double(g.inertia) * double(dot(w, w));
          *pe += mg * gs * double(sim.body_position(BodyId{i}).y);
        }
      };
      const double Mb = double(sh.mass);
      double ke0, pe0;
      bed_sums(&ke0, &pe0);
      const double ball_pe0 = Mb * gs * double(sim.body_position(*body).y);
      sim.set_energy_ledger(true);
      const double et0 = sim.tangential_spring_energy();
      bool first_frame = true;
      double el_base = 0;  // the springs at the first substep (the resting bed's), J
      auto record = [&]() {
        CraterFrame fr;
        fr.t = sim.time() - t_release;
        const Vec3 bv = sim.body_velocity(*body);
        fr.bottom = (double(sim.body_position(*body).y) - Rs) * s - mean0;
        fr.vy = bv.y * s;
        fr.body_kinetic = 0.5 * Mb * double(dot(bv, bv));
        const Vec3 bw = sim.body_angular_velocity(*body);
        fr.body_kinetic += 0.5 * double(inertia) * double(dot(bw, bw));
        const double ball_pe = Mb * gs * double(sim.body_position(*body).y);
        fr.body_potential = ball_pe - ball_pe0;
        double ke, pe;
        bed_sums(&ke, &pe);
        fr.bed_kinetic = ke;
        fr.bed_potential = pe - pe0;
        const double el = sim.normal_spring_energy() + sim.tangential_spring_energy();
        if (first_frame && sim.time() > t_release) el_base = el, first_frame = false;
        fr.elastic = sim.time() > t_release ? el - el_base : 0.0;
        fr.elastic_tangential = sim.tangential_spring_energy() - et0;
        fr.normal_damping = sim.dissipated_normal();
        fr.friction = sim.dissipated_friction();
        out.frames.push_back(fr);
      };
      (void)ke0;
      record();
      for (int f = 0; f < frames; ++f) {
        if (auto st = sim.step(fdt); !st) return st.errors();
        record();
      }
      sim.set_energy_ledger(false);
    }
  }
  if (out.frames.empty())
    for (int f = 0; f < frames; ++f)
      if (auto st = sim.step(fdt); !st) return st.errors();
  (void)sim.max_granule_speed();  // GL: waits for the last frame (its status read-back)
  out.wall_seconds = seconds_since(t0);
  out.sim_seconds = frames * fdt;
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
    sd.material.unloading_stiffness_ratio = 1.0f;  // settled linear, as the manager settles its tiles
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

}  // namespace sandpatch
