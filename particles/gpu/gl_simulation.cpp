// Granule DEM on the GPU (GL compute shaders): GlSimulation's methods and the substep that
// sequences the stages (gl_simulation.hpp, docs/dem-gpu.md). The backend's state and its other
// files are listed in gl_impl.hpp; the kernels are shaders/dem/*.comp.
#include "particles/gpu/gl_simulation.hpp"

#include <chrono>
#include <GL/glcorearb.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>

#include "common/hash.hpp"
#include "particles/dem_control.hpp"
#include "particles/gpu/gl_impl.hpp"

namespace sandpatch::gpu {

// One substep: its whole command sequence, recorded here only. The caller (step) bound the
// storage buffers (bind_all) and the indirect-dispatch buffer (bind_substep_targets), set the
// frame's uniforms (u_dt, u_first_law, u_pred: the same for every substep of a frame) and ran
// grid_decide.comp, which wrote the grid kernels' arguments from the re-sort flag. Per
// substep: 8 dispatches (6 of them indirect; 9 with a body of more than kWideSpheres spheres),
// 8 program switches (9), 8 barriers and 2 storage-buffer bindings; no copy, no uniform.
void GlSimulation::Impl::substep() {
  // The grid kernels read their arguments from args_buf (A.grid_dispatch), which the kernels
  // write; the barrier before (the body stage's of the last substep, or grid_decide's) has
  // GL_COMMAND_BARRIER_BIT.
  // the counting sort (0 workgroups each when no re-sort is needed); a storage barrier after
  // each: every stage reads what the one before wrote, the contact stage the cells and order
  for (int k = kGridCount; k <= kGridCopyBack; ++k) dispatch_indirect(Kernel(k));
  // contacts; storage barrier: the body stage reads the spheres' forces
  dispatch(kForce, np_gpu, wg, GL_SHADER_STORAGE_BARRIER_BIT);
  cur_s = 1 - cur_s;  // the springs written become the ones read next substep
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindSIn, buf[kS0 + cur_s]);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindSOut, buf[kS0 + 1 - cur_s]);
  // bodies; storage barrier: the next substep's kernels read the spheres and the re-sort flag;
  // command barrier: its indirect dispatches read the arguments request_resort wrote
  // (the shells: a workgroup each, on other bodies and spheres than kBodies: one barrier after both)
  dispatch_groups(kBodiesWide, int(wide.size()));
  dispatch(kBodies, nb_gpu, wg, GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT);
}

void GlSimulation::Impl::resolve_queries() {
  for (std::size_t i = 0; i < query_kernel.size(); ++i) {
    GLuint64 ns = 0;
    glGetQueryObjectui64v(queries[i], GL_QUERY_RESULT, &ns);
    kernel_seconds[query_kernel[i]] += 1e-9 * double(ns);
  }
  query_kernel.clear();
}

// ---------------------------------------------------------------------------------------
GlSimulation::GlSimulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
GlSimulation::GlSimulation(GlSimulation&&) noexcept = default;
GlSimulation& GlSimulation::operator=(GlSimulation&&) noexcept = default;
GlSimulation::~GlSimulation() = default;

namespace {
Status validate_common(const SimulationDef& d, const GlOptions& o) {
  std::vector<Error> es;
  auto bad = [&](const std::string& f, double v, const std::string& allowed) {
    es.push_back(Error{"", f, format_number(v), allowed, ""});
  };
  if (d.max_bodies < 1 || d.max_bodies > (1 << 28)) bad("SimulationDef.max_bodies", d.max_bodies, "must be in [1, 2^28]");
  if (d.max_particles < 1 || d.max_particles > (1 << 28))
    bad("SimulationDef.max_particles", d.max_particles, "must be in [1, 2^28]");
  if (o.max_contacts_per_sphere < 1 || o.max_contacts_per_sphere > 64)
    bad("GlOptions.max_contacts_per_sphere", o.max_contacts_per_sphere, "must be in [1, 64]");
  if (o.workgroup_size < 1 || o.workgroup_size > 1024 || (o.workgroup_size & (o.workgroup_size - 1)))
    bad("GlOptions.workgroup_size", o.workgroup_size, "must be a power of two in [1, 1024]");
  if (d.sleep_regions)
    es.push_back(Error{"", "SimulationDef.sleep_regions", "true", "is a CPU backend feature: must be false on the GL backend",
                       "the GL backend steps every granule of an awake simulation"});
  if (!es.empty()) return es;
  return Ok{};
}

// The CPU backend's guard for `d`: a capacity-1 Simulation (validates d with the CPU's
// own errors).
Result<Simulation> make_guard(const SimulationDef& d) {
  SimulationDef gd = d;
  gd.max_bodies = 1;
  gd.max_particles = 1;
  gd.threads = 1;
  return Simulation::create(gd);
}

int grid_cells(const SimulationDef& d, float r_max) {
  const float skin = d.cell_skin > 0 ? d.cell_skin : 0.2f * d.particle_radius;
  const float h = 2.0f * r_max + skin;
  Vec3 ext = d.bounds_max - d.bounds_min;
  return std::max(1, int(std::ceil(ext.x / h))) * std::max(1, int(std::ceil(ext.y / h))) *
         std::max(1, int(std::ceil(ext.z / h)));
}
}  // namespace

// Takes a (validated) definition that fits the allocated capacities; empties the simulation.
Status GlSimulation::Impl::configure(const SimulationDef& d, const char* cap_prefix) {
  if (auto st = validate_common(d, opt); !st) return st;
  auto g = make_guard(d);
  if (!g) return g.errors();
  const std::string pre = cap_prefix;
  if (d.max_bodies > cap_b)
    return Error{"", "SimulationDef.max_bodies", format_number(d.max_bodies), "exceeds the capacity " + format_number(cap_b) + ": raise " + pre + "max_bodies", ""};
  if (d.max_particles > cap_p)
    return Error{"", "SimulationDef.max_particles", format_number(d.max_particles),
                 "exceeds the capacity " + format_number(cap_p) + ": raise " + pre + "max_particles", ""};
  if (grid_cells(d, d.particle_radius) > cap_cells)
    return Error{"", "SimulationDef.bounds_max", format_number(grid_cells(d, d.particle_radius)) + " grid cells",
                 "exceeds the capacity of " + format_number(cap_cells) + " cells: enlarge " + pre + "bounds or shrink the patch", ""};
  if (d.terrain.heights.size() > cap_terrain)
    return Error{"", "SimulationDef.terrain.heights", format_number(double(d.terrain.heights.size())) + " samples",
                 "exceeds the capacity of " + format_number(double(cap_terrain)) + " samples: raise " + pre + "terrain", ""};
  def = d;
  guard = std::make_unique<Simulation>(std::move(*g));
  guard_point_mass = std::numeric_limits<double>::infinity();
  shape = make_granule_shape(d.particle_radius, d.granule_edge_factor, d.material.density);
  gravity = d.scale.gravity_to_sim(d.gravity_world);
  zeta = float(damping_ratio_from_restitution(d.material.restitution));
  r_max = d.particle_radius;
  skin = d.cell_skin > 0 ? d.cell_skin : 0.2f * d.particle_radius;
  size_grid();
  // empty: live counts, staging, springs and wall contacts of every particle id
  np = nb = np_gpu = nb_gpu = 0;
  wide.clear();
  pst.clear();
  bst.clear();
  host_flags.clear();
  host_count.clear();
  host_group.clear();
  set_pairs.clear();
  set_planes.clear();
  if (buf[kS0] != 0) {
    std::vector<std::uint32_t> zero(std::size_t(cap_p), 0u);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kS0, 0, zero.size() * 4, zero.data());
    write(kS1, 0, zero.size() * 4, zero.data());
    write(kW, 0, zero.size() * 4, zero.data());
  }
  time = 0;
  asleep = false;
  below_time = 0;
  has_moving_kinematic = false;
  last_vmax = 0;
  stats = StepStats{};
  if (prog[0].id() != 0) {
    set_static_uniforms();
    set_counts();
  }
  if (buf[kSort] != 0) upload_terrain();
  return Ok{};
}

Result<GlSimulation> GlSimulation::create(const SimulationDef& d, const GlOptions& o) {
  if (auto st = validate_common(d, o); !st) return st.errors();
  auto im = std::make_unique<Impl>();
  Impl& s = *im;
  s.opt = o;
  s.cap_p = d.max_particles;
  s.cap_b = d.max_bodies;
  s.cap_cells = grid_cells(d, d.particle_radius);  // larger shells only make cells bigger, so fewer
  s.scan_blocks_cap = (s.cap_cells + kScanBlock - 1) / kScanBlock;
  s.K = o.max_contacts_per_sphere;
  s.wg = o.workgroup_size;
  s.cap_terrain = d.terrain.heights.size();
  if (auto st = s.configure(d, "SimulationDef."); !st) return st.errors();

  // buffer sizes, checked against the driver's largest storage block
  const std::size_t P = std::size_t(s.cap_p);
  s.buf_bytes[Impl::kP0] = s.buf_bytes[Impl::kP1] = std430_size(kParticleFields, P);
  s.buf_bytes[Impl::kB] = std430_size(kBodyFields, std::size_t(s.cap_b));
  s.buf_bytes[Impl::kG] = s.g_wide_body() + 4 * std::size_t(s.cap_b);
  // springs (common.glsl SpringsIn/Out): counts, K slots of (xi, partner id), K dmax
  s.buf_bytes[Impl::kS0] = s.buf_bytes[Impl::kS1] = round_up(4 * P, 16) + 20 * P * std::size_t(s.K);
  s.buf_bytes[Impl::kW] = round_up(4 * P, 16) + 16 * P * kWallSlots;
  s.buf_bytes[Impl::kSort] = s.sort_terrain_offset() + 4 * std::max<std::size_t>(s.cap_terrain, 1);
  GLint64 max_block = 0;
  glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block);
  if (max_block <= 0) return Error{"", "GlSimulation", "no GL context", "a current OpenGL 4.3+ context is needed", ""};
  GLint max_blocks = 0;
  glGetIntegerv(GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS, &max_blocks);
  if (max_blocks < kStorageBlocks)
    return Error{"", "GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS", std::to_string(max_blocks),
                 "must be at least " + std::to_string(kStorageBlocks) + " (the DEM kernels' storage blocks)",
                 "use the CPU backend on this driver"};
  const char* what[Impl::kBufCount] = {"particles (SimulationDef.max_particles)", "particles (SimulationDef.max_particles)",
                                       "bodies (SimulationDef.max_bodies)", "grid cells (SimulationDef.bounds_max / particle_radius)",
                                       "springs (SimulationDef.max_particles x GlOptions.max_contacts_per_sphere)",
                                       "springs (SimulationDef.max_particles x GlOptions.max_contacts_per_sphere)",
                                       "wall springs (SimulationDef.max_particles)", "sort (SimulationDef.max_particles)"};
  for (int b = 0; b < Impl::kBufCount; ++b)
    if (s.buf_bytes[b] > std::size_t(max_block))
      return Error{"", what[b], format_number(double(s.buf_bytes[b])) + " bytes",
                   "must fit the driver's GL_MAX_SHADER_STORAGE_BLOCK_SIZE = " + format_number(double(max_block)) + " bytes",
                   "lower the capacity named"};

  if (auto st = s.build_programs(); !st) return st.errors();

  // buffers, zeroed (spring counts, wall masks and cell counts start at 0)
  glGenBuffers(Impl::kBufCount, s.buf);
  for (int b = 0; b < Impl::kBufCount; ++b) {
    std::vector<unsigned char> zero(s.buf_bytes[b], 0);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, s.buf[b]);
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(s.buf_bytes[b]), zero.data(), GL_DYNAMIC_COPY);
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  glGenBuffers(1, &s.args_buf);
  glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, s.args_buf);
  glBufferData(GL_DISPATCH_INDIRECT_BUFFER, GLsizeiptr(12 * physics::kGridKernels), nullptr, GL_DYNAMIC_COPY);
  glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, 0);
  s.set_static_uniforms();
  s.set_counts();
  s.upload_terrain();
  return GlSimulation(std::move(im));
}

Status GlSimulation::reset(const SimulationDef& def, const char* capacity_prefix) {
  return impl_->configure(def, capacity_prefix);
}

Result<BodyId> GlSimulation::add_granule(Vec3 x, Quat q, Vec3 v, Vec3 w) { return push_granule(*impl_, x, q, v, w); }

Result<BodyId> GlSimulation::add_shell(const ShellDef& sh) {
  Impl& s = *impl_;
  auto plan = plan_shell(sh, s.nb, s.def.max_bodies, s.np, s.def.max_particles);
  if (!plan) return plan.errors();
  const float arm = plan->arm;
  if (sh.motion == MotionType::Dynamic) {
    // the guard: keep the lightest point mass in the capacity-1 CPU simulation
    const float imin = std::min({sh.inertia.x, sh.inertia.y, sh.inertia.z});
    const double pm = point_effective_mass(sh.mass, imin, arm);
    if (pm < s.guard_point_mass) {
      auto g = make_guard(s.def);
      if (!g) return g.errors();
      ShellDef one_point;
      one_point.offsets = {Vec3{arm, 0, 0}};
      one_point.radii = {s.def.particle_radius};
      one_point.motion = MotionType::Dynamic;
      one_point.mass = sh.mass;
      one_point.inertia = {imin, imin, imin};
      if (auto b = g->add_shell(one_point); !b) return b.errors();
      s.guard = std::make_unique<Simulation>(std::move(*g));
      s.guard_point_mass = pm;
    }
  }
  if (plan->max_radius > s.r_max) {  // bigger cells: fewer of them, the buffers still fit
    s.r_max = plan->max_radius;
    s.size_grid();
    s.set_static_uniforms();
  }
  const int i = push_shell(s, sh, *plan);
  s.bst.group[std::size_t(i - s.nb_gpu)] = sh.group;
  s.host_group[std::size_t(i)] = sh.group;
  if (sh.motion == MotionType::Kinematic) s.has_moving_kinematic = true;
  return BodyId{i};
}

Status GlSimulation::set_kinematic_velocity(BodyId id, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  s.flush();
  std::uint32_t fl = 0;
  if (id.index >= 0 && id.index < s.nb) s.read(Impl::kB, s.boff(kBody_flags) + std::size_t(id.index) * 4, 4, &fl);
  if (id.index < 0 || id.index >= s.nb || !(fl & kBodyKinematic))
    return Error{"", "set_kinematic_velocity.body", std::to_string(id.index), "must be a kinematic shell", ""};
  const float vv[3] = {v.x, v.y, v.z}, ww[3] = {w.x, w.y, w.z};
  glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  s.write(Impl::kB, s.boff(kBody_vel) + std::size_t(id.index) * 16, 12, vv);
  s.write(Impl::kB, s.boff(kBody_omega) + std::size_t(id.index) * 16, 12, ww);
  return Ok{};  // as the CPU: an asleep simulation wakes when the shell comes into contact
}

// ---- control from the terrain manager (as dem.cpp) ----

Status GlSimulation::set_body_state(BodyId id, Vec3 x, Quat q, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (Status st = check_body_index(id.index, s.nb, "set_body_state"); !st) return st;
  if (s.body_flags(id.index) & kBodyParked)
    return Error{"", "set_body_state.body", std::to_string(id.index), "is disabled; enable it first", ""};
  const Quat qn = normalized(q);
  const float xx[3] = {x.x, x.y, x.z}, qq[4] = {qn.x, qn.y, qn.z, qn.w}, vv[3] = {v.x, v.y, v.z}, ww[3] = {w.x, w.y, w.z};
  s.set_body_vec(kBody_pos, id.index, xx, 3);
  s.set_body_vec(kBody_quat, id.index, qq, 4);
  s.set_body_vec(kBody_vel, id.index, vv, 3);
  s.set_body_vec(kBody_omega, id.index, ww, 3);
  s.rebuild_body(id.index);
  wake();
  return Ok{};
}

Status GlSimulation::set_body_enabled(BodyId id, bool enabled) {
  Impl& s = *impl_;
  if (Status st = check_body_index(id.index, s.nb, "set_body_enabled"); !st) return st;
  std::uint32_t f = s.body_flags(id.index);
  const bool parked = f & kBodyParked;
  if (enabled == !parked) return Ok{};
  if (!enabled) {
    f = parked_flags(f);  // dem_control.hpp, as the CPU backend
    const Vec3 pk = parking_position(s.def);
    const float far[3] = {pk.x, pk.y, pk.z};
    const float zero[3] = {0, 0, 0};
    s.set_body_vec(kBody_pos, id.index, far, 3);
    s.set_body_vec(kBody_vel, id.index, zero, 3);
    s.set_body_vec(kBody_omega, id.index, zero, 3);
    if (id.index < s.nb_gpu) {
      // its boundary contacts end here (enabled again elsewhere, a plane it touches is a new
      // contact): its spheres' plane masks (common.glsl Walls) cleared
      std::size_t first = 0;
      for (int b = 0; b < id.index; ++b) first += std::size_t(s.host_count[std::size_t(b)]);
      const std::vector<std::uint32_t> none(std::size_t(s.host_count[std::size_t(id.index)]), 0u);
      glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
      s.write(Impl::kW, 4 * first, 4 * none.size(), none.data());
    }
  } else {
    f = unparked_flags(f);
  }
  s.host_flags[std::size_t(id.index)] = f;
  if (id.index >= s.nb_gpu) {
    s.bst.flags[std::size_t(id.index - s.nb_gpu)] = f;
  } else {
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    s.write(Impl::kB, s.boff(kBody_flags) + std::size_t(id.index) * 4, 4, &f);
  }
  if (!enabled) s.rebuild_body(id.index);  // its spheres leave with it (and stop moving)
  wake();
  return Ok{};
}

Status GlSimulation::set_body_group(BodyId id, std::int32_t group) {
  Impl& s = *impl_;
  const bool in = id.index >= 0 && id.index < s.nb;
  if (Status st = check_body_group(id.index, s.nb, in ? s.body_flags(id.index) : 0u, group); !st) return st;  // dem_control.hpp, as the CPU
  std::int32_t& g = s.host_group[std::size_t(id.index)];
  if (g == group) return Ok{};
  g = group;
  if (id.index >= s.nb_gpu) {
    s.bst.group[std::size_t(id.index - s.nb_gpu)] = group;
  } else {
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    s.write(Impl::kB, s.boff(kBody_group) + std::size_t(id.index) * 4, 4, &group);
  }
  wake();  // (the force kernel searches the grid every substep: nothing to rebuild)
  return Ok{};
}

std::int32_t GlSimulation::body_group(BodyId id) const {
  const Impl& s = *impl_;
  return id.index >= 0 && id.index < s.nb ? s.host_group[std::size_t(id.index)] : 0;
}

Result<int> GlSimulation::substeps_for(double dt_frame) const { return impl_->guard->substeps_for(dt_frame); }
Status GlSimulation::set_steps_per_contact(int n) {
  if (Status st = impl_->guard->set_steps_per_contact(n); !st) return st;
  impl_->def.accuracy_steps_per_contact = n;
  return Ok{};
}
double GlSimulation::contact_time() const { return impl_->guard->contact_time(); }
double GlSimulation::max_substep_dt() const { return impl_->guard->max_substep_dt(); }

Status GlSimulation::step(double dt_frame) {
  Impl& s = *impl_;
  auto ns = substeps_for(dt_frame);
  if (!ns) return ns.errors();
  if (!s.opt.upload_in_step) {
  } else if (s.opt.upload_bytes_per_step > 0) {
    s.upload(s.opt.upload_bytes_per_step);
  } else {
    s.flush();
  }
  if (s.springs_waiting()) s.take_set_springs();  // set_contact_springs: into the history the first substep reads
  s.stats = StepStats{};
  s.stats.substeps = *ns;
  s.stats.substep_dt = dt_frame / *ns;
  if (s.asleep) {
    // as dem.cpp: would a moving kinematic shell touch a dynamic sphere this frame? If not,
    // only the kinematic shells move and time advances; if so, wake and step.
    bool touch = false;
    if (s.has_moving_kinematic && s.np_gpu > 0) {
      s.set_status_word(offsetof(physics::DemStatus, kinematic_touch), 0);
      s.bind_all();
      const GLuint tp = s.prog[kKinematicTouch].id();
      glProgramUniform1f(tp, s.u[kKinematicTouch].dt, float(dt_frame));
      s.dispatch(kKinematicTouch, s.np_gpu, s.wg);
      std::uint32_t flag = 0;
      s.read(Impl::kG, offsetof(physics::DemStatus, kinematic_touch), 4, &flag);
      touch = flag != 0;
      if (!touch) {
        const GLuint bp = s.prog[kBodies].id();
        glProgramUniform1i(bp, s.u[kBodies].mode, 2);
        glProgramUniform1f(bp, s.u[kBodies].dt, float(dt_frame));
        s.dispatch(kBodies, s.nb_gpu, s.wg);
        glProgramUniform1i(bp, s.u[kBodies].mode, 0);
      }
      glUseProgram(0);
    }
    if (asleep_frame(s, dt_frame, touch)) return Ok{};
  }
  if (s.np_gpu == 0) {
    s.time += dt_frame;
    return Ok{};
  }
  // the status block's counters (physics::DemStatus): zeroed for this frame, except the re-sort
  // flag, which carries over
  physics::DemStatus status{};
  glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
  s.write(Impl::kG, 0, offsetof(physics::DemStatus, resort), &status);
  s.write(Impl::kG, offsetof(physics::DemStatus, grid_rebuilds), 4, &status.grid_rebuilds);
  const float dt = float(dt_frame / *ns);
  s.bind_all();
  glProgramUniform1f(s.prog[kForce].id(), s.u[kForce].dt, dt);
  glProgramUniform1i(s.prog[kForce].id(), s.u[kForce].first_law, s.guard->contact_timing_on(dt) ? 1 : 0);
  for (Kernel k : {kBodies, kBodiesWide}) {
    glProgramUniform1f(s.prog[k].id(), s.u[k].dt, dt);
    glProgramUniform1f(s.prog[k].id(), s.u[k].pred, float(s.guard->velocity_predictor_gain(dt)));
  }
  // the grid kernels' arguments from the re-sort flag (which an upload or a moved body may have
  // raised); storage barrier: the grid kernels write the same words after it; command barrier:
  // the first substep's indirect dispatches read them
  s.dispatch(kGridDecide, 1, 1, GL_SHADER_STORAGE_BARRIER_BIT | GL_COMMAND_BARRIER_BIT);
  s.bind_substep_targets();
  const auto t_submit = std::chrono::steady_clock::now();
  for (int k = 0; k < *ns; ++k) {
    if (k + 1 == *ns) {  // the counters describe the last substep, as on the CPU
      constexpr std::size_t first = offsetof(physics::DemStatus, max_partners);
      s.write(Impl::kG, first, offsetof(physics::DemStatus, resort) - first, &status.max_partners);
      s.write(Impl::kG, offsetof(physics::DemStatus, max_granule_speed), 4, &status.max_granule_speed);
    }
    s.substep();
    s.time += dt;
  }
  glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, 0);
  glUseProgram(0);
  // the renderers draw the particle block as vertex arrays (TerrainManager::gpu_particles):
  // they see the frame's positions
  glMemoryBarrier(GL_VERTEX_ATTRIB_ARRAY_BARRIER_BIT);
  const auto t_read = std::chrono::steady_clock::now();
  s.read(Impl::kG, 0, sizeof(physics::DemStatus), &status);
  s.stats.submit_seconds = std::chrono::duration<double>(t_read - t_submit).count();
  s.stats.readback_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_read).count();
  if (s.opt.profile) s.resolve_queries();
  float vmax;
  std::memcpy(&vmax, &status.max_granule_speed, 4);
  s.last_vmax = vmax;
  s.stats.contacts = status.contacts;
  s.stats.wall_contacts = status.plane_contacts;
  s.stats.resorts = int(status.grid_rebuilds);
  if (status.nonfinite_bodies > 0)
    return Error{"", "step", "NaN", std::to_string(status.nonfinite_bodies) + " bodies became non-finite in the integrate stage",
                 "reduce the frame dt or material.normal_stiffness, or check the inputs"};
  // (the slots hold the springs and which contacts are not new: force.comp)
  if (int(status.max_partners) > s.K)
    return Error{"", "GlOptions.max_contacts_per_sphere", std::to_string(s.K),
                 "is full: a sphere touched " + std::to_string(status.max_partners) + " partners at once; raise max_contacts_per_sphere",
                 "the springs beyond the capacity restarted from zero this frame, and those contacts were "
                 "treated as new (first-substep dashpot)"};
  update_sleep(s.def, vmax, dt_frame, s.below_time, s.asleep);  // dem_control.hpp, as the CPU backend
  return Ok{};
}

bool GlSimulation::asleep() const { return impl_->asleep; }
void GlSimulation::wake() { wake_up(*impl_); }
int GlSimulation::body_count() const { return impl_->nb; }
int GlSimulation::particle_count() const { return impl_->np; }
int GlSimulation::body_particle_count(BodyId b) const {
  return b.index >= 0 && b.index < impl_->nb ? impl_->host_count[std::size_t(b.index)] : 0;
}
Vec3 GlSimulation::body_position(BodyId b) const { return impl_->body_vec(kBody_pos, b); }
Quat GlSimulation::body_orientation(BodyId b) const {
  float v[4] = {0, 0, 0, 1};
  if (b.index >= 0 && b.index < impl_->nb) {
    impl_->flush();  // orientation of a staged body: upload it
    impl_->read(Impl::kB, impl_->boff(kBody_quat) + std::size_t(b.index) * 16, 16, v);
  }
  return {v[0], v[1], v[2], v[3]};
}
Vec3 GlSimulation::body_velocity(BodyId b) const { return impl_->body_vec(kBody_vel, b); }
Vec3 GlSimulation::body_angular_velocity(BodyId b) const { return impl_->body_vec(kBody_omega, b); }
Vec3 GlSimulation::body_force(BodyId b) const { return impl_->body_vec(kBody_force, b); }
Vec3 GlSimulation::body_torque(BodyId b) const { return impl_->body_vec(kBody_torque, b); }
std::vector<Vec3> GlSimulation::particle_positions() const { return impl_->by_id(kParticle_pos); }
std::vector<Vec3> GlSimulation::particle_forces() const { return impl_->by_id(kParticle_force); }

double GlSimulation::max_granule_speed() const {
  Impl& s = *impl_;
  s.flush();
  std::vector<float> v(std::size_t(s.nb) * 4), w(std::size_t(s.nb) * 4);
  std::vector<std::uint32_t> fl(s.nb);
  s.read(Impl::kB, s.boff(kBody_vel), v.size() * 4, v.data());
  s.read(Impl::kB, s.boff(kBody_omega), w.size() * 4, w.data());
  s.read(Impl::kB, s.boff(kBody_flags), fl.size() * 4, fl.data());
  double m = 0;
  const double reach = s.shape.centre_distance + s.shape.radius;
  for (int i = 0; i < s.nb; ++i) {
    if (!(fl[i] & kBodyGranule)) continue;
    const float* a = &v[4 * std::size_t(i)];
    const float* b = &w[4 * std::size_t(i)];
    double sp = length(Vec3{a[0], a[1], a[2]}) + length(Vec3{b[0], b[1], b[2]}) * reach;
    m = std::max(m, sp);
  }
  return m;
}

const StepStats& GlSimulation::last_step() const { return impl_->stats; }

std::uint64_t GlSimulation::state_hash() const {
  Impl& s = *impl_;
  s.flush();
  Hasher h;
  h.pod(s.nb);
  h.pod(s.np);
#define SP_HASH_B(type, name, n, hashed, backend, unit)                                         \
  SANDPATCH_FIELD_ON(GL, backend, if (hashed) {                                                  \
    std::vector<type> a(std::size_t(s.nb) * (n));                                               \
    s.read(Impl::kB, s.boff(kBody_##name), a.size() * sizeof(type), a.data());                  \
    h.bytes(a.data(), a.size() * sizeof(type));                                                 \
  })
  SANDPATCH_BODY_FIELDS(SP_HASH_B)
#undef SP_HASH_B
  std::vector<std::int32_t> slot(s.np);
  s.read(Impl::kSort, s.s_slot_of(), slot.size() * 4, slot.data());
#define SP_HASH_P(type, name, n, hashed, backend, unit)                                         \
  SANDPATCH_FIELD_ON(GL, backend, if (hashed) {                                                  \
    std::vector<type> a(std::size_t(s.np) * (n)), b(a.size());                                  \
    s.read(s.pcur(), s.poff(kParticle_##name), a.size() * sizeof(type), a.data());              \
    for (int id = 0; id < s.np; ++id)                                                           \
      for (int c = 0; c < (n); ++c) b[std::size_t(id) * (n) + c] = a[std::size_t(slot[id]) * (n) + c]; \
    h.bytes(b.data(), b.size() * sizeof(type));                                                 \
  })
  SANDPATCH_PARTICLE_FIELDS(SP_HASH_P)
#undef SP_HASH_P
  // The contact history (fields.hpp: the GL keeps it by particle id in buffers of its own
  // layout, common.glsl): each sphere's plane mask and 6 plane springs, then its pair springs
  // (count, and the slots in use: xi bits and partner id) as the next substep reads them. With
  // the hysteretic normal spring the planes' dmax (the w of their springs) and the pairs' dmax
  // are hashed too (they decide the next force); with the linear spring they stay 0 and the
  // pairs' are left out, so the linear law's hashes are those it had before dmax existed.
  {
    const std::size_t n = std::size_t(s.np), head = round_up(4 * std::size_t(s.cap_p), 16);
    std::vector<std::uint32_t> mask(n), wxi(n * 4 * kWallSlots), count(n), slots(n * 4 * std::size_t(s.K));
    s.read(Impl::kW, 0, mask.size() * 4, mask.data());
    s.read(Impl::kW, head, wxi.size() * 4, wxi.data());
    h.bytes(mask.data(), mask.size() * 4);
    h.bytes(wxi.data(), wxi.size() * 4);
    const Impl::Buf springs = Impl::Buf(Impl::kS0 + s.cur_s);
    s.read(springs, 0, count.size() * 4, count.data());
    s.read(springs, head, slots.size() * 4, slots.data());
    for (std::size_t id = 0; id < n; ++id) {
      h.pod(count[id]);
      h.bytes(&slots[id * 4 * std::size_t(s.K)], 16 * std::size_t(count[id]));
    }
    if (s.def.material.unloading_stiffness_ratio > 1.0f) {
      std::vector<float> dm(n * std::size_t(s.K));
      s.read(springs, head + 16 * std::size_t(s.cap_p) * std::size_t(s.K), dm.size() * 4, dm.data());
      for (std::size_t id = 0; id < n; ++id) h.bytes(&dm[id * std::size_t(s.K)], 4 * std::size_t(count[id]));
    }
  }
  return h.value();
}

const SimulationDef& GlSimulation::def() const { return impl_->def; }
const GranuleShape& GlSimulation::granule_shape() const { return impl_->shape; }
double GlSimulation::time() const { return impl_->time; }

unsigned GlSimulation::particle_buffer() const { return impl_->buf[Impl::kP0 + impl_->cur_p]; }
std::size_t GlSimulation::particle_id_offset() const { return impl_->poff(kParticle_id); }

std::vector<unsigned> GlSimulation::gl_buffers() const {
  std::vector<unsigned> out(std::begin(impl_->buf), std::end(impl_->buf));
  for (GLuint b : {impl_->args_buf, impl_->staging})
    if (b != 0) out.push_back(b);
  return out;
}
std::vector<unsigned> GlSimulation::gl_programs() const {
  std::vector<unsigned> out;
  for (const auto& p : impl_->prog) out.push_back(p.id());
  return out;
}
std::size_t GlSimulation::pending_upload_bytes() const { return impl_->pending_bytes(); }
std::size_t GlSimulation::upload(std::size_t max_bytes, bool at_least_one) {
  return impl_->upload(max_bytes, at_least_one);
}
int GlSimulation::uploaded_body_count() const { return impl_->nb_gpu; }

std::vector<std::pair<std::string, double>> GlSimulation::kernel_seconds() const {
  std::vector<std::pair<std::string, double>> out;
  for (int k = 0; k < kKernelCount; ++k)
    out.emplace_back(std::string(kKernelFile[k]) + (kKernelDefine[k] ? std::string(" ") + kKernelDefine[k] : ""),
                     impl_->kernel_seconds[k]);
  return out;
}

std::size_t GlSimulation::gpu_bytes() const {
  std::size_t n = 0;
  for (std::size_t b : impl_->buf_bytes) n += b;
  return n;
}

}  // namespace sandpatch::gpu
