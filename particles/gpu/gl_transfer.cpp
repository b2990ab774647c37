// Granule DEM on the GPU: host <-> GPU transfers. Bodies added are staged on the host (the
// generated structure-of-arrays of fields.hpp) and uploaded whole, within a byte budget; a
// body's state is written at its index (and its spheres rebuilt); queries read back only what
// they return, by stable particle id. gl_impl.hpp.
#include <cstring>
#include <limits>

#include "particles/dem_control.hpp"
#include "particles/gpu/gl_impl.hpp"

namespace sandpatch::gpu {

// Uploads staged bodies in order, whole bodies only, while they fit in max_bytes (with
// at_least_one, the first body goes however large it is), one write per field; then
// rebuilds their spheres. Returns the bytes written.
std::size_t GlSimulation::Impl::upload(std::size_t max_bytes, bool at_least_one) {
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
  append_wide(int(b0));
  bind_all();
  glMemoryBarrier(GL_ALL_BARRIER_BITS);
  glProgramUniform1i(prog[kBodies].id(), u[kBodies].mode, 1);
  glProgramUniform1ui(prog[kBodies].id(), u[kBodies].first_body, GLuint(b0));
  dispatch(kBodies, int(bn), wg);
  glProgramUniform1i(prog[kBodies].id(), u[kBodies].mode, 0);
  glUseProgram(0);
  return bytes;
}

// Writes xyz of a vec4 body field of body i: the staged copy, or 12 bytes at its index.
void GlSimulation::Impl::set_body_vec(int field, int i, const float* xyzw, std::size_t comps) {
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
void GlSimulation::Impl::rebuild_body(int i) {
  if (i >= nb_gpu) return;  // staged: upload() rebuilds it
  bind_all();
  glMemoryBarrier(GL_ALL_BARRIER_BITS);
  const GLuint bp = prog[kBodies].id();
  const Uniforms& ub = u[kBodies];
  glProgramUniform1i(bp, ub.mode, 1);
  glProgramUniform1ui(bp, ub.first_body, GLuint(i));
  glProgramUniform1ui(bp, ub.nb, GLuint(i + 1));
  dispatch(kBodies, 1, wg);
  glProgramUniform1ui(bp, ub.nb, GLuint(nb_gpu));
  glProgramUniform1i(bp, ub.mode, 0);
  glUseProgram(0);
  set_status_word(offsetof(physics::DemStatus, resort), 1);
}

// Appends a body and its spheres to the staging arrays (caller checked capacities).
int GlSimulation::Impl::push_body(std::uint32_t flags, Vec3 x, Quat q, Vec3 v, Vec3 w, float mass, float invm, Vec3 inv_inertia,
              const Vec3* offsets, const float* radii, int count, bool one_radius) {
  const int i = nb++;
  const std::size_t bi = std::size_t(i - nb_gpu);
  bst.push_zero();
  write_body_record(bst, bi, flags, x, q, v, w, mass, invm, inv_inertia, np, count);  // dem_control.hpp
  host_flags.push_back(flags);
  host_count.push_back(count);
  host_group.push_back(0);  // add_shell sets a shell's
  for (int k = 0; k < count; ++k) {
    const int s = np++;
    const std::size_t si = std::size_t(s - np_gpu);
    pst.push_zero();
    pst.id[si] = s;
    pst.body[si] = i;
    put3(pst.offset, si, offsets[k]);
    pst.pos[4 * si + 3] = one_radius ? radii[0] : radii[k];
  }
  wake_up(*this);
  return i;
}

Vec3 GlSimulation::Impl::body_vec(int field, BodyId b) const {
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
std::vector<Vec3> GlSimulation::Impl::by_id(int field) const {
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

}  // namespace sandpatch::gpu
