// The one chain from the public definitions (include/sandpatch/sandpatch.hpp: TerrainDef,
// BodyDef) to what the frame is made of. Both doors come through here: the library's
// Terrain::create / add_body, and scene files, whose parser (scene/scene.hpp) fills the same
// TerrainDef and BodyDef. So a setting is validated by one rule,
// turned into the internal definition in one place, and means the same in a scene file and
// in a game.
//
// Errors name the public fields ("TerrainDef.material.stiffness", "BodyDef.shape.radius");
// the scene layer renames them to the scene file's fields.
#pragma once

#include <string>
#include <vector>

#include "common/error.hpp"
#include "heightfield/heightfield.hpp"
#include "manager/bullet_world.hpp"
#include "manager/terrain_manager.hpp"
#include "sandpatch/sandpatch.hpp"

namespace sandpatch {

// Every TerrainDef field, before anything is built.
std::vector<Error> validate(const api::TerrainDef& def);

// The heightfield a valid TerrainDef describes: its heights array, heightmap file or
// generator, then height = vertical_offset + vertical_scale · value for every source.
Result<Heightfield> build_heightfield(const api::TerrainDef& def);

// Every field TerrainDef shares with TerrainManagerDef (material, pool, scale, N, max
// substeps, depths, sleep, idle timeout, backend, threads, contact prediction, budget,
// gravity, seed; gl_depth_render → use_gl). What only scene files have (scale bands, a flat
// bedrock) the scene layer adds after.
TerrainManagerDef manager_def(const api::TerrainDef& def);

// A BodyDef validated (every field, the mesh loaded and checked) and turned into Bullet's
// body definition. Quaternions: [w, x, y, z] in the public definitions; Eigen's named
// components inside (its storage, like Bullet's and the DEM's packed fields, is x, y, z, w).
Result<RigidBodyDef> rigid_body_def(const api::BodyDef& def);

}  // namespace sandpatch
