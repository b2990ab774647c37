// Granule DEM, CPU/OpenMP reference backend: Simulation's methods and the substep that runs
// the stages (dem.hpp). The backend's state and its other files are listed in dem_impl.hpp;
// the contact law, terrain and boundary planes are shaders/dem/physics_common.glsl
// (dem_physics.hpp), shared with the GL backend; the material formulas are material.hpp.
#include "particles/dem.hpp"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <cmath>
#include <limits>
#include <string>

#include "common/hash.hpp"
#include "particles/contact_simd.hpp"
#include "particles/dem_control.hpp"
#include "particles/dem_impl.hpp"
#include "particles/fields.hpp"

namespace sandpatch {

// A granule's sphere moved skin/2 since the sort (d2_granule, m^2): the grid and both lists;
// a shell's sphere moved shell_trip since the shell list's build (d2_shell): that list.
void Simulation::Impl::note_moved(float d2_granule, float d2_shell) {
  if (4.0f * d2_granule > skin * skin) need_sort = true;
  if (d2_shell > shell_trip * shell_trip) need_shell_list = true;
}

void Simulation::Impl::refresh_lists() {
  if (need_sort) {
    sort();  // (rebuilds the shell list too)
    if (def.sleep_regions) refresh_sphere_dozing();
  } else if (need_shell_list) {
    build_shell_list();
    stats.shell_lists++;
  }
}

// The substep's stages, each timed into stats (StepStats::*_seconds).
Status Simulation::Impl::substep(float dt) {
  using Clock = std::chrono::steady_clock;
  auto since = [](Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); };
  pred_gain = float(predictor_gain(dt));
  first_law = timing_on(dt);
  auto t0 = Clock::now();
  if (need_sort || need_shell_list) {
    refresh_lists();
    stats.sort_seconds += since(t0);
    t0 = Clock::now();
  }
  contacts(dt);
  stats.pair_seconds += since(t0);
  t0 = Clock::now();
  float d2max = 0, d2shell = 0;
  const bool finite = bodies(dt, &d2max, &d2shell);
  stats.body_seconds += since(t0);
  if (!finite)
    return Error{"", "step", "NaN", "a body state became non-finite in the integrate stage",
                 "reduce the frame dt or material.normal_stiffness, or check the inputs"};
  note_moved(d2max, d2shell);
  if (shell_list_each_substep) need_shell_list = true;
  if (need_sort || need_shell_list) {
    t0 = Clock::now();
    refresh_lists();
    stats.sort_seconds += since(t0);
  }
  time += dt;
  return Ok{};
}

// ---------------------------------------------------------------------------------------
Simulation::Simulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;
Simulation::~Simulation() = default;

Result<Simulation> Simulation::create(const SimulationDef& d) { return make(d, nullptr); }

Result<Simulation> Simulation::make(const SimulationDef& d, Impl* reuse) {
  std::vector<Error> es;
  auto bad = [&](const std::string& f, double v, const char* allowed) {
    es.push_back(Error{"", "SimulationDef." + f, format_number(v), allowed, ""});
  };
  if (d.max_bodies < 1 || d.max_bodies > (1 << 28)) bad("max_bodies", d.max_bodies, "must be in [1, 2^28]");
  if (d.max_particles < 1 || d.max_particles > (1 << 28))
    bad("max_particles", d.max_particles, "must be in [1, 2^28]");
  if (!(d.particle_radius > 0) || !std::isfinite(d.particle_radius))
    bad("particle_radius", d.particle_radius, "must be a finite number > 0 (m)");
  if (!(d.granule_edge_factor >= 0.5f && d.granule_edge_factor <= 1.0f))
    bad("granule_edge_factor", d.granule_edge_factor, "must be in [0.5, 1] (edge = 2 r s)");
  if (auto st = validate(d.material, "SimulationDef.material"); !st)
    for (auto& e : st.errors()) es.push_back(e);
  const char* axes[3] = {"x", "y", "z"};
  float lo[3] = {d.bounds_min.x, d.bounds_min.y, d.bounds_min.z};
  float hi[3] = {d.bounds_max.x, d.bounds_max.y, d.bounds_max.z};
  for (int a = 0; a < 3; ++a)
    if (!(hi[a] > lo[a]) || !std::isfinite(lo[a]) || !std::isfinite(hi[a]))
      bad(std::string("bounds_max.") + axes[a], hi[a], "must be finite and > bounds_min");
  // Float positions resolve |x| 2^-23 (m): keep that below 1e-3 r, i.e. |x| <= 8389 r (42 m at
  // r = 5 mm). Farther patches keep their simulation near 0 and put the offset in
  // scale.origin (a double).
  if (es.empty()) {
    const double far = 8388.608 * double(d.particle_radius);
    for (int a = 0; a < 3; ++a)
      for (int m = 0; m < 2; ++m) {
        const double v = m == 0 ? lo[a] : hi[a];
        if (std::abs(v) > far) {
          es.push_back(Error{"", std::string(m == 0 ? "SimulationDef.bounds_min." : "SimulationDef.bounds_max.") + axes[a],
                             format_number(v) + " m",
                             "must be within 8389 particle_radius = " + format_number(far) +
                                 " m of the simulation origin (float positions resolve |x| 2^-23 m, 1e-3 r there)",
                             "simulate patch-relative near 0 and put the patch offset in SimulationDef.scale origin "
                             "(ParticleScale::create(scale, origin), double)"});
          a = 3;
          break;
        }
      }
  }
  if (!std::isfinite(d.floor_height)) bad("floor_height", d.floor_height, "must be finite (m)");
  if (!std::isfinite(d.gravity_world.x + d.gravity_world.y + d.gravity_world.z))
    bad("gravity_world", 0, "must be finite (m/s^2)");
  if (!(d.cell_skin >= 0) || !std::isfinite(d.cell_skin)) bad("cell_skin", d.cell_skin, "must be >= 0 (m)");
  if (d.accuracy_steps_per_contact < 2)
    bad("accuracy_steps_per_contact", d.accuracy_steps_per_contact, "must be >= 2 (20 or more for accuracy)");
  if (d.max_substeps < 1) bad("max_substeps", d.max_substeps, "must be >= 1");
  if (!(d.max_overlap_fraction >= 0) || !std::isfinite(d.max_overlap_fraction))
    bad("max_overlap_fraction", d.max_overlap_fraction, "must be a finite number >= 0 (0 = guard off)");
  if (!(d.sleep_speed >= 0)) bad("sleep_speed", d.sleep_speed, "must be >= 0 (m/s)");
  if (!(d.sleep_time >= 0)) bad("sleep_time", d.sleep_time, "must be >= 0 (s)");
  if (!(d.region_sleep_time >= 0) || !std::isfinite(d.region_sleep_time))
    bad("region_sleep_time", d.region_sleep_time, "must be >= 0 (s; 0: sleep_time)");
  if (d.threads < 0) bad("threads", d.threads, "must be >= 0 (0 = OpenMP default)");
  if (!d.terrain.empty()) {
    const TerrainGrid& t = d.terrain;
    if (t.nx < 2 || t.nz < 2 || std::size_t(t.nx) * std::size_t(t.nz) != t.heights.size())
      bad("terrain.heights", double(t.heights.size()), "must hold nx * nz >= 4 samples (nx, nz >= 2)");
    if (!(t.spacing > 0)) bad("terrain.spacing", t.spacing, "must be > 0 (m)");
  }
  if (!es.empty()) return es;

  auto im = std::make_unique<Impl>();
  Impl& s = *im;
  // The particles and bodies the reused simulation held: only those entries of its
  // capacity-sized arrays were written (a life's ids only grow), so only those are set back.
  int used_p = 0, used_b = 0;
  if (reuse) {
    // The capacity-sized arrays keep their memory, and the simulation is the one create()
    // makes: the entries the last life wrote are set back to create()'s values below. (A
    // fresh allocation of the pool's capacity, tens of MB, page-faulted at every promotion: 5
    // of a 6 ms promotion in the default scene; writing the whole capacity again, 16 MB for a
    // slot of 65,536 granules, still took 3.9 ms of each promotion of scenes/vehicle_drive.json.)
    Impl& o = *reuse;
    used_p = o.np;
    used_b = o.nb;
    s.b = std::move(o.b);
    s.p = std::move(o.p);
    s.slot_of = std::move(o.slot_of);
    s.cell = std::move(o.cell);
    s.pos_at_sort = std::move(o.pos_at_sort);
    s.acc = std::move(o.acc);
    s.guard_pt_mass = std::move(o.guard_pt_mass);
    s.guard_arm = std::move(o.guard_arm);
    s.guard_rmin = std::move(o.guard_rmin);
    s.cell_start = std::move(o.cell_start);
    if (d.sleep_regions && o.def.sleep_regions) {
      s.still_for = std::move(o.still_for);
      s.anchor = std::move(o.anchor);
      s.dozing = std::move(o.dozing);
      s.sphere_dozing = std::move(o.sphere_dozing);
    }
  }
  s.def = d;
  s.shape = make_granule_shape(d.particle_radius, d.granule_edge_factor, d.material.density);
  for (int k = 0; k < 4; ++k) {
    s.shape_offsets[4 * k] = s.shape.offsets[k].x;
    s.shape_offsets[4 * k + 1] = s.shape.offsets[k].y;
    s.shape_offsets[4 * k + 2] = s.shape.offsets[k].z;
  }
  s.gravity = d.scale.gravity_to_sim(d.gravity_world);
  s.threads = d.threads > 0 ? d.threads : omp_get_max_threads();
  s.simd_pairs = simd::use_avx2_pair_kernel();
  if (const char* e = std::getenv("SANDPATCH_DEM_SHELL_LIST")) s.shell_list_each_substep = std::strcmp(e, "each") == 0;
  s.zeta = damping_ratio_from_restitution(d.material.restitution);
  s.r_max = d.particle_radius;
  s.skin = d.cell_skin > 0 ? d.cell_skin : 0.2f * d.particle_radius;
  s.shell_skin = Impl::kShellSkinFactor * s.skin;
  s.shell_trip = std::min(0.5f * s.shell_skin, s.shell_skin - s.skin);
  {
    float h = 2.0f * s.r_max + s.skin;
    Vec3 ext = d.bounds_max - d.bounds_min;
    double cells = std::ceil(ext.x / h) * std::ceil(ext.y / h) * std::ceil(ext.z / h);
    if (cells > double(1 << 26))
      return Error{"", "SimulationDef.bounds_max", format_number(cells) + " grid cells",
                   "the grid (cell = 2 particle_radius + cell_skin) must have <= 2^26 cells",
                   "shrink the bounds or raise particle_radius"};
  }
  const std::size_t mp = std::size_t(d.max_particles), mb = std::size_t(d.max_bodies);
  const std::size_t up = std::size_t(used_p), ub = std::size_t(used_b);
  s.b.resize(mb, ub);
  s.p.resize(mp, up);
  refill(s.slot_of, mp, std::int32_t(-1), up);
  if (!reuse) s.cell.assign(mp, 0);  // (reused: the sort sizes it to the spheres it holds)
  refill(s.pos_at_sort, 4 * mp, 0.0f, 4 * up);
  refill(s.acc, mp, Impl::SphereSums{}, up);
  refill(s.guard_pt_mass, mb, 0.0f, ub);
  refill(s.guard_arm, mb, 0.0f, ub);
  refill(s.guard_rmin, mb, 0.0f, ub);
  s.still_drift = Impl::kStillDrift * d.particle_radius;
  if (d.sleep_regions) {
    refill(s.still_for, mb, 0.0f, ub);
    refill(s.anchor, 4 * mb, 0.0f, 4 * ub);
    refill(s.dozing, mb, std::uint8_t(0), ub);
    refill(s.sphere_dozing, mp, std::uint8_t(0), up);
  }
  s.size_grid();
  // OpenMP's worker threads are made on the first parallel region with this many threads:
  // here, at the process's first creation with that many, not in the first frame that steps a
  // patch large enough to run its stages in parallel (measured: that frame took 16.5 ms in the
  // default scene, against 2 ms). Once per process: the workers stay (a region per creation
  // made the scene fuzzer, which creates a world per input, ten times slower).
  static std::atomic<int> warmed{1};
  if (int w = warmed.load(); s.threads > w && warmed.compare_exchange_strong(w, s.threads)) {
#pragma omp parallel num_threads(s.threads)
    { (void)omp_get_thread_num(); }
  }
  return Simulation(std::move(im));
}

Result<BodyId> Simulation::add_granule(Vec3 x, Quat q, Vec3 v, Vec3 w) { return push_granule(*impl_, x, q, v, w); }

Result<ShellPlan> plan_shell(const ShellDef& sh, int bodies_used, int max_bodies, int particles_used,
                             int max_particles) {
  ShellPlan p;
  p.count = int(sh.offsets.size());
  const int count = p.count;
  if (count < 1) return Error{"", "ShellDef.offsets", "0 spheres", "must hold at least one sphere", ""};
  if (sh.group < 0)
    return Error{"", "ShellDef.group", std::to_string(sh.group), "must be >= 0 (0: no collision group)", ""};
  p.one_radius = sh.radii.size() == 1;
  if (!p.one_radius && int(sh.radii.size()) != count)
    return Error{"", "ShellDef.radii", format_number(double(sh.radii.size())) + " radii",
                 "must hold one radius, or one per offset (" + std::to_string(count) + ")", ""};
  if (bodies_used + 1 > max_bodies)
    return Error{"", "SimulationDef.max_bodies", format_number(max_bodies), "is full: raise max_bodies",
                 "add_shell needs 1 more body"};
  if (particles_used + count > max_particles)
    return Error{"", "SimulationDef.max_particles", format_number(max_particles), "is full: raise max_particles",
                 "add_shell needs " + std::to_string(count) + " more particles"};
  for (int k = 0; k < count; ++k) {
    const float r = p.one_radius ? sh.radii[0] : sh.radii[k];
    if (!(r > 0) || !std::isfinite(r))
      return Error{"", "ShellDef.radii[" + std::to_string(p.one_radius ? 0 : k) + "]", format_number(r),
                   "must be > 0 (m)", ""};
    if (!std::isfinite(sh.offsets[k].x + sh.offsets[k].y + sh.offsets[k].z))
      return Error{"", "ShellDef.offsets[" + std::to_string(k) + "]", "non-finite", "must be finite (m)", ""};
    p.max_radius = std::max(p.max_radius, r);
    p.arm = std::max(p.arm, length(sh.offsets[k]));
  }
  if (sh.motion == MotionType::Dynamic) {
    if (!(sh.mass > 0) || !std::isfinite(sh.mass))
      return Error{"", "ShellDef.mass", format_number(sh.mass), "must be > 0 (kg)", ""};
    if (!(sh.inertia.x > 0 && sh.inertia.y > 0 && sh.inertia.z > 0))
      return Error{"", "ShellDef.inertia", format_number(std::min({sh.inertia.x, sh.inertia.y, sh.inertia.z})),
                   "principal moments must be > 0 (kg m^2)", ""};
    p.flags = kBodyDynamic;
    p.inv_mass = 1.0f / sh.mass;
    p.inv_inertia = {1.0f / sh.inertia.x, 1.0f / sh.inertia.y, 1.0f / sh.inertia.z};
  } else {
    p.flags = sh.motion == MotionType::Static ? kBodyStatic : kBodyKinematic;
  }
  return p;
}

Result<BodyId> Simulation::add_shell(const ShellDef& sh) {
  Impl& s = *impl_;
  auto plan = plan_shell(sh, s.nb, s.def.max_bodies, s.np, s.def.max_particles);
  if (!plan) return plan.errors();
  const int count = plan->count;
  // overlap guard: the body's weight shared by all its spheres (the most favourable case)
  if (sh.motion == MotionType::Dynamic && s.def.max_overlap_fraction > 0) {
    float rmin = std::numeric_limits<float>::infinity();
    for (int k = 0; k < count; ++k) rmin = std::min(rmin, plan->one_radius ? sh.radii[0] : sh.radii[k]);
    const double r = std::min(double(rmin), double(s.def.particle_radius));
    const double g = length(s.gravity), kn = s.def.material.normal_stiffness, f = s.def.max_overlap_fraction;
    const double overlap = double(sh.mass) * g / (count * kn);
    if (overlap > f * r)
      return Error{"", "ShellDef.mass", format_number(sh.mass) + " kg",
                   "must be <= " + format_number(f * r * count * kn / g) + " kg: its weight on its " +
                       std::to_string(count) + " spheres overlaps each contact by >= m |g| / (n k_n) = " +
                       format_number(overlap) + " m > max_overlap_fraction x r = " + format_number(f * r) +
                       " m, so it would sink through the bed and the floor",
                   "raise SimulationDef.material.normal_stiffness to >= " + format_number(kn * overlap / (f * r)) +
                       " N/m, give the shell more spheres, or lower its mass"};
  }
  // a new dynamic body may shorten the contact time (the guard uses the lightest body)
  if (sh.motion == MotionType::Dynamic) {
    double imin = std::min({sh.inertia.x, sh.inertia.y, sh.inertia.z});
    s.min_point_mass = std::min(s.min_point_mass, point_effective_mass(sh.mass, imin, plan->arm));
  }
  if (plan->max_radius > s.r_max) {  // bigger spheres: bigger (fewer) grid cells
    s.r_max = plan->max_radius;
    s.size_grid();
  }
  const int i = push_shell(s, sh, *plan);
  s.b.group[i] = sh.group;
  return BodyId{i};
}

Status Simulation::set_kinematic_velocity(BodyId id, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (id.index < 0 || id.index >= s.nb || !(s.b.flags[id.index] & kBodyKinematic))
    return Error{"", "set_kinematic_velocity.body", std::to_string(id.index), "must be a kinematic shell", ""};
  st3(s.b.vel, id.index, v);
  st3(s.b.omega, id.index, w);
  return Ok{};
}

Result<int> Simulation::substeps_for(double dt_frame) const {
  const Impl& s = *impl_;
  if (!(dt_frame > 0) || !std::isfinite(dt_frame))
    return Error{"", "step.dt_frame", format_number(dt_frame), "must be a finite number > 0 (s)", ""};
  double mdt = s.max_dt();
  double n = std::ceil(dt_frame / mdt * (1.0 - 1e-9));
  if (n < 1) n = 1;
  if (n > s.def.max_substeps)
    return Error{"", "step.dt_frame", format_number(dt_frame),
                 "needs " + format_number(n) + " substeps of <= " + format_number(mdt) + " s (t_c = " + format_number(s.contact_time_()) +
                     " s / " + std::to_string(s.def.accuracy_steps_per_contact) + ") but max_substeps = " +
                     std::to_string(s.def.max_substeps),
                 "lower dt_frame, raise SimulationDef.max_substeps, or lower material.normal_stiffness"};
  return int(n);
}

Status Simulation::step(double dt_frame) {
  Impl& s = *impl_;
  auto ns = substeps_for(dt_frame);
  if (!ns) return ns.errors();
  const auto t_guard = std::chrono::steady_clock::now();
  if (!s.asleep)
    if (auto st = s.check_impacts(); !st) return st;
  s.stats = StepStats{};
  s.stats.guard_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_guard).count();
  // (lists built ahead of the step, build_lists_now)
  s.stats.resorts = s.early_lists.resorts, s.stats.shell_lists = s.early_lists.shell_lists;
  s.stats.sort_seconds = s.early_lists.sort_seconds;
  s.early_lists = {};
  s.stats.substeps = *ns;
  s.stats.substep_dt = dt_frame / *ns;
  if (s.asleep) {
    const bool touched = s.kinematic_touch(dt_frame);
    if (!touched) s.move_kinematic(dt_frame);
    if (asleep_frame(s, dt_frame, touched)) return Ok{};
  }
  s.update_regions(dt_frame);  // dem_regions.cpp (sleep_regions)
  s.stats.sleeping_granules = s.dozing_granules;
  const float dt = float(dt_frame / *ns);
  for (int k = 0; k < *ns; ++k)
    if (auto st = s.substep(dt); !st) return st;
  update_sleep(s.def, s.granule_vmax, dt_frame, s.below_time, s.asleep);  // dem_control.hpp
  return Ok{};
}

void Simulation::build_lists_now() {
  Impl& s = *impl_;
  if (s.asleep || !(s.need_sort || s.need_shell_list)) return;
  const StepStats keep = s.stats;  // (the last step's, read until the next)
  const auto t0 = std::chrono::steady_clock::now();
  s.refresh_lists();
  s.early_lists.resorts += s.stats.resorts - keep.resorts;
  s.early_lists.shell_lists += s.stats.shell_lists - keep.shell_lists;
  s.early_lists.sort_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  s.stats = keep;
}

double Simulation::contact_time() const { return impl_->contact_time_(); }
double Simulation::max_impact_speed(double m_pt) const { return impl_->max_impact_speed(m_pt); }
double Simulation::max_substep_dt() const { return impl_->max_dt(); }
double Simulation::velocity_predictor_gain(double dt) const { return impl_->predictor_gain(dt); }
bool Simulation::contact_timing_on(double dt) const { return impl_->timing_on(dt); }
bool Simulation::asleep() const { return impl_->asleep; }
void Simulation::wake() { wake_up(*impl_); }
bool Simulation::region_asleep(BodyId b) const {
  const Impl& s = *impl_;
  return s.def.sleep_regions && b.index >= 0 && b.index < s.nb && s.dozing[std::size_t(b.index)] != 0;
}
Simulation::StillTime Simulation::still_time(BodyId b) const {
  const Impl& s = *impl_;
  if (b.index < 0 || b.index >= s.nb) return {};
  const std::size_t i = std::size_t(b.index);
  if (!s.def.sleep_regions || !(s.b.flags[i] & kBodyGranule)) return {0.0f, ld3(s.b.pos, b.index)};
  return {s.still_for[i], Vec3{s.anchor[4 * i], s.anchor[4 * i + 1], s.anchor[4 * i + 2]}};
}
Status Simulation::set_still_time(BodyId id, StillTime still) {
  Impl& s = *impl_;
  if (Status st = check_body_index(id.index, s.nb, "set_still_time"); !st) return st;
  const std::size_t i = std::size_t(id.index);
  if (!(s.b.flags[i] & kBodyGranule))
    return Error{"", "set_still_time.body", std::to_string(id.index), "must be a granule", ""};
  if (!(std::isfinite(still.seconds) && still.seconds >= 0.0f))
    return Error{"", "set_still_time.seconds", format_number(still.seconds), "must be finite and >= 0", ""};
  if (!std::isfinite(still.anchor.x + still.anchor.y + still.anchor.z))
    return Error{"", "set_still_time.anchor", "non-finite", "must be finite", ""};
  if (!s.def.sleep_regions) return Ok{};
  s.still_for[i] = still.seconds;
  s.anchor[4 * i] = still.anchor.x, s.anchor[4 * i + 1] = still.anchor.y, s.anchor[4 * i + 2] = still.anchor.z;
  return Ok{};
}
int Simulation::body_count() const { return impl_->nb; }
int Simulation::particle_count() const { return impl_->np; }
int Simulation::body_particle_count(BodyId b) const {
  return b.index >= 0 && b.index < impl_->nb ? impl_->b.count[b.index] : 0;
}
Vec3 Simulation::body_position(BodyId b) const { return ld3(impl_->b.pos, b.index); }
Quat Simulation::body_orientation(BodyId b) const { return ldq(impl_->b.quat, b.index); }
Vec3 Simulation::body_velocity(BodyId b) const { return ld3(impl_->b.vel, b.index); }
Vec3 Simulation::body_angular_velocity(BodyId b) const { return ld3(impl_->b.omega, b.index); }
Vec3 Simulation::body_force(BodyId b) const { return ld3(impl_->b.force, b.index); }
Vec3 Simulation::body_torque(BodyId b) const { return ld3(impl_->b.torque, b.index); }
const StepStats& Simulation::last_step() const { return impl_->stats; }
void Simulation::set_energy_ledger(bool on) {
  if (on && !impl_->ledger) impl_->ledger_normal = impl_->ledger_friction = 0;
  impl_->ledger = on;
}
double Simulation::dissipated_normal() const { return impl_->ledger_normal; }
double Simulation::dissipated_friction() const { return impl_->ledger_friction; }
double Simulation::normal_spring_energy() const { return impl_->ledger_spring_pairs + impl_->ledger_spring_walls; }
double Simulation::tangential_spring_energy() const {
  const Impl& s = *impl_;
  const double kt = double(s.def.material.normal_stiffness) * s.def.material.tangential_stiffness_ratio;
  double e = 0;
  // the list's entries (nstart has the spheres of its last build: a body added since is not in it)
  const std::size_t entries = s.nstart.empty() ? 0 : std::size_t(s.nstart.back());
  for (std::size_t k = 0; k < entries; ++k) {
    const float* x = &s.pairs.xi[3 * k];
    e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
  }
  for (std::size_t k = 0; k < s.snbr.size(); ++k) {  // the shell list's
    const float* x = &s.spairs.xi[3 * k];
    e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
  }
  for (int i = 0; i < s.np; ++i)
    for (int k = 0; k < kWallSlots; ++k) {
      if (!(s.p.wall_mask[i] & (1u << k))) continue;
      const float* x = &s.p.wall_xi[(std::size_t(i) * kWallSlots + k) * 3];
      e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
    }
  return e;
}
Status Simulation::set_threads(int threads) {
  if (threads < 0)
    return Error{"", "Simulation::set_threads.threads", std::to_string(threads), "must be >= 0 (0 = OpenMP's default)", ""};
  impl_->threads = threads > 0 ? threads : omp_get_max_threads();
  return Ok{};
}
Status Simulation::set_steps_per_contact(int n) {
  if (n < 2)
    return Error{"", "SimulationDef.accuracy_steps_per_contact", std::to_string(n), "must be >= 2 (20 or more for accuracy)", ""};
  impl_->def.accuracy_steps_per_contact = n;
  return Ok{};
}
const SimulationDef& Simulation::def() const { return impl_->def; }
const GranuleShape& Simulation::granule_shape() const { return impl_->shape; }
double Simulation::time() const { return impl_->time; }
double Simulation::max_granule_speed() const { return impl_->max_granule_speed(); }

std::vector<Vec3> Simulation::particle_positions() const {
  const Impl& s = *impl_;
  std::vector<Vec3> out(s.np);
  for (int id = 0; id < s.np; ++id) out[id] = ld3(s.p.pos, s.slot_of[id]);
  return out;
}

double Simulation::kinetic_energy() const {
  const Impl& s = *impl_;
  double e = 0;
  for (int i = 0; i < s.nb; ++i) {
    if (!(s.b.flags[i] & kBodyDynamic)) continue;
    Vec3 v = ld3(s.b.vel, i);
    e += 0.5 * s.b.mass[4 * i] * double(dot(v, v));
    Vec3 wb = rotate_inv(ldq(s.b.quat, i), ld3(s.b.omega, i));
    Vec3 iI = ld3(s.b.inv_inertia, i);
    e += 0.5 * (double(wb.x) * wb.x / iI.x + double(wb.y) * wb.y / iI.y + double(wb.z) * wb.z / iI.z);
  }
  return e;
}

double Simulation::potential_energy() const {
  const Impl& s = *impl_;
  double e = 0;
  for (int i = 0; i < s.nb; ++i)  // gravity, dynamic bodies
    if (s.b.flags[i] & kBodyDynamic) e -= double(s.b.mass[4 * i]) * double(dot(s.gravity, ld3(s.b.pos, i)));
  // elastic: normal springs at the current positions, tangential springs from the history
  const Material& m = s.def.material;
  const float kn = m.normal_stiffness, kt = m.normal_stiffness * m.tangential_stiffness_ratio;
  auto granule = [&](int sphere) { return bool(s.b.flags[s.p.body[sphere]] & kBodyGranule); };
  for (int i = 0; i < s.np; ++i) {
    Vec3 pi = ld3(s.p.pos, i);
    float ri = s.p.pos[4 * i + 3];
    bool dyn_i = s.p.vel[4 * i + 3] > 0;
    const bool granule_i = granule(i);
    int c = s.cell_of(pi);
    int cx = c % s.gx, cy = (c / s.gx) % s.gy, cz = c / (s.gx * s.gy);
    for (int zz = std::max(0, cz - 1); zz <= std::min(s.gz - 1, cz + 1); ++zz)
      for (int yy = std::max(0, cy - 1); yy <= std::min(s.gy - 1, cy + 1); ++yy)
        for (int xx = std::max(0, cx - 1); xx <= std::min(s.gx - 1, cx + 1); ++xx) {
          int cc = (zz * s.gy + yy) * s.gx + xx;
          for (int j = s.cell_start[cc]; j < s.cell_start[cc + 1]; ++j) {
            if (s.p.body[j] == s.p.body[i]) continue;
            if (!granule_i || !granule(j)) continue;  // a shell's pairs: from the shell list below
            if (!dyn_i && s.p.vel[4 * j + 3] == 0) continue;
            float d = length(pi - ld3(s.p.pos, j));
            float del = ri + s.p.pos[4 * j + 3] - d;
            if (del > 0) e += 0.25 * kn * double(del) * del;  // half of the pair, counted twice
          }
        }
    if (dyn_i) {
      auto plane = [&](float dist) {
        if (dist < ri) e += 0.5 * kn * double(ri - dist) * (ri - dist);
      };
      plane(pi.y - s.def.floor_height);
      if (s.def.side_walls) {
        plane(pi.x - s.def.bounds_min.x);
        plane(s.def.bounds_max.x - pi.x);
        plane(pi.z - s.def.bounds_min.z);
        plane(s.def.bounds_max.z - pi.z);
      }
    }
    if (i < int(s.nstart.size()) - 1) {
      for (int k = s.nstart[i]; k < s.nstart[i + 1]; ++k) {  // one entry per pair
        const float* x = &s.pairs.xi[3 * std::size_t(k)];
        e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
      }
      for (int k = 0; k < kWallSlots; ++k) {
        if (!(s.p.wall_mask[i] & (1u << k))) continue;
        const float* x = &s.p.wall_xi[(std::size_t(i) * kWallSlots + k) * 3];
        e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
      }
    }
  }
  // the shells' pairs (their cells are those of the last sort, the shell list's are current)
  for (int r = 0, rows = int(s.srow.size()); r < rows; ++r) {
    const int i = s.srow[std::size_t(r)];
    for (int k = s.sstart[std::size_t(r)]; k < s.sstart[std::size_t(r) + 1]; ++k) {
      const int j = s.snbr[std::size_t(k)];
      const float del = s.p.pos[4 * i + 3] + s.p.pos[4 * j + 3] - length(ld3(s.p.pos, i) - ld3(s.p.pos, j));
      if (del > 0) e += 0.5 * kn * double(del) * del;
      const float* x = &s.spairs.xi[3 * std::size_t(k)];
      e += 0.5 * kt * (double(x[0]) * x[0] + double(x[1]) * x[1] + double(x[2]) * x[2]);
    }
  }
  return e;
}

std::uint64_t Simulation::state_hash() const {
  const Impl& s = *impl_;
  Hasher h;
  h.pod(s.nb);
  h.pod(s.np);
#define SP_HASH_B(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.b.name.data(), sizeof(type) * std::size_t(n) * s.nb);)
  SANDPATCH_BODY_FIELDS(SP_HASH_B)
#undef SP_HASH_B
#define SP_HASH_P(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.p.name.data(), sizeof(type) * std::size_t(n) * s.np);)
  SANDPATCH_PARTICLE_FIELDS(SP_HASH_P)
  SANDPATCH_SPHERE_CONTACT_FIELDS(SP_HASH_P)
#undef SP_HASH_P
  // the pairs' contact history, in list order (the list is the same for any thread count)
  const std::size_t entries = s.nstart.empty() ? 0 : std::size_t(s.nstart.back());  // the last build's spheres
#define SP_HASH_C(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.pairs.name.data(), sizeof(type) * std::size_t(n) * entries);)
  SANDPATCH_PAIR_CONTACT_FIELDS(SP_HASH_C)
#undef SP_HASH_C
  // the shell list's, in its order
  const std::size_t shell_entries = s.snbr.size();
#define SP_HASH_S(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(CPU, backend, if (hashed) h.bytes(s.spairs.name.data(), sizeof(type) * std::size_t(n) * shell_entries);)
  SANDPATCH_PAIR_CONTACT_FIELDS(SP_HASH_S)
#undef SP_HASH_S
  if (s.def.sleep_regions) {  // which granules sleep, and how long each has been still
    h.bytes(s.dozing.data(), std::size_t(s.nb));
    h.bytes(s.still_for.data(), sizeof(float) * std::size_t(s.nb));
    h.bytes(s.anchor.data(), sizeof(float) * 4 * std::size_t(s.nb));
  }
  return h.value();
}

// ---- control from the terrain manager ----

Status Simulation::reset(const SimulationDef& d) {
  const SimulationDef& cur = impl_->def;
  if (d.max_bodies > cur.max_bodies)
    return Error{"", "reset.max_bodies", std::to_string(d.max_bodies),
                 "must not exceed the slot's capacity " + std::to_string(cur.max_bodies), ""};
  if (d.max_particles > cur.max_particles)
    return Error{"", "reset.max_particles", std::to_string(d.max_particles),
                 "must not exceed the slot's capacity " + std::to_string(cur.max_particles), ""};
  auto fresh = make(d, impl_.get());
  if (!fresh) return fresh.errors();
  *this = std::move(*fresh);
  return Ok{};
}

Status Simulation::set_body_state(BodyId id, Vec3 x, Quat q, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (Status st = check_body_index(id.index, s.nb, "set_body_state"); !st) return st;
  if (s.b.flags[id.index] & kBodyParked)
    return Error{"", "set_body_state.body", std::to_string(id.index), "is disabled; enable it first", ""};
  st3(s.b.pos, id.index, x);
  stq(s.b.quat, id.index, normalized(q));
  st3(s.b.vel, id.index, v);
  st3(s.b.omega, id.index, w);
  // Its spheres follow at once. The neighbour list holds every pair within r_i + r_j + skin
  // at the last sort, so it still holds every touching pair while no sphere has moved more
  // than skin/2 since: the list is rebuilt only when one of the body's spheres has (the test
  // the substep makes after the body stage). A shell that follows its Bullet body is set every
  // frame it moves; rebuilding the list each time was 70 of the 664 rebuilds of the default
  // scene's patches over 1.5 s (docs/BENCHMARKS.md, "The DEM inside a scene").
  s.rouse(id.index);  // (a granule set from outside is awake and not still)
  const float d2 = s.rebuild_body(id.index);
  if (s.b.flags[id.index] & kBodyGranule) s.note_moved(d2, 0.0f);
  else s.note_moved(0.0f, d2);  // (a shell's pairs are in the shell list, dem_impl.hpp)
  wake();
  return Ok{};
}

Status Simulation::set_body_enabled(BodyId id, bool enabled) {
  Impl& s = *impl_;
  if (Status st = check_body_index(id.index, s.nb, "set_body_enabled"); !st) return st;
  std::uint32_t& f = s.b.flags[id.index];
  const bool parked = f & kBodyParked;
  if (enabled == !parked) return Ok{};
  s.rouse(id.index);
  if (!enabled) {
    f = parked_flags(f);  // dem_control.hpp, as the GL backend
    st3(s.b.pos, id.index, parking_position(s.def));
    st3(s.b.vel, id.index, Vec3{});
    st3(s.b.omega, id.index, Vec3{});
    // its boundary contacts end here (enabled again elsewhere, a plane it touches is a new contact)
    for (int k = 0; k < s.b.count[id.index]; ++k) s.p.wall_mask[std::size_t(s.slot_of[std::size_t(s.b.first[id.index] + k)])] = 0;
  } else {
    f = unparked_flags(f);
  }
  s.rebuild_body(id.index);
  s.need_sort = true;
  wake();
  return Ok{};
}

Status Simulation::set_body_group(BodyId id, std::int32_t group) {
  Impl& s = *impl_;
  const bool in = id.index >= 0 && id.index < s.nb;
  if (Status st = check_body_group(id.index, s.nb, in ? s.b.flags[id.index] : 0u, group); !st) return st;  // dem_control.hpp
  if (s.b.group[id.index] == group) return Ok{};
  s.b.group[id.index] = group;
  s.need_sort = true;  // the neighbour list holds the pairs that interact
  wake();
  return Ok{};
}

std::int32_t Simulation::body_group(BodyId id) const {
  const Impl& s = *impl_;
  return id.index >= 0 && id.index < s.nb ? s.b.group[id.index] : 0;
}

}  // namespace sandpatch
