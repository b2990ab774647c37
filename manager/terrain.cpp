#include "manager/terrain.hpp"

#include <cmath>
#include <string>
#include <vector>

#include "manager/definitions.hpp"
#include "manager/scene_world.hpp"

namespace sandpatch {
namespace {


// Re-grids `hf` to another (square) spacing, keeping the samples: used when the scene gives
// the terrain's size instead of its spacing, which is only known after the file is read.
Result<Heightfield> with_spacing(const Heightfield& hf, float spacing) {
  HeightfieldDef d;
  d.samples_x = hf.samples_x();
  d.samples_z = hf.samples_z();
  d.spacing = spacing;
  d.origin_x = hf.origin_x();
  d.origin_y = hf.origin_y();
  d.origin_z = hf.origin_z();
  d.tile_cells = hf.tile_cells();
  auto out = Heightfield::create(d);
  if (!out) return out.errors();
  std::vector<float> rows(std::size_t(d.samples_x) * d.samples_z);
  const GridRegion all{0, 0, d.samples_x, d.samples_z};
  hf.read(all, rows.data());
  out->write(all, rows.data());
  return out;
}

}  // namespace

Result<Heightfield> load_scene_terrain(const SceneDef& scene) {
  const TerrainDef& t = scene.terrain;
  // The library's heightfield builder, on the scene's terrain as a TerrainDef (one chain).
  Result<Heightfield> hf = build_heightfield(terrain_def(scene, 0, "cpu"));
  if (!hf) {
    // Heightfield errors name the heightmap file; add the scene field they came from.
    std::vector<Error> errs = hf.errors();
    for (Error& e : errs) {
      if (e.field.starts_with("TerrainDef.")) e.field = e.field.substr(11);
      if (e.field.empty()) e.field = "terrain.source";
      else if (e.field.rfind("terrain", 0) != 0) e.field = "terrain.source (" + e.field + ")";
      if (e.file.empty()) e.file = scene.source_path;
    }
    return errs;
  }
  if (t.size && t.source_kind() != TerrainSourceKind::Procedural) {
    const auto sp = t.spacing_xz(hf->samples_x(), hf->samples_z());
    if (std::abs(sp[0] - sp[1]) > 1e-6 * sp[0]) {
      return Error{scene.source_path, "terrain.size",
                   "[" + std::to_string((*t.size)[0]) + ", " + std::to_string((*t.size)[1]) + "]",
                   "must give square cells for a " + std::to_string(hf->samples_x()) + " x " +
                       std::to_string(hf->samples_z()) + " sample heightmap (spacing x " + std::to_string(sp[0]) +
                       " m vs z " + std::to_string(sp[1]) + " m)"};
    }
    return with_spacing(*hf, float(sp[0]));
  }
  return hf;
}

double bedrock_world_height(const SceneDef& scene, const Heightfield& hf, double x, double z) {
  const TerrainDef& t = scene.terrain;
  if (t.bedrock_height) return t.origin[1] + *t.bedrock_height;
  const double surface = hf.origin_y() + hf.sample(float(x - hf.origin_x()), float(z - hf.origin_z()));
  return surface - t.soil_depth;
}

}  // namespace sandpatch
