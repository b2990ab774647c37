// Granule DEM on the GPU (GL compute shaders); see gl_simulation.hpp and docs/dem-gpu.md.
// The kernels are shaders/dem/*.comp; this file builds their generated preamble (the
// std430 blocks of fields.hpp), owns the buffers, uploads bodies and sequences the stages.
#include "particles/gpu/gl_simulation.hpp"

#include <GL/glcorearb.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <cstring>
#include <limits>

#include "common/hash.hpp"
#include "gl/program.hpp"
#include "particles/dem_control.hpp"
#include "particles/dem_physics.hpp"
#include "particles/fields.hpp"
#include "particles/gpu/layout.hpp"
#include "shaders/shaders.hpp"

namespace sandpatch::gpu {

namespace {

// Buffer bindings (shaders/dem/common.glsl lists the same).
enum Binding : GLuint { kBindP = 0, kBindPn = 1, kBindB = 2, kBindG = 3, kBindSIn = 4, kBindSOut = 5, kBindW = 6, kBindS = 7 };

constexpr int kWallSlots = 6;  // per sphere: floor, walls x0, x1, z0, z1, terrain
constexpr int kScanBlock = 1024;  // cells per workgroup of scan_blocks.comp

// The kernels, in the order of a substep (rebuild is bodies.comp in mode 1). The grid
// kernels kGridCount..kGridCopyBack run by glDispatchComputeIndirect with the arguments
// grid_decide.comp wrote (DemStatus::grid_dispatch[3 (k - kGridCount) ..]).
enum Kernel {
  kGridDecide, kGridCount, kScanBlocks, kScanTop, kScanAdd, kGridScatter, kGridCellSort, kGridGather, kGridCopyBack,
  kForce, kBodies, kKinematicTouch, kKernelCount
};
constexpr const char* kKernelFile[kKernelCount] = {
    "dem/grid_decide.comp",   "dem/grid_count.comp",    "dem/scan_blocks.comp", "dem/scan_top.comp",
    "dem/scan_add.comp",      "dem/grid_scatter.comp",  "dem/grid_cellsort.comp", "dem/grid_gather.comp",
    "dem/grid_copyback.comp", "dem/force.comp",         "dem/bodies.comp",        "dem/kinematic_touch.comp"};

// CPU staging of bodies/particles added since the last upload (generated SoA, as dem.cpp).
struct ParticleStage {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, std::vector<type> name;)
  SANDPATCH_PARTICLE_FIELDS(SP_DECL)
#undef SP_DECL
  void clear() {
#define SP_CLR(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, name.clear();)
    SANDPATCH_PARTICLE_FIELDS(SP_CLR)
#undef SP_CLR
  }
  void push_zero() {
#define SP_PUSH(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, name.resize(name.size() + (n), type{});)
    SANDPATCH_PARTICLE_FIELDS(SP_PUSH)
#undef SP_PUSH
  }
  std::size_t size() const { return id.size(); }
};
struct BodyStage {
#define SP_DECL(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, std::vector<type> name;)
  SANDPATCH_BODY_FIELDS(SP_DECL)
#undef SP_DECL
  void clear() {
#define SP_CLR(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, name.clear();)
    SANDPATCH_BODY_FIELDS(SP_CLR)
#undef SP_CLR
  }
  void push_zero() {
#define SP_PUSH(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, name.resize(name.size() + (n), type{});)
    SANDPATCH_BODY_FIELDS(SP_PUSH)
#undef SP_PUSH
  }
};

void put3(std::vector<float>& a, std::size_t i, Vec3 v, float w = 0.0f) {
  a[4 * i] = v.x;
  a[4 * i + 1] = v.y;
  a[4 * i + 2] = v.z;
  a[4 * i + 3] = w;
}

// Bytes per element summed over a block's fields (one body / one particle).
template <std::size_t N>
constexpr std::size_t sum_strides(const std::array<Std430Field, N>& fields) {
  std::size_t n = 0;
  for (const auto& f : fields) n += f.stride;
  return n;
}

}  // namespace

struct GlSimulation::Impl {
  SimulationDef def;
  GlOptions opt;
  GranuleShape shape;
  Vec3 gravity;
  float zeta = 0;

  // Stability guard: a CPU Simulation of capacity 1 with the same definition, holding (at
  // most) one single-sphere dynamic shell with the lightest point mass of our dynamic
  // shells, so substeps_for / contact_time / max_substep_dt are the CPU backend's own.
  std::unique_ptr<Simulation> guard;
  double guard_point_mass = std::numeric_limits<double>::infinity();

  // capacities and live counts
  int cap_p = 0, cap_b = 0, cap_cells = 0, scan_blocks_cap = 0, K = 16, wg = 64;
  std::size_t cap_terrain = 0;  // terrain height samples (fixed at creation)
  int np = 0, nb = 0, np_gpu = 0, nb_gpu = 0;  // *_gpu: uploaded
  ParticleStage pst;
  BodyStage bst;
  std::vector<std::uint32_t> host_flags;  // every body's flags (only the host changes them): no read-back

  // grid (sized as the CPU's: cell = 2 r_max + skin)
  float r_max = 0, skin = 0, h = 0;
  int gx = 1, gy = 1, gz = 1;

  // GL objects
  enum Buf { kP0, kP1, kB, kG, kS0, kS1, kW, kSort, kBufCount };
  GLuint buf[kBufCount] = {};
  std::size_t buf_bytes[kBufCount] = {};
  gl::Program prog[kKernelCount];
  int cur_p = 0;  // P is buffer kP0 + cur_p, the grid's scratch copy the other (cur_p stays 0:
                  // grid_copyback.comp copies the sorted particles back)
  int cur_s = 0;  // springs read this substep: kS0 + cur_s; written: the other

  // state
  double time = 0;
  bool asleep = false;
  double below_time = 0;
  bool has_moving_kinematic = false;
  float last_vmax = 0;
  StepStats stats;
  double kernel_seconds[kKernelCount] = {};  // GlOptions::profile

  Status configure(const SimulationDef& d, const char* cap_prefix);

  std::size_t poff(int f) const { return std430_offset(kParticleFields, f, std::size_t(cap_p)); }
  std::size_t boff(int f) const { return std430_offset(kBodyFields, f, std::size_t(cap_b)); }
  // Byte offsets inside the other blocks (common.glsl's declarations).
  std::size_t g_cell_start() const { return sizeof(physics::DemStatus); }
  std::size_t s_slot_of() const { return 0; }
  std::size_t sort_terrain_offset() const { return round_up(12 * std::size_t(cap_p), 16) + 16 * std::size_t(cap_p); }

  ~Impl() {
    // a program in use is only flagged for deletion: release ours so the names really go
    GLint current = 0;
    glGetIntegerv(GL_CURRENT_PROGRAM, &current);
    for (const auto& p : prog)
      if (p.id() != 0 && GLuint(current) == p.id()) glUseProgram(0);
    bool any = false;
    for (GLuint b : buf) any = any || b != 0;
    if (any) glDeleteBuffers(kBufCount, buf);
  }

  std::string preamble() const {
    std::string s = "#version 430\n";
    s += "#define SP_PARTICLES " + std::to_string(cap_p) + "\n";
    s += "#define SP_BODIES " + std::to_string(cap_b) + "\n";
    s += "#define SP_CELLS " + std::to_string(cap_cells) + "\n";
    s += "#define SP_SCAN_BLOCKS " + std::to_string(scan_blocks_cap) + "\n";
    s += "#define SP_K " + std::to_string(K) + "\n";
    s += "#define SP_WG " + std::to_string(wg) + "\n";
    s += "#define SP_BODY_GRANULE " + std::to_string(unsigned(kBodyGranule)) + "u\n";
    s += "#define SP_BODY_STATIC " + std::to_string(unsigned(kBodyStatic)) + "u\n";
    s += "#define SP_BODY_KINEMATIC " + std::to_string(unsigned(kBodyKinematic)) + "u\n";
    s += "#define SP_BODY_DYNAMIC " + std::to_string(unsigned(kBodyDynamic)) + "u\n";
    s += "// generated from particles/fields.hpp (particles/gpu/layout.hpp)\n";
    s += glsl_block(kParticleFields, "ParticlesA", "P", kBindP, std::size_t(cap_p));
    s += glsl_block(kParticleFields, "ParticlesB", "Pn", kBindPn, std::size_t(cap_p));
    s += glsl_block(kBodyFields, "Bodies", "B", kBindB, std::size_t(cap_b));
    s += "#define SP_COPY_PARTICLE(to, dst, from, src) " + glsl_copy_all(kParticleFields, "to", "dst", "from", "src") + "\n";
    s += "#line 1 1\n";
    return s;
  }

  void size_grid() {
    h = 2.0f * r_max + skin;
    const float inv_h = 1.0f / h;
    Vec3 ext = def.bounds_max - def.bounds_min;
    gx = std::max(1, int(std::ceil(ext.x * inv_h)));
    gy = std::max(1, int(std::ceil(ext.y * inv_h)));
    gz = std::max(1, int(std::ceil(ext.z * inv_h)));
  }
  int cells() const { return gx * gy * gz; }

  void bind_all() {
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindP, buf[kP0 + cur_p]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindPn, buf[kP0 + 1 - cur_p]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindB, buf[kB]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindG, buf[kG]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindSIn, buf[kS0 + cur_s]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindSOut, buf[kS0 + 1 - cur_s]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindW, buf[kW]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindS, buf[kSort]);
  }

  // Uniforms that change only with the grid or never: set on every program.
  void set_static_uniforms() {
    const Material& m = def.material;
    const float cn0 = float(2.0 * double(zeta) * std::sqrt(double(m.normal_stiffness)));
    for (auto& p : prog) {
      GLuint id = p.id();
      auto loc = [&](const char* n) { return glGetUniformLocation(id, n); };
      glProgramUniform1ui(id, loc("u_cells"), GLuint(cells()));
      glProgramUniform3i(id, loc("u_grid"), gx, gy, gz);
      glProgramUniform3f(id, loc("u_bmin"), def.bounds_min.x, def.bounds_min.y, def.bounds_min.z);
      glProgramUniform3f(id, loc("u_bmax"), def.bounds_max.x, def.bounds_max.y, def.bounds_max.z);
      glProgramUniform1f(id, loc("u_inv_h"), 1.0f / h);
      glProgramUniform1ui(id, loc("u_blocks"), GLuint((cells() + kScanBlock - 1) / kScanBlock));
      glProgramUniform1f(id, loc("u_kn"), m.normal_stiffness);
      glProgramUniform1f(id, loc("u_cn0"), cn0);
      glProgramUniform1f(id, loc("u_kt"), m.normal_stiffness * m.tangential_stiffness_ratio);
      glProgramUniform1f(id, loc("u_ctr"), m.tangential_damping_ratio);
      glProgramUniform1f(id, loc("u_mu"), m.friction);
      glProgramUniform1f(id, loc("u_floor_y"), def.floor_height);
      glProgramUniform1i(id, loc("u_walls"), def.side_walls ? 1 : 0);
      glProgramUniform3f(id, loc("u_gravity"), gravity.x, gravity.y, gravity.z);
      glProgramUniform1f(id, loc("u_reach"), shape.centre_distance + shape.radius);
      glProgramUniform1f(id, loc("u_resort_d2"), 0.25f * skin * skin);
      glProgramUniform1f(id, loc("u_half_skin"), 0.5f * skin);
      const TerrainGrid& t = def.terrain;
      glProgramUniform1i(id, loc("u_terrain"), t.empty() ? 0 : 1);
      glProgramUniform2i(id, loc("u_tn"), t.nx, t.nz);
      glProgramUniform2f(id, loc("u_t0"), t.x0, t.z0);
      glProgramUniform1f(id, loc("u_tspacing"), t.spacing);
      glProgramUniform4f(id, loc("u_fill"), t.fill_min_x, t.fill_min_z, t.fill_max_x, t.fill_max_z);
    }
  }
  // The terrain heights after the sort arrays (common.glsl: Sort.terrain).
  void upload_terrain() {
    if (def.terrain.empty()) return;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kSort, sort_terrain_offset(), def.terrain.heights.size() * 4, def.terrain.heights.data());
  }
  void set_counts() {
    for (auto& p : prog) {
      glProgramUniform1ui(p.id(), glGetUniformLocation(p.id(), "u_np"), GLuint(np_gpu));
      glProgramUniform1ui(p.id(), glGetUniformLocation(p.id(), "u_nb"), GLuint(nb_gpu));
    }
  }

  void dispatch(Kernel k, int items, int per_group) {
    if (items <= 0) return;
    std::chrono::steady_clock::time_point t0;
    if (opt.profile) {
      glFinish();
      t0 = std::chrono::steady_clock::now();
    }
    glUseProgram(prog[k].id());
    glDispatchCompute(GLuint((items + per_group - 1) / per_group), 1, 1);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    if (opt.profile) {
      glFinish();
      kernel_seconds[k] += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  }

  // A grid kernel with the arguments grid_decide.comp wrote (0 workgroups: no re-sort).
  void dispatch_indirect(Kernel k) {
    std::chrono::steady_clock::time_point t0;
    if (opt.profile) {
      glFinish();
      t0 = std::chrono::steady_clock::now();
    }
    glUseProgram(prog[k].id());
    glDispatchComputeIndirect(GLintptr(offsetof(physics::DemStatus, grid_dispatch) + 12 * std::size_t(k - kGridCount)));
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    if (opt.profile) {
      glFinish();
      kernel_seconds[k] += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    }
  }

  // One word of the status block (physics::DemStatus, at the start of the grid buffer).
  void set_status_word(std::size_t offset, std::uint32_t v) {
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kG, offset, 4, &v);
  }
  void write(Buf b, std::size_t offset, std::size_t bytes, const void* data) {
    if (bytes == 0) return;
    glBindBuffer(GL_COPY_WRITE_BUFFER, buf[b]);
    glBufferSubData(GL_COPY_WRITE_BUFFER, GLintptr(offset), GLsizeiptr(bytes), data);
  }
  void read(Buf b, std::size_t offset, std::size_t bytes, void* out) const {
    if (bytes == 0) return;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    glBindBuffer(GL_COPY_READ_BUFFER, buf[b]);
    glGetBufferSubData(GL_COPY_READ_BUFFER, GLintptr(offset), GLsizeiptr(bytes), out);
  }
  Buf pcur() const { return Buf(kP0 + cur_p); }

  // Bytes one staged body (with its spheres) takes to upload.
  std::size_t body_upload_bytes(std::size_t staged_body) const {
    return body_bytes + std::size_t(bst.count[staged_body]) * (particle_bytes + 4);
  }
  static constexpr std::size_t body_bytes = sum_strides(kBodyFields);
  static constexpr std::size_t particle_bytes = sum_strides(kParticleFields);

  std::size_t pending_bytes() const {
    std::size_t n = 0;
    for (std::size_t b = 0; b < std::size_t(nb - nb_gpu); ++b) n += body_upload_bytes(b);
    return n;
  }

  // Uploads staged bodies in order, whole bodies only, while they fit in max_bytes (with
  // at_least_one, the first body goes however large it is), one write per field; then
  // rebuilds their spheres. Returns the bytes written.
  std::size_t upload(std::size_t max_bytes, bool at_least_one = true) {
    const std::size_t staged = std::size_t(nb - nb_gpu);
    if (staged == 0) return 0;
    std::size_t bn = 0, bytes = 0;
    while (bn < staged && ((bn == 0 && at_least_one) || bytes + body_upload_bytes(bn) <= max_bytes))
      bytes += body_upload_bytes(bn++);
    if (bn == 0) return 0;
    std::size_t pn = 0;
    for (std::size_t b = 0; b < bn; ++b) pn += std::size_t(bst.count[b]);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    const std::size_t p0 = std::size_t(np_gpu), b0 = std::size_t(nb_gpu);
    // new particles take sorted places np_gpu.. (their ids), until the next grid build
#define SP_UP_P(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(GL, backend, write(pcur(), poff(kParticle_##name) + p0 * 4 * (n), pn * 4 * (n), pst.name.data());)
    SANDPATCH_PARTICLE_FIELDS(SP_UP_P)
#undef SP_UP_P
#define SP_UP_B(type, name, n, hashed, backend, unit) \
  SANDPATCH_FIELD_ON(GL, backend, write(kB, boff(kBody_##name) + b0 * 4 * (n), bn * 4 * (n), bst.name.data());)
    SANDPATCH_BODY_FIELDS(SP_UP_B)
#undef SP_UP_B
    std::vector<std::int32_t> slot(pn);
    for (std::size_t k = 0; k < pn; ++k) slot[k] = std::int32_t(p0 + k);
    write(kSort, s_slot_of() + p0 * 4, pn * 4, slot.data());
    set_status_word(offsetof(physics::DemStatus, resort), 1);  // the new spheres are in no cell yet: re-sort
    // drop the uploaded part of the staging arrays
#define SP_DROP_P(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, pst.name.erase(pst.name.begin(), pst.name.begin() + pn * (n));)
    SANDPATCH_PARTICLE_FIELDS(SP_DROP_P)
#undef SP_DROP_P
#define SP_DROP_B(type, name, n, hashed, backend, unit) SANDPATCH_FIELD_ON(GL, backend, bst.name.erase(bst.name.begin(), bst.name.begin() + bn * (n));)
    SANDPATCH_BODY_FIELDS(SP_DROP_B)
#undef SP_DROP_B
    np_gpu += int(pn);
    nb_gpu += int(bn);
    set_counts();
    bind_all();
    glMemoryBarrier(GL_ALL_BARRIER_BITS);
    glProgramUniform1i(prog[kBodies].id(), glGetUniformLocation(prog[kBodies].id(), "u_mode"), 1);
    glProgramUniform1ui(prog[kBodies].id(), glGetUniformLocation(prog[kBodies].id(), "u_first_body"), GLuint(b0));
    dispatch(kBodies, int(bn), wg);
    glProgramUniform1i(prog[kBodies].id(), glGetUniformLocation(prog[kBodies].id(), "u_mode"), 0);
    glUseProgram(0);
    return bytes;
  }
  void flush() {
    while (nb_gpu < nb) upload(std::numeric_limits<std::size_t>::max());
  }

  std::uint32_t body_flags(int i) const { return host_flags[std::size_t(i)]; }
  // Writes xyz of a vec4 body field of body i: the staged copy, or 12 bytes at its index.
  void set_body_vec(int field, int i, const float* xyzw, std::size_t comps) {
    if (i >= nb_gpu) {
      std::vector<float>* a[] = {&bst.pos, &bst.quat, &bst.vel, &bst.omega};
      const int fields[] = {kBody_pos, kBody_quat, kBody_vel, kBody_omega};
      for (int k = 0; k < 4; ++k)
        if (fields[k] == field)
          for (std::size_t c = 0; c < comps; ++c) (*a[k])[4 * std::size_t(i - nb_gpu) + c] = xyzw[c];
      return;
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kB, boff(field) + std::size_t(i) * 16, comps * 4, xyzw);
  }
  // Rebuilds the spheres of uploaded body i from its (just written) state, as an upload
  // does (bodies.comp mode 1, limited to body i), and raises the re-sort flag: the spheres
  // jumped, so the cells and the neighbour search must be rebuilt before the next contacts.
  void rebuild_body(int i) {
    if (i >= nb_gpu) return;  // staged: upload() rebuilds it
    bind_all();
    glMemoryBarrier(GL_ALL_BARRIER_BITS);
    const GLuint bp = prog[kBodies].id();
    glProgramUniform1i(bp, glGetUniformLocation(bp, "u_mode"), 1);
    glProgramUniform1ui(bp, glGetUniformLocation(bp, "u_first_body"), GLuint(i));
    glProgramUniform1ui(bp, glGetUniformLocation(bp, "u_nb"), GLuint(i + 1));
    dispatch(kBodies, 1, wg);
    glProgramUniform1ui(bp, glGetUniformLocation(bp, "u_nb"), GLuint(nb_gpu));
    glProgramUniform1i(bp, glGetUniformLocation(bp, "u_mode"), 0);
    glUseProgram(0);
    set_status_word(offsetof(physics::DemStatus, resort), 1);
  }

  void substep(float dt) {
    bind_all();
    // grid: decided on the GPU, then the counting sort by indirect dispatches
    dispatch(kGridDecide, 1, 1);
    glMemoryBarrier(GL_COMMAND_BARRIER_BIT);
    glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, buf[kG]);
    for (int k = kGridCount; k <= kGridCopyBack; ++k) dispatch_indirect(Kernel(k));
    glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, 0);
    glProgramUniform1f(prog[kForce].id(), glGetUniformLocation(prog[kForce].id(), "u_dt"), dt);
    glProgramUniform1i(prog[kForce].id(), glGetUniformLocation(prog[kForce].id(), "u_first_law"),
                       guard->contact_timing_on(dt) ? 1 : 0);
    dispatch(kForce, np_gpu, wg);
    cur_s = 1 - cur_s;  // the springs written become the ones read next substep
    bind_all();
    glProgramUniform1f(prog[kBodies].id(), glGetUniformLocation(prog[kBodies].id(), "u_dt"), dt);
    glProgramUniform1f(prog[kBodies].id(), glGetUniformLocation(prog[kBodies].id(), "u_pred"),
                       float(guard->velocity_predictor_gain(dt)));
    dispatch(kBodies, nb_gpu, wg);
  }

  // Appends a body and its spheres to the staging arrays (caller checked capacities).
  int push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm, Vec3 inv_inertia,
                const Vec3* offsets, const float* radii, int count, bool one_radius) {
    const int i = nb++;
    const std::size_t bi = std::size_t(i - nb_gpu);
    bst.push_zero();
    put3(bst.pos, bi, x);
    Quat qn = normalized(q);
    bst.quat[4 * bi] = qn.x;
    bst.quat[4 * bi + 1] = qn.y;
    bst.quat[4 * bi + 2] = qn.z;
    bst.quat[4 * bi + 3] = qn.w;
    put3(bst.vel, bi, v);
    put3(bst.omega, bi, w);
    bst.mass[4 * bi] = mass;
    bst.mass[4 * bi + 1] = invm;
    put3(bst.inv_inertia, bi, inv_inertia);
    bst.flags[bi] = flags;
    host_flags.push_back(flags);
    bst.first[bi] = np;
    bst.count[bi] = count;
    for (int k = 0; k < count; ++k) {
      const int s = np++;
      const std::size_t si = std::size_t(s - np_gpu);
      pst.push_zero();
      pst.id[si] = s;
      pst.body[si] = i;
      put3(pst.offset, si, offsets[k]);
      pst.pos[4 * si + 3] = one_radius ? radii[0] : radii[k];
    }
    asleep = false;
    below_time = 0;
    return i;
  }

  Vec3 body_vec(int field, BodyId b) const {
    float v[4] = {};
    if (b.index < 0 || b.index >= nb) return {};
    if (b.index >= nb_gpu) {  // still staged: not simulated yet
      const std::size_t k = std::size_t(b.index - nb_gpu);
      const std::vector<float>* a[] = {&bst.pos, &bst.quat, &bst.vel, &bst.omega, &bst.force, &bst.torque};
      const int fields[] = {kBody_pos, kBody_quat, kBody_vel, kBody_omega, kBody_force, kBody_torque};
      for (int i = 0; i < 6; ++i)
        if (fields[i] == field) return {(*a[i])[4 * k], (*a[i])[4 * k + 1], (*a[i])[4 * k + 2]};
      return {};
    }
    read(kB, boff(field) + std::size_t(b.index) * 16, 16, v);
    return {v[0], v[1], v[2]};
  }
  // Particle field (vec4) in stable-id order.
  std::vector<Vec3> by_id(int field) const {
    const_cast<Impl*>(this)->flush();
    std::vector<float> a(std::size_t(np) * 4);
    std::vector<std::int32_t> slot(np);
    read(pcur(), poff(field), a.size() * 4, a.data());
    read(kSort, s_slot_of(), slot.size() * 4, slot.data());
    std::vector<Vec3> out(np);
    for (int id = 0; id < np; ++id) {
      const std::size_t s = std::size_t(slot[id]);
      out[id] = {a[4 * s], a[4 * s + 1], a[4 * s + 2]};
    }
    return out;
  }

  // Checks the generated layout against the offsets the driver assigned.
  Status check_layout() const {
    auto check = [&](GLuint program, const std::string& block, std::string_view field, std::size_t want) -> Status {
      const std::string name = block + "." + std::string(field) + "[0]";
      GLuint idx = glGetProgramResourceIndex(program, GL_BUFFER_VARIABLE, name.c_str());
      if (idx == GL_INVALID_INDEX) return Ok{};  // not reported by this driver: nothing to compare
      const GLenum props[1] = {GL_OFFSET};
      GLint got = -1;
      glGetProgramResourceiv(program, GL_BUFFER_VARIABLE, idx, 1, props, 1, nullptr, &got);
      if (std::size_t(got) != want)
        return Error{"", "std430 layout of " + name, std::to_string(got),
                     "the driver's offset must equal the generated offset " + std::to_string(want),
                     "particles/gpu/layout.hpp and the driver disagree"};
      return Ok{};
    };
    for (int f = 0; f < kParticleFieldCount; ++f)
      if (auto st = check(prog[kGridGather].id(), "ParticlesA", kParticleFields[f].name, poff(f)); !st) return st;
    for (int f = 0; f < kBodyFieldCount; ++f)
      if (auto st = check(prog[kBodies].id(), "Bodies", kBodyFields[f].name, boff(f)); !st) return st;
    return Ok{};
  }
};

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
  pst.clear();
  bst.clear();
  host_flags.clear();
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
  s.buf_bytes[Impl::kG] = sizeof(physics::DemStatus) + 4 * (std::size_t(s.cap_cells) + 1 + std::size_t(s.cap_cells) + s.scan_blocks_cap);
  s.buf_bytes[Impl::kS0] = s.buf_bytes[Impl::kS1] = round_up(4 * P, 16) + 16 * P * std::size_t(s.K);
  s.buf_bytes[Impl::kW] = round_up(4 * P, 16) + 16 * P * kWallSlots;
  s.buf_bytes[Impl::kSort] = s.sort_terrain_offset() + 4 * std::max<std::size_t>(s.cap_terrain, 1);
  GLint64 max_block = 0;
  glGetInteger64v(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_block);
  if (max_block <= 0) return Error{"", "GlSimulation", "no GL context", "a current OpenGL 4.3+ context is needed", ""};
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

  // programs: generated preamble + physics_common.glsl (the physics shared with the CPU
  // backend, and the status block) + common.glsl + kernel
  const std::string pre = s.preamble() + std::string(shaders::source("dem/physics_common.glsl")) + "\n#line 1 2\n" +
                          std::string(shaders::source("dem/common.glsl")) + "\n#line 1 3\n";
  for (int k = 0; k < kKernelCount; ++k) {
    std::string_view src = shaders::source(kKernelFile[k]);
    if (src.empty()) return Error{"", std::string("shaders/") + kKernelFile[k], "missing", "must be embedded", ""};
    auto p = gl::Program::compute(std::string("shaders/") + kKernelFile[k], pre + std::string(src));
    if (!p) return p.errors();
    s.prog[k] = std::move(*p);
  }
  if (auto st = s.check_layout(); !st) return st.errors();

  // buffers, zeroed (spring counts, wall masks and cell counts start at 0)
  glGenBuffers(Impl::kBufCount, s.buf);
  for (int b = 0; b < Impl::kBufCount; ++b) {
    std::vector<unsigned char> zero(s.buf_bytes[b], 0);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, s.buf[b]);
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(s.buf_bytes[b]), zero.data(), GL_DYNAMIC_COPY);
  }
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  s.set_static_uniforms();
  s.set_counts();
  s.upload_terrain();
  return GlSimulation(std::move(im));
}

Status GlSimulation::reset(const SimulationDef& def, const char* capacity_prefix) {
  return impl_->configure(def, capacity_prefix);
}

Result<BodyId> GlSimulation::add_granule(Vec3 x, Quat q, Vec3 v, Vec3 w) {
  Impl& s = *impl_;
  if (s.nb + 1 > s.def.max_bodies)
    return Error{"", "SimulationDef.max_bodies", format_number(s.def.max_bodies), "is full: raise max_bodies",
                 "add_granule needs 1 more body"};
  if (s.np + 4 > s.def.max_particles)
    return Error{"", "SimulationDef.max_particles", format_number(s.def.max_particles), "is full: raise max_particles",
                 "add_granule needs 4 more particles"};
  if (!std::isfinite(x.x + x.y + x.z + q.x + q.y + q.z + q.w + v.x + v.y + v.z + w.x + w.y + w.z))
    return Error{"", "add_granule", "non-finite", "position, orientation and velocities must be finite", ""};
  const GranuleShape& g = s.shape;
  float r = g.radius;
  float inv_i = 1.0f / g.inertia;
  return BodyId{s.push_body(kBodyGranule | kBodyDynamic, x, q, v, w, g.mass, 1.0f / g.mass, {inv_i, inv_i, inv_i},
                            g.offsets.data(), &r, 4, true)};
}

Result<BodyId> GlSimulation::add_shell(const ShellDef& sh) {
  Impl& s = *impl_;
  auto plan = plan_shell(sh, s.nb, s.def.max_bodies, s.np, s.def.max_particles);
  if (!plan) return plan.errors();
  const int count = plan->count;
  const bool one = plan->one_radius;
  const float rmax = plan->max_radius, arm = plan->arm, invm = plan->inv_mass;
  const std::uint32_t flags = plan->flags;
  const Vec3 iI = plan->inv_inertia;
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
  if (rmax > s.r_max) {  // bigger cells: fewer of them, the buffers still fit
    s.r_max = rmax;
    s.size_grid();
    s.set_static_uniforms();
  }
  const int i = s.push_body(flags, sh.position, sh.orientation, sh.velocity, sh.angular_velocity,
                            sh.motion == MotionType::Dynamic ? sh.mass : 0.0f, invm, iI, sh.offsets.data(),
                            sh.radii.data(), count, one);
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
  if (id.index < 0 || id.index >= s.nb)
    return Error{"", "set_body_state.body", std::to_string(id.index), "must be a body of this simulation", ""};
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
  if (id.index < 0 || id.index >= s.nb)
    return Error{"", "set_body_enabled.body", std::to_string(id.index), "must be a body of this simulation", ""};
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

Result<int> GlSimulation::substeps_for(double dt_frame) const { return impl_->guard->substeps_for(dt_frame); }
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
      glProgramUniform1f(tp, glGetUniformLocation(tp, "u_dt"), float(dt_frame));
      s.dispatch(kKinematicTouch, s.np_gpu, s.wg);
      std::uint32_t flag = 0;
      s.read(Impl::kG, offsetof(physics::DemStatus, kinematic_touch), 4, &flag);
      touch = flag != 0;
      if (!touch) {
        const GLuint bp = s.prog[kBodies].id();
        glProgramUniform1i(bp, glGetUniformLocation(bp, "u_mode"), 2);
        glProgramUniform1f(bp, glGetUniformLocation(bp, "u_dt"), float(dt_frame));
        s.dispatch(kBodies, s.nb_gpu, s.wg);
        glProgramUniform1i(bp, glGetUniformLocation(bp, "u_mode"), 0);
      }
      glUseProgram(0);
    }
    if (!touch) {
      s.time += dt_frame;
      s.stats.slept = true;
      s.stats.substeps = 0;
      return Ok{};
    }
    s.asleep = false;
    s.below_time = 0;
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
  for (int k = 0; k < *ns; ++k) {
    if (k + 1 == *ns) {  // the counters describe the last substep, as on the CPU
      glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
      constexpr std::size_t first = offsetof(physics::DemStatus, max_partners);
      s.write(Impl::kG, first, offsetof(physics::DemStatus, resort) - first, &status.max_partners);
      s.write(Impl::kG, offsetof(physics::DemStatus, max_granule_speed), 4, &status.max_granule_speed);
    }
    s.substep(dt);
    s.time += dt;
  }
  glUseProgram(0);
  s.read(Impl::kG, 0, offsetof(physics::DemStatus, grid_dispatch), &status);
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
void GlSimulation::wake() {
  impl_->asleep = false;
  impl_->below_time = 0;
}
int GlSimulation::body_count() const { return impl_->nb; }
int GlSimulation::particle_count() const { return impl_->np; }
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
  // (count, and the slots in use: xi bits and partner id) as the next substep reads them.
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
  }
  return h.value();
}

const SimulationDef& GlSimulation::def() const { return impl_->def; }
const GranuleShape& GlSimulation::granule_shape() const { return impl_->shape; }
double GlSimulation::time() const { return impl_->time; }

unsigned GlSimulation::particle_buffer() const { return impl_->buf[Impl::kP0 + impl_->cur_p]; }

std::vector<unsigned> GlSimulation::gl_buffers() const {
  return std::vector<unsigned>(std::begin(impl_->buf), std::end(impl_->buf));
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
  for (int k = 0; k < kKernelCount; ++k) out.emplace_back(kKernelFile[k], impl_->kernel_seconds[k]);
  return out;
}

std::size_t GlSimulation::gpu_bytes() const {
  std::size_t n = 0;
  for (std::size_t b : impl_->buf_bytes) n += b;
  return n;
}

}  // namespace sandpatch::gpu
