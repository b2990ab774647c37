// Granule DEM on the GPU: the kernels' programs. Each is the generated preamble (#version,
// capacities, the std430 blocks generated from particles/fields.hpp by layout.hpp, BodyFlags)
// + shaders/dem/physics_common.glsl (the contact law, terrain, boundary planes and status
// block, the CPU backend's own source) + common.glsl + the kernel; the uniforms they share;
// the check of the generated layout against the driver's. gl_impl.hpp.
#include <algorithm>
#include <string>
#include <string_view>

#include "particles/gpu/gl_impl.hpp"
#include "shaders/shaders.hpp"

namespace sandpatch::gpu {

std::string GlSimulation::Impl::preamble() const {
  std::string s = "#version 430\n";
  s += "#define SP_PARTICLES " + std::to_string(cap_p) + "\n";
  s += "#define SP_BODIES " + std::to_string(cap_b) + "\n";
  s += "#define SP_CELLS " + std::to_string(cap_cells) + "\n";
  s += "#define SP_SCAN_BLOCKS " + std::to_string(scan_blocks_cap) + "\n";
  s += "#define SP_K " + std::to_string(K) + "\n";
  s += "#define SP_WG " + std::to_string(wg) + "\n";
  s += "#define SP_WIDE " + std::to_string(kWideSpheres) + "\n";
  s += "#define SP_WIDE_WG " + std::to_string(kWideGroup) + "\n";
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

// Compiles every kernel: the generated preamble + physics_common.glsl (the physics shared
// with the CPU backend, and the status block) + common.glsl + the kernel; then checks the
// generated layout against the driver's offsets.
Status GlSimulation::Impl::build_programs() {
  const std::string pre = preamble() + std::string(shaders::source("dem/physics_common.glsl")) + "\n#line 1 2\n" +
                          std::string(shaders::source("dem/common.glsl")) + "\n#line 1 3\n";
  for (int k = 0; k < kKernelCount; ++k) {
    std::string_view src = shaders::source(kKernelFile[k]);
    if (src.empty()) return Error{"", std::string("shaders/") + kKernelFile[k], "missing", "must be embedded", ""};
    const std::string define = kKernelDefine[k] ? "#define " + std::string(kKernelDefine[k]) + "\n#line 1 3\n" : "";
    // copy_words.comp touches no DEM block: its own two only
    const std::string head = k == kCopyWords ? "#version 430\n#define SP_WG " + std::to_string(wg) + "\n#line 1 3\n" : pre;
    auto p = gl::Program::compute(std::string("shaders/") + kKernelFile[k], head + define + std::string(src));
    if (!p) return p.errors();
    prog[k] = std::move(*p);
    const GLuint id = prog[k].id();
    u[k] = Uniforms{glGetUniformLocation(id, "u_dt"),         glGetUniformLocation(id, "u_first_law"),
                    glGetUniformLocation(id, "u_pred"),       glGetUniformLocation(id, "u_mode"),
                    glGetUniformLocation(id, "u_first_body"), glGetUniformLocation(id, "u_np"),
                    glGetUniformLocation(id, "u_nb"),         glGetUniformLocation(id, "u_src_word"),
                    glGetUniformLocation(id, "u_dst_word"),   glGetUniformLocation(id, "u_words")};
  }
  return check_layout();
}

// Uniforms that change only with the grid or never: set on every program.
void GlSimulation::Impl::set_static_uniforms() {
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
    glProgramUniform1f(id, loc("u_kn2"), m.normal_stiffness * std::max(1.0f, m.unloading_stiffness_ratio));
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

// Checks the generated layout against the offsets the driver assigned.
Status GlSimulation::Impl::check_layout() const {
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

}  // namespace sandpatch::gpu
