// The GL backend's internal state (GlSimulation::Impl) and what its files share; see
// gl_simulation.hpp and docs/dem-gpu.md. Internal to particles/gpu/:
//   gl_simulation.cpp  GlSimulation's methods: create/reset, bodies, step and substep, queries,
//                      state hash
//   gl_programs.cpp    the kernels' generated preamble (std430 blocks of fields.hpp), their
//                      compilation (with shaders/dem/physics_common.glsl), uniforms, layout check
//   gl_transfer.cpp    host <-> GPU: staging and upload of bodies, writes of a body's state,
//                      read-backs by id
//   gl_springs.cpp     contact springs read and set from outside (contact_springs,
//                      set_contact_springs)
#pragma once

#include <GL/glcorearb.h>

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "gl/program.hpp"
#include "particles/dem_physics.hpp"
#include "particles/fields.hpp"
#include "particles/gpu/gl_simulation.hpp"
#include "particles/gpu/layout.hpp"

namespace sandpatch::gpu {

// Buffer bindings (shaders/dem/common.glsl lists the same).
enum Binding : GLuint {
  kBindP = 0, kBindPn = 1, kBindB = 2, kBindG = 3, kBindSIn = 4, kBindSOut = 5, kBindW = 6, kBindS = 7,
  kBindArgs = 8, kBindCopySrc = 9, kBindCopyDst = 10
};
// Storage blocks a DEM kernel declares (bindings 0-8, common.glsl; copy_words.comp declares its
// own two alone): one more than GL 4.3's minimum per compute shader, 8; drivers offer 16 or
// more (NVIDIA, Mesa). create() checks GL_MAX_COMPUTE_SHADER_STORAGE_BLOCKS.
constexpr int kStorageBlocks = 9;

constexpr int kWallSlots = physics::kPlaneSlots;  // per sphere: floor, walls x0, x1, z0, z1, terrain
constexpr int kScanBlock = 1024;  // cells per workgroup of scan_blocks.comp

// The kernels, in the order of a frame (rebuild is bodies.comp in mode 1): grid_decide.comp
// once, then per substep the grid kernels kGridCount..kGridCopyBack by glDispatchComputeIndirect
// with the arguments of A.grid_dispatch[3 (k - kGridCount) ..] (shaders/dem/common.glsl
// write_grid_dispatch; args_buf), the contact and the body stage. kCopyWords: the host's writes.
enum Kernel {
  kGridDecide, kGridCount, kScanBlocks, kScanTop, kGridScatter, kGridGather, kGridCopyBack,
  kForce, kBodies, kBodiesWide, kKinematicTouch, kCopyWords, kKernelCount
};
inline constexpr const char* kKernelFile[kKernelCount] = {
    "dem/grid_decide.comp",  "dem/grid_count.comp",    "dem/scan_blocks.comp", "dem/scan_top.comp",
    "dem/grid_scatter.comp", "dem/grid_gather.comp",   "dem/grid_copyback.comp", "dem/force.comp",
    "dem/bodies.comp",       "dem/bodies.comp",        "dem/kinematic_touch.comp", "dem/copy_words.comp"};
// A macro defined before a kernel's source (nullptr: none): kBodiesWide is bodies.comp's
// workgroup-per-body pass.
inline constexpr const char* kKernelDefine[kKernelCount] = {nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr,
                                                           nullptr, nullptr, "SP_WIDE_PASS", nullptr, nullptr};

// A body of more spheres than this (a shell) is summed, integrated and rebuilt by a workgroup
// of its own (bodies.comp's SP_WIDE_PASS); the others, granules first, by one invocation
// each. One invocation looping over a shell of a few thousand spheres took most of a scene's
// body stage (docs/BENCHMARKS.md "The GL backend's host time in scenes").
constexpr int kWideSpheres = 32;
// The invocations of that workgroup: each sums every kWideGroup-th sphere of the shell. A
// 5 m crate of 48,000 spheres summed by 32 invocations took 70 % of a scene's GPU time
// (docs/BENCHMARKS.md "Leach & Marais' scenarios 1 and 2 at the paper's sizes on a GPU").
// Its two shared arrays of vec4 take 2 x 16 x 512 = 16 KiB, half the 32 KiB every GL 4.3
// driver gives a workgroup.
constexpr int kWideGroup = 512;

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

inline void put3(std::vector<float>& a, std::size_t i, Vec3 v, float w = 0.0f) {
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
  std::vector<std::int32_t> wide;  // uploaded bodies of more than kWideSpheres spheres, as in G.wide_body
  ParticleStage pst;
  BodyStage bst;
  std::vector<std::uint32_t> host_flags;  // every body's flags (only the host changes them): no read-back
  std::vector<std::int32_t> host_count;   // every body's sphere count
  std::vector<std::int32_t> host_group;   // every body's collision group (only the host changes them)

  // grid (sized as the CPU's: cell = 2 r_max + skin)
  float r_max = 0, skin = 0, h = 0;
  int gx = 1, gy = 1, gz = 1;

  // GL objects
  enum Buf { kP0, kP1, kB, kG, kS0, kS1, kW, kSort, kBufCount };
  GLuint buf[kBufCount] = {};
  std::size_t buf_bytes[kBufCount] = {};
  // The grid kernels' dispatch-indirect arguments, copied from the status block at the start
  // of every substep: a buffer of its own that no shader binds (substep()).
  GLuint args_buf = 0;
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
  double kernel_seconds[kKernelCount] = {};  // GlOptions::profile: GPU seconds per kernel
  std::vector<GLuint> queries;                // GlOptions::profile: GL_TIME_ELAPSED query objects, reused
  std::vector<int> query_kernel;              // the kernel of each query issued this step
  // The per-dispatch uniforms' locations in each program (-1 where a program lacks one: GL
  // ignores a write to -1), looked up once after linking rather than by name every substep.
  struct Uniforms {
    GLint dt = -1, first_law = -1, pred = -1, mode = -1, first_body = -1, np = -1, nb = -1;
    GLint src_word = -1, dst_word = -1, words = -1;  // copy_words.comp
  } u[kKernelCount];

  Status configure(const SimulationDef& d, const char* cap_prefix);
  Status build_programs();  // gl_programs.cpp
  void resolve_queries();   // GlOptions::profile: adds this step's GPU times to kernel_seconds

  std::size_t poff(int f) const { return std430_offset(kParticleFields, f, std::size_t(cap_p)); }
  std::size_t boff(int f) const { return std430_offset(kBodyFields, f, std::size_t(cap_b)); }
  // Byte offsets inside the other blocks (common.glsl's declarations).
  std::size_t g_cell_start() const { return sizeof(physics::DemStatus); }
  // G.wide_body (common.glsl): after the cell starts, counts and block sums
  std::size_t g_wide_body() const {
    return g_cell_start() + 4 * (2 * std::size_t(cap_cells) + 1 + std::size_t(scan_blocks_cap));
  }
  std::size_t s_slot_of() const { return 0; }
  std::size_t sort_terrain_offset() const { return round_up(12 * std::size_t(cap_p), 16) + 16 * std::size_t(cap_p); }

  // The one buffer every write() goes through (write()).
  GLuint staging = 0;
  ~Impl() {
    // a program in use is only flagged for deletion: release ours so the names really go
    GLint current = 0;
    glGetIntegerv(GL_CURRENT_PROGRAM, &current);
    for (const auto& p : prog)
      if (p.id() != 0 && GLuint(current) == p.id()) glUseProgram(0);
    bool any = false;
    for (GLuint b : buf) any = any || b != 0;
    if (any) glDeleteBuffers(kBufCount, buf);
    if (args_buf != 0) glDeleteBuffers(1, &args_buf);
    if (staging != 0) glDeleteBuffers(1, &staging);
    if (!queries.empty()) glDeleteQueries(GLsizei(queries.size()), queries.data());
  }

  std::string preamble() const;

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
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindArgs, args_buf);
  }

  // Uniforms that change only with the grid or never: set on every program.
  void set_static_uniforms();
  // The terrain heights after the sort arrays (common.glsl: Sort.terrain).
  void upload_terrain() {
    if (def.terrain.empty()) return;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kSort, sort_terrain_offset(), def.terrain.heights.size() * 4, def.terrain.heights.data());
  }
  void set_counts() {
    for (int k = 0; k < kKernelCount; ++k) {
      glProgramUniform1ui(prog[k].id(), u[k].np, GLuint(np_gpu));
      glProgramUniform1ui(prog[k].id(), u[k].nb, GLuint(nb_gpu));
    }
  }

  // Kernel k over `items` invocations, then glMemoryBarrier(after): by default the storage
  // barrier (the next kernel reads what this one wrote); substep() names what each orders.
  void dispatch(Kernel k, int items, int per_group, GLbitfield after = GL_SHADER_STORAGE_BARRIER_BIT) {
    if (items <= 0) return;
    begin_query(k);
    glUseProgram(prog[k].id());
    glDispatchCompute(GLuint((items + per_group - 1) / per_group), 1, 1);
    end_query();
    glMemoryBarrier(after);
  }

  // Kernel k in `groups` workgroups, no barrier (the caller's next dispatch orders it).
  void dispatch_groups(Kernel k, int groups) {
    if (groups <= 0) return;
    begin_query(k);
    glUseProgram(prog[k].id());
    glDispatchCompute(GLuint(groups), 1, 1);
    end_query();
  }

  // Appends the bodies [first, nb_gpu) of more than kWideSpheres spheres to G.wide_body, for
  // the workgroup-per-body pass (after an upload: bodies never change their sphere count).
  void append_wide(int first) {
    const std::size_t had = wide.size();
    for (int i = first; i < nb_gpu; ++i)
      if (host_count[std::size_t(i)] > kWideSpheres) wide.push_back(i);
    if (wide.size() == had) return;
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kG, g_wide_body() + 4 * had, (wide.size() - had) * 4, wide.data() + had);
  }

  // A grid kernel with the arguments in args_buf (bound as GL_DISPATCH_INDIRECT_BUFFER by
  // bind_substep_targets; 0 workgroups: no re-sort), then the storage barrier: each grid
  // stage reads what the one before wrote, and the contact stage the grid.
  void dispatch_indirect(Kernel k) {
    begin_query(k);
    glUseProgram(prog[k].id());
    glDispatchComputeIndirect(GLintptr(12 * std::size_t(k - kGridCount)));  // args_buf
    end_query();
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
  }

  // The indirect-dispatch buffer of the substeps' grid kernels, bound once per frame (step).
  void bind_substep_targets() { glBindBuffer(GL_DISPATCH_INDIRECT_BUFFER, args_buf); }

  // GlOptions::profile: a GL_TIME_ELAPSED query around one dispatch, read at the end of the
  // step (no stall between kernels, so the step runs as it does unprofiled).
  void begin_query(Kernel k) {
    if (!opt.profile) return;
    if (query_kernel.size() == queries.size()) {
      queries.push_back(0);
      glGenQueries(1, &queries.back());
    }
    glBeginQuery(GL_TIME_ELAPSED, queries[query_kernel.size()]);
    query_kernel.push_back(k);
  }
  void end_query() {
    if (opt.profile) glEndQuery(GL_TIME_ELAPSED);
  }

  // One word of the status block (physics::DemStatus, at the start of the grid buffer).
  void set_status_word(std::size_t offset, std::uint32_t v) {
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    write(kG, offset, 4, &v);
  }
  // Bytes (whole 32-bit words) into buffer b at offset, in command order: into `staging` (a
  // fresh allocation each time), and from there by copy_words.comp, between storage barriers
  // (the kernels before have read and written b; the ones after read the words). On NVIDIA's
  // driver a glBufferSubData straight into a buffer the GPU was still using took about 1 ms a
  // call, and a glCopyBufferSubData into a large block 50-450 us (docs/BENCHMARKS.md "The GL
  // backend's host time in scenes", "GL backend on a GPU").
  void write(Buf b, std::size_t offset, std::size_t bytes, const void* data) {
    if (bytes == 0) return;
    if (staging == 0) glGenBuffers(1, &staging);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, staging);
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(bytes), data, GL_STREAM_DRAW);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindCopySrc, staging);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kBindCopyDst, buf[b]);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    const GLuint id = prog[kCopyWords].id();
    const Uniforms& cu = u[kCopyWords];
    const std::size_t words = bytes / 4, chunk = std::size_t(wg) * 65535;  // the dispatch's x limit
    for (std::size_t done = 0; done < words; done += chunk) {
      const std::size_t n = std::min(chunk, words - done);
      glProgramUniform1ui(id, cu.src_word, GLuint(done));
      glProgramUniform1ui(id, cu.dst_word, GLuint(offset / 4 + done));
      glProgramUniform1ui(id, cu.words, GLuint(n));
      dispatch(kCopyWords, int(n), wg);  // and the storage barrier
    }
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
  std::size_t upload(std::size_t max_bytes, bool at_least_one = true);
  void flush() {
    while (nb_gpu < nb) upload(std::numeric_limits<std::size_t>::max());
  }

  std::uint32_t body_flags(int i) const { return host_flags[std::size_t(i)]; }
  // Writes xyz of a vec4 body field of body i: the staged copy, or 12 bytes at its index.
  void set_body_vec(int field, int i, const float* xyzw, std::size_t comps);
  // Rebuilds the spheres of uploaded body i from its (just written) state, as an upload
  // does (bodies.comp mode 1, limited to body i), and raises the re-sort flag: the spheres
  // jumped, so the cells and the neighbour search must be rebuilt before the next contacts.
  void rebuild_body(int i);

  void substep();

  // Appends a body and its spheres to the staging arrays (caller checked capacities).
  int push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm, Vec3 inv_inertia, const Vec3* offsets, const float* radii, int count, bool one_radius);

  Vec3 body_vec(int field, BodyId b) const;
  // Particle field (vec4) in stable-id order.
  std::vector<Vec3> by_id(int field) const;

  // Springs set from outside (set_contact_springs, gl_springs.cpp), waiting for the next step:
  // pairs by (lower particle id << 32 | higher id), the spring as the lower id's (m); plane
  // springs by particle id * kWallSlots + plane. take_set_springs() writes those whose spheres
  // are uploaded into the history the next substep reads and drops them from here; step()
  // calls it only while some wait (nothing is added to a step without them).
  struct SetSpring {
    float xi[3];  // m
    float dmax;   // m
  };
  std::map<std::uint64_t, SetSpring> set_pairs;
  std::map<std::int64_t, SetSpring> set_planes;
  bool springs_waiting() const { return !set_pairs.empty() || !set_planes.empty(); }
  void take_set_springs();
  // Byte offset of the slots after the counts / masks in the spring and wall blocks (common.glsl
  // SpringsIn/Out: count[P], slot[P K], dmax[P K]; Walls: mask[P], xi[P 6]).
  std::size_t springs_head() const { return round_up(4 * std::size_t(cap_p), 16); }
  std::size_t springs_dmax() const { return springs_head() + 16 * std::size_t(cap_p) * std::size_t(K); }

  // Checks the generated layout against the offsets the driver assigned.
  Status check_layout() const;
};

}  // namespace sandpatch::gpu
