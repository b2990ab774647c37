// Predictive activation (Leach & Marais §3; docs/manager.md "The frame"): before
// a body touches the terrain, request a granular patch around the predicted contact, so a
// fast body never lands on a patch that is not ready.
//
// Prediction: the body's world bounds are swept along its ballistic path
//   p(t) = p0 + v0 t + ½ g t²        (t in [0, horizon], sampled every horizon/samples s)
// and the first sample whose bounds' bottom comes within `margin` of the highest heightfield
// sample under the bounds' footprint is the predicted contact. The bounds are inflated by the
// distance travelled in one sample interval, so a contact between two samples is not missed.
// The request covers the footprint at contact plus `apron` on every side.
//
// Pure functions of their inputs (no GL, no Bullet), after CDLOD's split of LOD selection
// from everything else (as CDLOD keeps LOD selection apart from drawing).
#pragma once

#include "common/knobs.hpp"

#include <Eigen/Core>
#include <vector>

#include "heightfield/heightfield.hpp"

namespace sandpatch {

struct LodDef {
  double horizon = knobs::kLodHorizon.def;  // s, how far ahead contacts are predicted
  int samples = 16;       // samples of the path over the horizon (>= 1)
  double margin = knobs::kLodMargin.def;    // m, clearance that already counts as contact
  double apron = knobs::kLodApron.def;      // m, added around the contact footprint on every side
  // A body carried toward its patch's edge takes its patch along (a successor moved by whole
  // tile periods, planning.cpp ask_successor) instead of a patch abutting it ahead.
  bool travel = true;
};

struct BodyMotion {
  Eigen::Vector3d lo, hi;         // m, world bounds now
  Eigen::Vector3d velocity;       // m/s
};

// A square-or-rectangular region of the terrain that should become particles.
struct PatchRequest {
  double x0 = 0, z0 = 0, x1 = 0, z1 = 0;  // m, world rectangle
  double time_to_contact = 0;             // s from now (0 = touching already)
  double speed = 0;                       // m/s of the fastest body in it (a priority key)
  std::vector<int> bodies;                // indices into the BodyMotion list
  // World size / simulated size the patch is promoted at; 0: chosen by the terrain manager at
  // promotion (by distance from the camera, TerrainManagerDef::scale_bands). A patch asked for
  // ahead of a body takes the scale of the patch the body is in (without a frame budget).
  double particle_scale = 0;
  // m: the apron on every side of the contacts' footprint (LodDef::apron; 0 for requests made
  // with request_patch). The frame budget may trim it (TerrainManagerDef::frame_budget_ms).
  double apron = 0;
  // The DEM's N (substeps at dt <= t_c / N) the patch runs at; 0: the manager's
  // (TerrainDef.steps_per_contact). The frame budget may lower it (budget.cpp).
  int steps_per_contact = 0;
  // The side (0: x0, 1: x1, 2: z0, 3: z1) on which it abuts the live patch it was asked for
  // ahead of (TerrainManager extend); -1: none. The budget trims its apron on the two sides
  // across that one only, so it stays against the patch it abuts and reaches as far ahead.
  int abuts = -1;
  // Asked for ahead of a body the patch it abuts carries: the frame budget does not make it
  // wait (filling.cpp; the body would meet the patch's edge first).
  bool ahead_of_carried = false;
  int waited_frames = 0;  // frames it waited in the queue because it did not fit the frame budget
  // A successor (planning.cpp extend, docs/manager.md "A patch that travels with its body"): the
  // live patch `successor_of` (a patch id) moved by whole tile periods ahead of the bodies it
  // carries, over exactly the heightfield samples [region_i0, region_i0 + region_ni) x
  // [region_j0, region_j0 + region_nj). It is filled from the tile only where it reaches past
  // that patch, takes that patch's granules over the rest when its fill is in, and that patch
  // is then demoted: one patch steps at a time. -1: an ordinary request.
  int successor_of = -1;
  int region_i0 = 0, region_j0 = 0, region_ni = 0, region_nj = 0;
  double width() const { return x1 - x0; }
  double depth() const { return z1 - z0; }
  bool overlaps(const PatchRequest& o) const { return x0 < o.x1 && o.x0 < x1 && z0 < o.z1 && o.z0 < z1; }
};

// Highest Elevation (m, world) of the heightfield samples in the world rectangle
// [x0, x1] × [z0, z1] and the samples bracketing it; -inf when it is off the terrain.
double max_height_under(const Heightfield& hf, double x0, double z0, double x1, double z1);

// One request per body that is predicted to touch the terrain within the horizon
// (bodies off the terrain or moving clear of it yield none).
std::vector<PatchRequest> predict_contacts(const Heightfield& hf, const std::vector<BodyMotion>& bodies,
                                           const Eigen::Vector3d& gravity, const LodDef& def);

// Merges overlapping requests into their bounding rectangle while the result stays within
// max_side (m) on both axes; a merged request keeps the earliest contact and fastest speed.
// The result is ordered by time to contact, then by speed (fastest first).
std::vector<PatchRequest> merge_requests(std::vector<PatchRequest> requests, double max_side);

}  // namespace sandpatch
