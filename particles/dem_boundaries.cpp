// Granule DEM, CPU backend: the boundary planes of a sphere (floor, side walls, the terrain
// outside the filled region and the region's sides) with the contact law, and the terrain
// grid's sampling: both from shaders/dem/physics_common.glsl, the source the GL force kernel
// compiles too. dem_impl.hpp.
#include "particles/dem_impl.hpp"

#include "particles/contact.hpp"

namespace sandpatch {

// (shaders/dem/physics_common.glsl, shared with the GL force kernel)
float TerrainGrid::height(float x, float z) const { return physics::terrain_height(*this, x, z); }
Vec3 TerrainGrid::normal(float x, float z) const { return physics::terrain_normal(*this, x, z); }

// Boundaries of sphere i (dynamic): the planes of physics::boundary_plane (floor, side walls,
// the terrain outside the fill and the fill's sides; shaders/dem/physics_common.glsl, shared
// with the GL force kernel) in slot order; adds their force and torque (about the sphere
// centre) to F, T. WM[i] has bit k set while plane k touched the sphere at the last substep;
// a plane contact that was not in the mask starts with a fresh spring. Out of line: 4 % of
// sphere-steps reach it in a bed.
__attribute__((noinline)) void Simulation::Impl::boundary_contacts(const GatherCtx& g, const int i, const float dt,
                                                                   const std::uint32_t slots, Vec3& F, Vec3& T,
                                                                   std::int64_t& nwall) {
  const float kn = g.law.kn, cn0 = g.law.cn0, kt = g.law.kt, ctr = g.law.ctr, mu = g.law.mu;
  const float* P = g.P;
  const float* V = g.V;
  const float* W = g.W;
  const Vec3 pi{P[4 * i], P[4 * i + 1], P[4 * i + 2]};
  const float ri = P[4 * i + 3];
  const Vec3 ui{V[4 * i], V[4 * i + 1], V[4 * i + 2]};
  const float invm_i = V[4 * i + 3];
  const Vec3 wi{W[4 * i], W[4 * i + 1], W[4 * i + 2]};
  float* wx = g.WX + std::size_t(i) * 3 * kWallSlots;
  const std::uint32_t old_mask = g.WM[i];
  std::uint32_t mask = 0;
  for (int slot = 0; slot < kWallSlots; ++slot) {
    if (!(slots & (1u << slot))) continue;  // (out of its reach: boundary_plane would say so)
    Vec3 nrm;
    float dist;
    if (!physics::boundary_plane(g.bounds, def.terrain, slot, pi, ri, nrm, dist)) continue;
    float* xe = wx + 3 * slot;
    ++nwall;
    mask |= 1u << slot;
    const Vec3 v = physics::plane_contact_velocity(ui, wi, nrm, ri);
    const bool fresh = !(old_mask & (1u << slot));
    Vec3 xi{};
    if (!fresh) xi = {xe[0], xe[1], xe[2]};
    const float cnw = cn0 / std::sqrt(invm_i);
    // new_contact: the first substep of this plane contact
    const ContactParams cp{kn, cnw, kt, ctr * cnw, mu, dt, g.first_law && fresh};
    const float xi2_old = dot(xi, xi);
    float* dme = g.WD + std::size_t(i) * kWallSlots + slot;
    const float dm_old = fresh ? 0.0f : *dme;
    float dm = dm_old;
    const ContactForce cf = contact_force_h(cp, g.kn2, nrm, ri - dist, v, xi, dm);
    if (g.kn2 > kn) *dme = dm;
    if (ledger) {
      double dn = 0, dfr = 0, du = 0;
      ledger_terms(kn, g.kn2, kt, ri - dist, dm_old, dm, nrm, v, dt, xi2_old, cf.f, cf.ft, xi, dn, dfr, du);
#pragma omp atomic
      ledger_normal += dn;
#pragma omp atomic
      ledger_friction += dfr;
#pragma omp atomic
      ledger_spring_walls += du;
    }
    xe[0] = xi.x;
    xe[1] = xi.y;
    xe[2] = xi.z;
    F = F + cf.f;
    T = T + cross(nrm * (-ri), cf.ft);
  }
  if (mask != old_mask) g.WM[i] = mask;
}

}  // namespace sandpatch
