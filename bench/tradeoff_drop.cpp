// The drop case of `sandpatch bench tradeoff` (bench/tradeoff_drop.hpp): a Bullet sphere onto
// a flat heightfield terrain through the TerrainManager, the crater read from the heightfield.
#include "bench/tradeoff_drop.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include "bench/bench_tradeoff.hpp"
#include "heightfield/heightfield.hpp"
#include "heightfield/procedural.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/world.hpp"
#include "particles/dem.hpp"

namespace sandpatch {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The DEM substep and contact time a slot of this definition runs at for one frame: a probe
// simulation with the slot's material, scale and N (TerrainManager's sim_def), no granules.
void probe_dt(const DropDef& d, const TradeoffKnobs& k, double* dt, double* tc) {
  *dt = *tc = 0;
  SimulationDef sd;
  sd.max_bodies = 4;
  sd.max_particles = 16;
  sd.particle_radius = d.granule_radius;
  sd.material.density = d.granule_density;
  sd.material.normal_stiffness = d.stiffness;
  sd.material.restitution = d.restitution;
  sd.material.friction = d.friction;
  sd.material.unloading_stiffness_ratio = d.unloading_ratio;
  sd.accuracy_steps_per_contact = k.steps_per_contact;
  sd.max_substeps = 100000;
  sd.max_overlap_fraction = 0;
  auto sc = ParticleScale::create(k.particle_scale);
  if (!sc) return;
  sd.scale = *sc;
  auto sim = Simulation::create(sd);
  if (!sim) return;
  if (!sim->step(d.frame_dt)) return;
  *dt = sim->last_step().substep_dt;
  *tc = sim->contact_time();
}

}  // namespace

Result<DropResult> measure_drop(const DropDef& d, const TradeoffKnobs& k) {
  auto bad = [](const std::string& f, double v, const char* allowed) {
    return Error{"", "DropDef." + f, format_number(v), allowed, ""};
  };
  if (!(d.sphere_radius > 0)) return bad("sphere_radius", d.sphere_radius, "must be > 0 (m)");
  if (!(d.sphere_density > 0)) return bad("sphere_density", d.sphere_density, "must be > 0 (kg/m^3)");
  if (!(d.drop_height >= 0)) return bad("drop_height", d.drop_height, "must be >= 0 (m)");
  if (!(d.spacing > 0)) return bad("spacing", d.spacing, "must be > 0 (m)");
  if (!(d.terrain_side >= 4 * d.sphere_radius)) return bad("terrain_side", d.terrain_side, "must be >= 4 sphere radii (m)");
  if (!(d.run_seconds > 0)) return bad("run_seconds", d.run_seconds, "must be > 0 (s)");
  if (!(d.frame_dt > 0)) return bad("frame_dt", d.frame_dt, "must be > 0 (s)");
  if (!(d.patch_depth > 0)) return bad("patch_depth", d.patch_depth, "must be > 0 (m)");
  if (k.substeps < 1) return bad("knobs.substeps", k.substeps, "must be >= 1");
  if (k.lod && !(k.lod_apron >= 0)) return bad("knobs.lod_apron", k.lod_apron, "must be >= 0 (m)");
  if (k.backend != "cpu" && k.backend != "gl") return Error{"", "DropDef.knobs.backend", k.backend, "cpu or gl", ""};

  // the terrain
  HeightfieldDef g;
  g.samples_x = g.samples_z = int(std::lround(d.terrain_side / d.spacing)) + 1;
  g.spacing = d.spacing;
  ProceduralHeightsDef p;
  p.kind = "flat";
  p.height = float(d.surface_height);
  auto hf = make_procedural(g, p);
  if (!hf) return hf.errors();
  const Heightfield original = *hf;
  auto made_world = World::create(std::move(*hf), {0, -9.81f, 0});
  if (!made_world) return made_world.errors();
  World& world = **made_world;
  const Heightfield* terrain = &world.heightfield();

  // the manager, as manager_def (manager/run.cpp) makes it from a scene, with the case's knobs
  TerrainManagerDef md;
  md.material.radius = d.granule_radius;
  md.material.density = d.granule_density;
  md.material.friction = d.friction;
  md.material.restitution = d.restitution;
  md.material.stiffness = d.stiffness;
  md.material.unloading_stiffness_ratio = d.unloading_ratio;
  md.particle_scale = k.particle_scale;
  md.steps_per_contact = k.steps_per_contact;
  md.slots = 1;
  md.granules_per_slot = k.granules_per_slot;
  md.patch_depth = d.patch_depth;
  md.soil_depth = 2.0;
  md.idle_timeout = 1e9;  // no demotion before demote_all, LOD on or off
  md.lod.apron = k.lod ? k.lod_apron : 0.2;  // LOD off: the whole-terrain patch covers every prediction
  md.fill_granules_per_frame = 1 << 20;  // the whole patch in its first frame, LOD on and off alike
  md.use_gl = false;                     // the CPU depth render (same contract, no GL context needed)
  // Every granule of an awake patch stepped: the drop and the impact experiments measure the
  // contact model and the knobs above, not the sleeping regions' freezing (its own error is
  // measured in docs/dem.md "Sleeping regions").
  md.sleep_regions = false;
  md.backend = k.backend;
  md.threads = d.threads;
  md.seed = d.settle_seed ? d.settle_seed : k.seed;
  md.tile_cache = d.tile_cache;
  if (d.max_substeps > 0) md.max_substeps = d.max_substeps;
  const auto t0 = Clock::now();
  if (Status st = world.enable_patches(md); !st) return st.errors();
  TerrainManager& m = *world.manager();
  DropResult out;
  out.setup_seconds = seconds_since(t0);
  probe_dt(d, k, &out.dt, &out.contact_time);

  // the sphere
  const double R = d.sphere_radius, c = 0.5 * d.terrain_side;
  RigidBodyDef b;
  b.name = "sphere";
  b.shape.kind = RigidShapeKind::Sphere;
  b.shape.radius = float(R);
  b.mass = float(d.sphere_density * 4.0 / 3.0 * std::numbers::pi * R * R * R);
  b.position = {c, d.surface_height + d.drop_height + R, c};
  auto body = world.add_body(b);
  if (!body) return body.errors();

  // the frame of every caller (World::step)
  const double dt = d.frame_dt;
  const int frames = int(std::lround(d.run_seconds / dt));
  if (!k.lod) m.request_patch(0, 0, d.terrain_side, d.terrain_side, 0.0);
  const auto t1 = Clock::now();
  const double weight = double(b.mass) * 9.81;  // N
  bool hit = false, turned = false;  // the soil has pushed the sphere; it has since stopped going down
  double last_still = 0;  // s, the last frame end at which the sphere was still faster than 1 % of v_in
  for (int f = 0; f < frames; ++f) {
    const double t = world.time();
    Status st = world.step(dt, k.substeps);
    if (!st) {
      // A patch larger than the slot is refused by the manager (promote(): the error names
      // simulation.pool.granules_per_slot and the granules the patch needs): the outcome of
      // that setting, not a failure of the bench.
      if (st.error().field.find("granules_per_slot") == std::string::npos) return st.errors();
      out.refused = true;
      out.refusal = st.message();
      out.refused_at = t;
      out.wall_seconds = seconds_since(t1);
      out.pool_bytes = m.pool_bytes();
      return out;
    }
    out.granules = std::max(out.granules, m.granules());
    const BodyState bs = world.bullet().state(*body);
    Eigen::Vector3f force = Eigen::Vector3f::Zero(), torque = Eigen::Vector3f::Zero();
    if (!m.soil_force(*body, &force, &torque)) force.setZero();
    DropFrame fr;
    fr.t = world.time();
    fr.bottom = bs.position.y() - R - d.surface_height;
    fr.vy = bs.linear_velocity.y();
    fr.fy = force.y();
    if (!hit && fr.fy > 0.1 * weight) {  // not the round-off of a free flight's momentum balance
      hit = true;
      out.impact_speed = out.frames.empty() ? std::sqrt(2 * 9.81 * d.drop_height) : std::abs(out.frames.back().vy);
    }
    if (hit) {
      out.rebound_speed = std::max(out.rebound_speed, fr.vy);
      if (!turned && fr.vy >= 0) turned = true, out.rebound_bottom = fr.bottom;
      if (turned) out.rebound_bottom = std::max(out.rebound_bottom, fr.bottom);
      if (bs.linear_velocity.norm() > 0.01 * out.impact_speed) last_still = fr.t;
    }
    out.deepest = std::max(out.deepest, -fr.bottom);
    out.frames.push_back(fr);
  }
  // (a sphere still going down at the end never turned: the field reads its bottom at the end,
  // not the original surface it starts at)
  if (hit && !turned && !out.frames.empty()) out.rebound_bottom = out.frames.back().bottom;
  if (hit) {
    // frame k0: the first in which the soil pushed the sphere (the hit)
    std::size_t k0 = 0;
    while (k0 < out.frames.size() && !(out.frames[k0].fy > 0.1 * weight)) ++k0;
    const double t_hit = k0 < out.frames.size() ? out.frames[k0].t - dt : 0.0;
    out.rebound_ratio = out.impact_speed > 0 ? out.rebound_speed / out.impact_speed : 0;
    out.settle_time = last_still - t_hit;
    // the stop (stop_time ...): frame k the first no longer going down
    // (stopped: going down at less than 1 % of the impact speed, the precision of a speed read
    // from frame ends; a light ball's last millimetres creep)
    const double v_stop = -0.01 * out.impact_speed;
    std::size_t k = k0;
    while (k < out.frames.size() && out.frames[k].vy < v_stop) ++k;
    if (k0 > 0 && k < out.frames.size() && out.frames[k - 1].vy < v_stop) {  // (k = k0: it stopped in the first frame)
      const DropFrame &a = out.frames[k - 1], &b = out.frames[k];
      const double u = (a.vy - v_stop) / (a.vy - b.vy);  // in [0, 1): where vy crosses v_stop
      const double t_stop = a.t + u * (b.t - a.t), bottom_stop = a.bottom + u * (b.bottom - a.bottom);
      const DropFrame& before = out.frames[k0 - 1];
      out.stop_time = t_stop - before.t;
      out.stop_penetration = before.bottom - bottom_stop;
      if (out.stop_penetration > 0) out.stop_time_ratio = out.stop_time * out.impact_speed / out.stop_penetration;
      std::size_t peak = k0;
      for (std::size_t i = k0; i <= k; ++i)
        if (out.frames[i].fy > out.frames[peak].fy) peak = i;
      out.peak_force_at = out.stop_time > 0 ? std::clamp((out.frames[peak].t - before.t) / out.stop_time, 0.0, 1.0) : 0.0;
    }
  }
  if (!d.trace) out.frames.clear();
  bool asleep = m.active_patches() > 0;
  for (const auto& pi : m.patches()) asleep = asleep && pi.asleep;
  out.asleep_at_end = asleep;
  out.sphere_sink = d.surface_height - (world.bullet().state(*body).position.y() - R);
  if (Status st = world.demote_all(); !st) return st.errors();
  out.wall_seconds = seconds_since(t1);
  {
    const int ic = int(std::lround(c / d.spacing));
    out.axis_depth_after = d.surface_height - terrain->height(ic, ic);
    const Eigen::Vector3d p0 = world.bullet().state(*body).position;
    for (int f = 0; f < int(std::lround(d.after_demotion / dt)); ++f)
      if (Status st = world.step(dt, k.substeps); !st) return st.errors();
    out.shift_after_demotion = (world.bullet().state(*body).position - p0).norm();
  }
  out.sim_seconds = frames * dt;
  out.dem_seconds = world.profile().timer(Stage::Dem).total_ms / 1000.0;
  out.pool_bytes = m.pool_bytes();
  for (const PatchEvent& e : m.events()) out.patches += e.kind == PatchEventKind::Promoted;
  const auto rep = m.report();
  out.ledger_error_pct = rep["ledger"]["total"]["error_pct"].get<double>();

  // the crater in the heightfield
  const double bin = d.spacing, sp2 = double(d.spacing) * d.spacing;
  const int nbins = std::max(1, int(std::floor((c - bin) / bin)));
  std::vector<double> sum(nbins, 0.0);
  std::vector<int> count(nbins, 0);
  // f(r, dh) for every heightfield sample: its distance from the drop axis (m) and its
  // height change since the start (m)
  auto each_sample = [&](auto&& f) {
    for (int j = 0; j < terrain->samples_z(); ++j)
      for (int i = 0; i < terrain->samples_x(); ++i)
        f(std::hypot(i * double(d.spacing) - c, j * double(d.spacing) - c),
          double(terrain->height(i, j)) - original.height(i, j));
  };
  double centre = 0;
  int nc = 0;
  each_sample([&](double r, double dh) {
    if (r <= 0.5 * R) centre += dh, ++nc;
    const int kb = int(r / bin);
    if (kb < nbins) sum[kb] += dh, ++count[kb];
  });
  out.depth = nc ? std::max(0.0, -centre / nc) : 0;
  out.dh.assign(nbins, -1e300);
  for (int kb = 0; kb < nbins; ++kb)
    if (count[kb]) out.dh[kb] = sum[kb] / count[kb];
  // The crater: bins from the axis whose mean Δh is below −(granule radius as the world sees it):
  // the whole patch settles by about a centimetre when the impact shakes it (the manager's
  // ledger), so "below the original surface" alone would run to the terrain's edge.
  const double eps = double(d.granule_radius) * k.particle_scale;
  int kb = 0;
  while (kb < nbins && out.dh[kb] < -1e299) ++kb;
  for (; kb < nbins && out.dh[kb] < -eps && out.dh[kb] > -1e299; ++kb) out.crater_radius = (kb + 1) * bin;
  for (; kb < nbins && (out.dh[kb] > 0 || out.dh[kb] < -1e299); ++kb) {
    if (out.dh[kb] < -1e299) continue;
    out.rim_volume += sum[kb] * sp2;
    out.rim_height = std::max(out.rim_height, out.dh[kb]);
  }
  // volume below the original surface within the crater's radius; far field: mean Δh of the
  // samples beyond 2 R from the axis (inside the terrain's inscribed circle)
  double far = 0;
  int nf = 0;
  each_sample([&](double r, double dh) {
    if (r < out.crater_radius) out.crater_volume += -dh * sp2;
    if (r >= 2 * R && r < nbins * bin) far += dh, ++nf;
  });
  out.far_field_dh = nf ? far / nf : 0;
  return out;
}

}  // namespace sandpatch
