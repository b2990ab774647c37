// Contact force law of the granule DEM, for one sphere of a pair or a sphere on a plane (sim
// units): the normal spring-dashpot f_n = max(0, k_n delta - c_n v.n) (N, never attractive;
// Bell et al. 2005, with the first-substep dashpot of docs/dem.md "Step size") and the
// Coulomb-capped tangential spring with history (Cundall & Strack 1979).
//
// The law itself is written once, in shaders/dem/physics_common.glsl, and compiled both as
// C++ (particles/dem_physics.hpp) and as GLSL (the GL force kernel); its comments give the
// formulas. This header names it in namespace sandpatch for the CPU backend and the tests.
#pragma once

#include "particles/dem_physics.hpp"

namespace sandpatch {

using physics::ContactForce;
using physics::ContactParams;
using physics::contact_force;

}  // namespace sandpatch
