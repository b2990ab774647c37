#include "manager/terrain_def.hpp"

namespace sandpatch {

TerrainManagerDef manager_def(const api::TerrainDef& def) {
  TerrainManagerDef m;
  m.material.radius = float(def.material.granule_radius);
  m.material.density = float(def.material.density);
  m.material.friction = float(def.material.friction);
  m.material.restitution = float(def.material.restitution);
  m.material.stiffness = float(def.material.stiffness);
  m.material.tangential_stiffness_ratio = float(def.material.tangential_stiffness_ratio);
  m.material.unloading_stiffness_ratio = float(def.material.unloading_stiffness_ratio);
  m.particle_scale = def.particle_scale;
  m.steps_per_contact = def.steps_per_contact;
  m.max_substeps = def.max_substeps;
  m.slots = def.slots;
  m.granules_per_slot = def.granules_per_slot;
  m.patch_depth = def.patch_depth;
  m.soil_depth = def.soil_depth;
  m.sleep_speed = def.sleep_speed;
  m.sleep_time = def.sleep_time;
  m.idle_timeout = def.idle_timeout;
  m.use_gl = def.gl_depth_render;
  m.backend = def.backend;
  m.threads = def.threads;
  m.lod.horizon = def.lod_horizon;
  m.lod.margin = def.lod_margin;
  m.lod.apron = def.lod_apron;
  // The frame budget: unset = half of each frame's dt; +infinity = none.
  if (!def.frame_budget_ms) m.frame_budget_fraction = 0.5;
  else m.frame_budget_ms = *def.frame_budget_ms;
  m.gravity = {def.gravity[0], def.gravity[1], def.gravity[2]};
  m.seed = def.seed;
  return m;
}

}  // namespace sandpatch
