// The one place where the public terrain settings (include/sandpatch/sandpatch.hpp's
// TerrainDef, the library's door) become the terrain manager's internal definition. A scene
// file is read into a TerrainDef first (manager/scene_world.cpp), so both doors go through here.
#pragma once

#include "manager/terrain_manager.hpp"
#include "sandpatch/sandpatch.hpp"

namespace sandpatch {

// Every field TerrainDef shares with TerrainManagerDef (material, pool, scale, N, max
// substeps, depths, sleep, idle timeout, backend, threads, contact prediction, gravity, seed;
// gl_depth_render → use_gl). What only scene files have (scale bands, a flat bedrock) the
// scene's door adds after.
TerrainManagerDef manager_def(const api::TerrainDef& def);

}  // namespace sandpatch
