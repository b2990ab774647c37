// The terrain manager: see terrain_manager.hpp. This file: creation, the frame's sequence of
// stages (each in its own source, terrain_manager_impl.hpp), the queries and the report.
#include "manager/terrain_manager.hpp"

#include "common/limits.hpp"

#include <algorithm>
#include <cstdlib>
#include <cmath>
#include <numbers>

#include "common/hash.hpp"
#include "manager/terrain_manager_impl.hpp"
#include "manager/tile_cache.hpp"
#include "particles/fields.hpp"
#include "particles/gpu/gl_backend.hpp"

namespace sandpatch {

const char* to_string(PatchEventKind k) {
  switch (k) {
    case PatchEventKind::Requested: return "requested";
    case PatchEventKind::Promoted: return "promoted";
    case PatchEventKind::Ready: return "ready";
    case PatchEventKind::Asleep: return "asleep";
    case PatchEventKind::Woke: return "woke";
    case PatchEventKind::Demoted: return "demoted";
    case PatchEventKind::TooFastToFollow: return "too_fast_to_follow";
    case PatchEventKind::TooFastForGranules: return "too_fast_for_granules";
    case PatchEventKind::SoilDropped: return "soil_dropped";
  }
  return "?";
}

Status TerrainManager::Impl::make_depth_renderer() {
  if (!def.use_gl) return Ok{};
  if (!gl) gl = gl::Context::create_or_explain(gl_note);
  if (!gl) return Ok{};  // demotions render on the CPU; the report says why (depth_render_note)
  // On a software renderer (llvmpipe) the CPU ray cast of the same contract is several times
  // faster than rasterising the spheres, and the CPU backend's particles are on the CPU
  // already: there, only the GL backend renders on GL (docs/manager.md "Demotion").
  if (gl->info().software && def.backend != "gl") {
    gl_note = "depth render on the CPU: the GL context is software (" + gl->info().gl_renderer +
              "), where the CPU ray cast is faster";
    gl.reset();  // nothing else on the CPU backend uses it
    return Ok{};
  }
  if (Status st = gl->make_current(); !st) return st;
  auto dr = ParticleDepthRenderer::create({def.depth_resolution});
  if (dr) depth = std::move(*dr);
  else gl_note = dr.message();
  return Ok{};
}

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
  // The settings both doors share are checked against the same table they are (common/knobs.hpp).
  auto knob = [&](const char* field, double v, const knobs::Knob& k) {
    if (!k.allows(v)) errs.push_back(Error{"", field, format_number(v), "must be in " + knobs::describe_range(k)});
  };
  knob("pool.slots", def.slots, knobs::kSlots);
  knob("steps_per_contact", def.steps_per_contact, knobs::kStepsPerContact);
  knob("max_substeps", def.max_substeps, knobs::kMaxSubsteps);
  knob("pool.granules_per_slot", def.granules_per_slot, knobs::kGranulesPerSlot);
  knob("patch_depth", def.patch_depth, knobs::kPatchDepth);
  if (!(def.frame_budget_ms > 0)) bad("frame_budget_ms", def.frame_budget_ms, "must be > 0 ms (infinity: no budget)");
  if (!(def.budget_substep_ms >= 0 && def.budget_substep_ms < 1e6)) bad("budget_substep_ms", def.budget_substep_ms, "must be in [0, 1e6) ms");
  if (!(def.budget_sphere_ns >= 0 && def.budget_sphere_ns < 1e9)) bad("budget_sphere_ns", def.budget_sphere_ns, "must be in [0, 1e9) ns");
  if (!(def.frame_budget_fraction >= 0 && def.frame_budget_fraction <= 100))
    bad("frame_budget_fraction", def.frame_budget_fraction, "must be in [0, 100] (0: frame_budget_ms applies)");
  // Every slot is allocated at full capacity below: the pool's total is capped (common/limits.hpp).
  if (knobs::kSlots.allows(def.slots) && knobs::kGranulesPerSlot.allows(def.granules_per_slot) &&
      double(def.slots) * def.granules_per_slot > double(limits::kMaxPoolGranules))
    errs.push_back(Error{"", "pool.slots", std::to_string(def.slots) + " × granules_per_slot " + std::to_string(def.granules_per_slot),
                         "slots × granules_per_slot must be at most " + std::to_string(limits::kMaxPoolGranules) +
                             " granules (every slot is allocated at full capacity)",
                         "lower slots or granules_per_slot"});
  if (!(def.surface_probe >= 0 && def.surface_probe <= 4)) bad("surface_probe", def.surface_probe, "must be in [0, 4] sphere radii");
  if (!(def.depth_texels_per_radius >= 0 && def.depth_texels_per_radius <= 1e3))
    bad("depth_texels_per_radius", def.depth_texels_per_radius, "must be in [0, 1000] (0: depth_resolution always)");
  if (def.fill_granules_per_frame < 1) bad("fill_granules_per_frame", def.fill_granules_per_frame, "must be >= 1");
  if (!errs.empty()) return errs;

  std::unique_ptr<TerrainManager> m(new TerrainManager());
  m->impl_ = std::make_unique<Impl>();
  Impl& I = *m->impl_;
  I.def = def;
  I.tile_cache = def.tile_cache == "off" ? std::string() : def.tile_cache.empty() ? tile_cache_dir() : def.tile_cache;
  if (def.tile_cache.empty() && !I.tile_cache.empty()) I.tile_fallback = tile_cache_build_dir();
  I.hf = &hf;
  I.world = &world;
  I.camera = def.camera;
  // The first pre-settled tile of every scale (filling.cpp); with a budget, the coarser scales
  // it may choose (budget.cpp) take their base scale's tiles where they are whole multiples of
  // it, and settle their own otherwise.
  for (double scale : I.scales())
    if (Status st = I.add_tile_set(scale); !st) return st.errors();
  for (double scale : I.all_scales())
    if (std::none_of(I.tile_sets.begin(), I.tile_sets.end(), [&](const TileSet& t) { return t.scale == scale; }))
      if (!I.derive_tile_set(scale))
        if (Status st = I.add_tile_set(scale); !st) return st.errors();
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
  const std::vector<double> all_scales = I.all_scales();
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
      // SANDPATCH_GL_PROFILE: every dispatch timed on the GPU (timer queries read at the end of
      // each step), summed into the report's dem.total.gl_kernel_ms
      gpu::GlOptions opt;
      opt.profile = I.gl_profile = std::getenv("SANDPATCH_GL_PROFILE") != nullptr;
      auto sim = gpu::GlSimulation::create(cap, opt);
      if (!sim) {
        // (the capacities it names come from the pool's fields: say which to lower; other
        // refusals, such as the driver's block count, keep their own advice)
        std::vector<Error> es = sim.errors();
        for (Error& e : es)
          if (e.field.find("SimulationDef") != std::string::npos)
            e.detail += (e.detail.empty() ? "" : "; ") + std::string("a slot holds simulation.pool.granules_per_slot = ") +
                      std::to_string(def.granules_per_slot) + " granules (4 spheres each) and shell_spheres_per_slot = " +
                      std::to_string(def.shell_particles_per_slot) + ": lower them, or use the CPU backend";
        return es;
      }
      I.slots.emplace_back(gpu::make_gl_backend(std::move(*sim)));
    } else {
      auto sim = Simulation::create(cap);
      if (!sim) return sim.errors();
      I.slots.emplace_back(make_cpu_backend(std::move(*sim)));
    }
  }
  I.records.resize(I.slots.size());
  // The fills' spheres (the demotion's render baseline) at full capacity too, so the pool's
  // memory is fixed from start-up whichever frame a fill is cut in (pool_bytes).
  for (PatchRecord& r : I.records) r.fill_spheres.reserve(std::size_t(16) * std::size_t(def.granules_per_slot));
  // The demotion's depth render on GL, decided now (without a context it renders on the CPU).
  if (Status st = I.make_depth_renderer(); !st) return st.errors();
  I.current();  // (the GL backend's slots run in its context)
  if (Status st = I.warm_slots(); !st) return st.errors();
  // With a budget, the DEM's rate on this machine before any patch has run.
  if (I.budget_on()) {
    I.current();
    if (Status st = I.calibrate(); !st) return st.errors();
  }
  return m;
}

TerrainManager::~TerrainManager() {
  if (impl_ && impl_->gl) (void)impl_->gl->make_current();  // GL slots and the depth renderer free their objects in it
}

Status TerrainManager::before_bodies(double time, double dt, Profile& profile) {
  Impl& I = *impl_;
  I.current();
  I.now = time;
  I.soil.clear();
  I.work = {};
  for (auto it = I.set_down_until.begin(); it != I.set_down_until.end();)
    it = it->second <= time ? I.set_down_until.erase(it) : std::next(it);
  {
    auto timer = profile.time(Stage::Lod);
    if (Status st = I.plan(time); !st) return st;
  }
  {
    auto timer = profile.time(Stage::Activation);
    const Status st = I.activate(time, dt);
    I.peak_queue = std::max(I.peak_queue, int(I.queue.size()));  // requests left waiting in a frame
    if (!st) return st;
  }
  {
    auto timer = profile.time(Stage::Dem);
    if (Status st = I.step_patches(time, dt); !st) return st;
  }
  return Ok{};
}

Status TerrainManager::prepare(double time, double dt, Profile& profile) {
  Impl& I = *impl_;
  I.current();
  I.now = time;
  // Each round: a request planned now and promoted; a patch a body engages (activate's
  // finish_due) is finished in the same round. At most one round a slot.
  for (std::size_t round = 0; round < I.slots.size(); ++round) {
    I.work = {};
    {
      auto timer = profile.time(Stage::Lod);
      if (Status st = I.plan(time); !st) return st;
    }
    auto timer = profile.time(Stage::Activation);
    if (Status st = I.activate(time, dt); !st) return st;
    if (I.work.urgent_fills == 0) break;
  }
  {
    auto timer = profile.time(Stage::Demotion);  // (the fills' renders, ahead of their demotions)
    if (Status st = I.render_baselines(time, /*whole=*/true); !st) return st;
  }
  I.work = {};
  return Ok{};
}

Status TerrainManager::after_bodies(double time, double dt, Profile& profile) {
  Impl& I = *impl_;
  I.current();
  {
    auto timer = profile.time(Stage::Sleep);
    I.update_sleep(time, dt);
  }
  {
    auto timer = profile.time(Stage::Demotion);
    if (Status st = I.demote_idle(time + dt); !st) return st;
  }
  return Ok{};
}

bool TerrainManager::soil_force(RigidBodyId body, Eigen::Vector3f* force, Eigen::Vector3f* torque) const {
  const auto it = impl_->soil.find(manager_detail::body_key(body));
  if (it == impl_->soil.end()) return false;
  *force = it->second.force;
  *torque = it->second.torque;
  return true;
}

double TerrainManager::budget_ms(double dt) const { return impl_->budget_ms(dt); }

void TerrainManager::set_planned_path(RigidBodyId body, std::vector<PathPose> path, bool extrapolated) {
  const std::int64_t key = manager_detail::body_key(body);
  const bool has = !path.empty();
  if (!has) impl_->paths.erase(key);
  else impl_->paths[key] = std::move(path);
  if (extrapolated && has) impl_->extrapolated.insert(key);
  else impl_->extrapolated.erase(key);
}

void TerrainManager::add_event(PatchEvent e) { impl_->events.push_back(std::move(e)); }

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
  for (const auto& s : impl_->slots) n += s.ready();
  return n;
}

Status TerrainManager::demote_all(double time, Profile& profile) {
  auto timer = profile.time(Stage::Demotion);
  impl_->current();
  return impl_->demote_every(time);
}

int TerrainManager::active_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.live();
  return n;
}

int TerrainManager::granules() const {
  int n = 0;
  for (const auto& r : impl_->records) n += r.granules;
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
  for (const auto& s : impl_->slots) n += s.state == SlotState::Filling;
  return n;
}

int TerrainManager::asleep_patches() const {
  int n = 0;
  for (const auto& s : impl_->slots) n += s.state == SlotState::Asleep;
  return n;
}

std::int64_t TerrainManager::pool_bytes() const {
  // Bytes per particle / per body: components × 4 bytes summed over the field lists.
#define SANDPATCH_FIELD_BYTES(type, name, n, hashed, backend, unit) +std::int64_t(n) * std::int64_t(sizeof(type))
  constexpr std::int64_t particle_bytes = 0 SANDPATCH_PARTICLE_FIELDS(SANDPATCH_FIELD_BYTES);
  constexpr std::int64_t body_bytes = 0 SANDPATCH_BODY_FIELDS(SANDPATCH_FIELD_BYTES);
#undef SANDPATCH_FIELD_BYTES
  const SimulationDef sd = impl_->sim_def(impl_->def.particle_scale);
  std::int64_t fills = 0;  // the fills' spheres kept for the demotion's render baseline
  for (const auto& r : impl_->records) fills += std::int64_t(r.fill_spheres.capacity() * sizeof(float));
  return std::int64_t(impl_->slots.size()) *
             (std::int64_t(sd.max_particles) * particle_bytes + std::int64_t(sd.max_bodies) * body_bytes) +
         fills;
}

std::uint64_t TerrainManager::state_hash() const {
  Hasher h;
  impl_->current();
  for (const auto& s : impl_->slots) {
    h.pod(int(s.state));
    if (s.state != SlotState::Free) h.pod(s.sim->state_hash());
  }
  return h.value();
}

const std::vector<PatchEvent>& TerrainManager::events() const { return impl_->events; }

const TerrainManager::FrameWork& TerrainManager::last_frame_work() const { return impl_->work; }

std::vector<TerrainManager::PatchInfo> TerrainManager::patches() const {
  std::vector<PatchInfo> out;
  for (const auto& s : impl_->slots) {
    if (s.state == SlotState::Free) continue;
    PatchInfo p;
    p.patch = s.patch;
    p.region = s.region;
    p.apron = s.apron;
    p.origin = s.origin;
    p.particle_scale = s.scale;
    p.granule_radius_world = double(s.sim->def().particle_radius) * p.particle_scale;
    p.steps_per_contact = s.sim->def().accuracy_steps_per_contact;
    p.granules = impl_->record(s).granules;
    p.ready = s.ready();
    p.asleep = s.state == SlotState::Asleep;
    if (const DemCost& c = impl_->record(s).cost; c.patch == s.patch) {
      p.last_substeps = c.last_substeps;
      p.last_spheres = c.last_spheres;
      p.last_rebuilds = c.last_rebuilds;
      p.last_step_ms = c.last_wall_ms;
      p.stepped = c.last_frame == impl_->frame;
    }
    out.push_back(p);
  }
  return out;
}

void TerrainManager::particles(std::vector<float>& xyzr) const {
  xyzr.clear();
  const Impl& I = *impl_;
  I.current();
  for (const auto& s : I.slots)
    if (s.state != SlotState::Free) I.granule_spheres(s, xyzr);
}

void TerrainManager::shell_spheres(std::vector<double>& xyzr) const {
  xyzr.clear();
  const Impl& I = *impl_;
  I.current();
  for (const auto& s : I.slots) {
    if (s.state == SlotState::Free) continue;
    std::vector<Vec3> pos;  // read once a slot, when it carries an enabled shell
    const double rw = I.radius_world(s);
    for (const Carried& c : s.carried) {
      if (!c.enabled) continue;
      if (pos.empty()) pos = s.sim->particle_positions();
      const auto [first, n] = particle_range(*s.sim, c.shell);
      for (std::size_t k = first; k < first + n && k < pos.size(); ++k) {
        const auto w = s.sim->def().scale.position_to_world(pos[k]);
        xyzr.insert(xyzr.end(), {w[0], w[1], w[2], rw});
      }
    }
  }
}

gl::Context* TerrainManager::gl_context() const { return impl_->def.backend == "gl" ? impl_->gl.get() : nullptr; }

std::vector<TerrainManager::GpuParticles> TerrainManager::gpu_particles() const {
  std::vector<GpuParticles> out;
  for (const auto& s : impl_->slots) {
    if (s.state == SlotState::Free || s.sim->gpu_particle_buffer() == 0) continue;
    GpuParticles g;
    g.buffer = s.sim->gpu_particle_buffer();
    g.count = s.sim->particle_count();
    g.id_offset = s.sim->gpu_particle_id_offset();
    g.granule_spheres = std::int64_t(4) * impl_->record(s).granules;
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
    if (s.state == SlotState::Free) continue;
    const float fade = impl_->def.fade_frames > 0 ? float(s.fade) / float(impl_->def.fade_frames) : 1.0f;
    out.emplace_back(std::size_t(4) * std::size_t(impl_->record(s).granules), std::min(1.0f, fade));
  }
  return out;
}

// The DEM's cost (PatchRecord::cost), per patch in patch order and in total: spheres (granules'
// 4 each and the enabled shells'), substeps, sphere-steps and their rate over the wall time of
// the step calls (docs/cli.md, report "dem").
nlohmann::ordered_json TerrainManager::Impl::dem_report() const {
  using ojson = nlohmann::ordered_json;
  std::vector<std::pair<const DemCost*, bool>> all;  // cost, live
  for (const DemCost& c : earlier_costs) all.push_back({&c, false});
  for (std::size_t k = 0; k < records.size(); ++k)
    if (records[k].cost.patch >= 0)
      all.push_back({&records[k].cost, slots[k].live() && slots[k].patch == records[k].cost.patch});
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.first->patch < b.first->patch; });
  ojson patches = ojson::array();
  DemCost t;
  for (const auto& [c, live] : all) {
    patches.push_back({{"patch", c->patch},
                       {"live", live},
                       {"granules", c->granules},
                       {"spheres", c->last_spheres},
                       {"granule_spheres", 4 * c->granules},
                       {"shell_spheres", c->last_spheres - 4 * c->granules},
                       {"frames", c->frames},
                       {"substeps", c->substeps},
                       {"substeps_per_frame", c->frames > 0 ? double(c->substeps) / double(c->frames) : 0.0},
                       {"substep_dt_s", c->substep_dt},
                       {"contacts_per_sphere", c->contacts_per_sphere},
                       {"mean_contacts_per_sphere", c->mean_contacts_per_sphere()},
                       {"sphere_steps", c->sphere_steps},
                       {"wall_ms", c->wall_ms},
                       {"sphere_steps_per_s", c->sphere_steps_per_s()},
                       {"sleeping_fraction", c->sleeping_fraction()},
                       {"awake_sphere_steps_per_s", c->awake_sphere_steps_per_s()},
                       {"mean_list_entries_per_sphere", c->mean_list_entries_per_sphere()},
                       {"grid_rebuilds", c->grid_rebuilds},
                       {"shell_list_rebuilds", c->shell_lists},
                       {"stage_ms", {{"sort", c->sort_ms}, {"pairs", c->pair_ms}, {"bodies", c->body_ms},
                                     {"gl_submit", c->submit_ms}, {"gl_readback", c->readback_ms}}}});
    t.wall_ms += c->wall_ms;
    t.substeps += c->substeps;
    t.sphere_steps += c->sphere_steps;
    t.frames += c->frames;
    t.contact_sphere_steps += c->contact_sphere_steps;
    t.grid_rebuilds += c->grid_rebuilds;
    t.shell_lists += c->shell_lists;
    t.entry_sphere_steps += c->entry_sphere_steps;
    t.sleeping_sphere_steps += c->sleeping_sphere_steps;
    t.sort_ms += c->sort_ms, t.pair_ms += c->pair_ms, t.body_ms += c->body_ms;
    t.submit_ms += c->submit_ms, t.readback_ms += c->readback_ms;
    t.substep_dt = std::max(t.substep_dt, c->substep_dt);
  }
  ojson total = {{"patches", int(all.size())},
                 {"frames", t.frames},
                 {"substeps", t.substeps},
                 {"substeps_per_frame", t.frames > 0 ? double(t.substeps) / double(t.frames) : 0.0},
                 {"max_substep_dt_s", t.substep_dt},
                 {"spheres_per_substep", t.substeps > 0 ? double(t.sphere_steps) / double(t.substeps) : 0.0},
                 {"mean_contacts_per_sphere", t.mean_contacts_per_sphere()},
                 {"sphere_steps", t.sphere_steps},
                 {"wall_ms", t.wall_ms},
                 {"sphere_steps_per_s", t.sphere_steps_per_s()},
                 {"sleeping_fraction", t.sleeping_fraction()},
                 {"awake_sphere_steps_per_s", t.awake_sphere_steps_per_s()},
                 {"mean_list_entries_per_sphere", t.mean_list_entries_per_sphere()},
                 {"grid_rebuilds", t.grid_rebuilds},
                 {"shell_list_rebuilds", t.shell_lists},
                 {"side_by_side_frames", side_by_side_frames},
                 {"stage_ms", {{"sort", t.sort_ms}, {"pairs", t.pair_ms}, {"bodies", t.body_ms},
                               {"gl_submit", t.submit_ms}, {"gl_readback", t.readback_ms}}}};
  // GL backend with SANDPATCH_GL_PROFILE: each kernel's GPU time over the run, all slots
  if (gl_profile) {
    ojson g = ojson::object();
    for (const auto& s : slots)
      for (const auto& [name, sec] : s.sim->kernel_seconds()) g[name] = g.value(name, 0.0) + 1e3 * sec;
    total["gl_kernel_ms"] = g;
  }
  return {{"patches", patches}, {"total", total}};
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
  ojson parts = ojson::object();
  for (std::size_t k = 0; k < I.part_times.size(); ++k) {
    const Impl::PartTime& t = I.part_times[k];
    parts[Impl::kPartNames[k]] = {{"count", t.count}, {"mean_ms", t.count > 0 ? t.total_ms / double(t.count) : 0.0}, {"max_ms", t.max_ms}};
  }
  r["conversion_parts"] = parts;
  int used = 0;
  for (const auto& s : I.slots) used += s.live();
  r["pool"] = {{"slots", int(I.slots.size())},
               {"slots_used", used},
               {"peak_slots_used", I.peak_slots},
               {"granules_per_slot", I.def.granules_per_slot},
               {"steps_per_contact", I.def.steps_per_contact},
               {"shell_particles_per_slot", I.def.shell_particles_per_slot},
               {"queued_requests", int(I.queue.size())},
               {"peak_queued_requests", I.peak_queue},
               {"lapsed_requests", I.lapsed_requests},
               {"extensions", I.extensions},
               {"travels", I.travels},
               {"springs_handed_over", I.springs_handed_over},
               {"urgent_fills", I.urgent_fills},
               {"released", I.released},
               {"released_early", I.early_releases}};
  nlohmann::ordered_json tiles = nlohmann::ordered_json::array();
  for (const TileSet& set : I.tile_sets)
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
  // The frame budget: what it chose for every patch and what it cost (docs/cli.md).
  {
    int degraded = 0;
    for (const auto& e : I.budget_log) degraded += e["rung"].get<int>() > 0;
    ojson b = {{"on", I.budget_on()}};
    if (I.def.frame_budget_fraction > 0) b["frame_budget_fraction"] = I.def.frame_budget_fraction;
    else if (I.budget_on()) b["frame_budget_ms"] = I.def.frame_budget_ms;
    b["cost_model"] = {{"substep_ms", I.cost_a_ms},
                       {"substep_sphere_ns", I.cost_b_ms * 1e6},
                       {"calibrated_substep_ms", I.calibrated_a_ms},
                       {"calibrated_substep_sphere_ns", I.calibrated_b_ms * 1e6},
                       {"load", I.load}};
    b["patches_degraded"] = degraded;
    b["overruns"] = I.budget_overruns;
    b["live_substeps_traded"] = I.budget_live_trades;
    b["lapsed_after_waiting"] = I.budget_log_lapsed;
    b["waited_request_frames"] = I.budget_waits;
    b["held_patch_frames"] = I.budget_held;
    b["held_ahead_patch_frames"] = I.budget_held_ahead;
    b["longest_hold_frames"] = I.budget_longest_hold;
    b["patches"] = I.budget_log;
    r["budget"] = b;
  }
  r["dem"] = I.dem_report();
  // Tools on planned paths (planning.cpp plan_path): what was asked for over their paths.
  if (!I.path_log.empty()) {
    ojson pp = ojson::array();
    for (const auto& [key, l] : I.path_log)
      pp.push_back({{"body", l.name},
                    {"path", l.extrapolated ? "extrapolated" : "keyframes"},
                    {"asked_frames", l.asked_frames},
                    {"too_big_frames", l.too_big_frames},
                    {"last_request_m", {l.last.x0, l.last.z0, l.last.x1, l.last.z1}},
                    {"last_request_s", {l.from, l.to}},
                    {"granules_predicted", l.granules},
                    {"granules_per_slot", I.def.granules_per_slot}});
    r["planned_paths"] = pp;
  }
  // Tools let go of with granules in them (coupling.cpp couple_before).
  if (!I.soil_drops.empty()) {
    ojson sd = ojson::array();
    for (const auto& d : I.soil_drops)
      sd.push_back({{"body", d.name},
                    {"time_s", d.time},
                    {"patch", d.patch},
                    {"height_m", d.height},
                    {"limit_m", Impl::carry_height},
                    {"granules", d.granules},
                    {"volume_m3", d.volume}});
    r["soil_dropped"] = sd;
  }
  // Bodies set on a patch's ground as they arrived on it (coupling.cpp couple_before).
  if (I.lifts > 0) r["arrivals"] = {{"lifted", I.lifts}, {"largest_lift_m", I.lift_max}};
  // Kinematic and static bodies that moved faster into a patch than its granules can stop
  // (coupling.cpp couple_before): their shells may have pushed granules through themselves.
  if (!I.fast_tools.empty()) {
    ojson ft = ojson::array();
    for (const auto& [key, f] : I.fast_tools)
      ft.push_back({{"body", f.name}, {"max_speed_m_s", f.speed}, {"limit_m_s", f.limit}, {"frames", f.frames}});
    r["tools_too_fast"] = ft;
  }
  return r;
}

}  // namespace sandpatch
