// Scene files' terrain section: the heightfield's source, grid, vertical scale, origin and
// depths (see scene_terrain.hpp, docs/scene-format.md "terrain").
#include "scene/scene_terrain.hpp"

#include <algorithm>
#include <cmath>

#include "common/knobs.hpp"
#include "common/limits.hpp"

namespace sandpatch {

namespace {
const std::vector<std::string> kSourceTypes = {"png16", "raw_f32", "esri_ascii", "procedural"};
const std::vector<std::string> kProceduralKinds = {"flat", "plane", "hills", "noise"};
}  // namespace

const char* to_string(TerrainSourceKind k) { return kSourceTypes[static_cast<int>(k)].c_str(); }
const char* to_string(ProceduralKind k) { return kProceduralKinds[static_cast<int>(k)].c_str(); }

TerrainSourceKind TerrainDef::source_kind() const {
  if (!procedural.empty()) return TerrainSourceKind::Procedural;
  return file_type == "raw_f32" ? TerrainSourceKind::RawF32 : file_type == "esri_ascii" ? TerrainSourceKind::EsriAscii : TerrainSourceKind::Png16;
}

std::array<double, 2> TerrainDef::spacing_xz(int nx, int nz) const {
  if (size) return {(*size)[0] / std::max(1, nx - 1), (*size)[1] / std::max(1, nz - 1)};
  return {spacing, spacing};
}

namespace scene_json {

// The terrain section into the library's fields of `t` (scene.hpp TerrainDef).
void parse_terrain(Ctx& c, const json& j, TerrainDef& t) {
  Obj o(c, j, "terrain");
  TerrainSourceKind kind = TerrainSourceKind::Procedural;
  if (const json* src = o.require("source", "an object with \"type\": " + join(kSourceTypes, " | "))) {
    Obj s(c, *src, o.at("source"));
    if (s.enumeration_req("type", kind, kSourceTypes) && s.valid()) {
      if (kind == TerrainSourceKind::Procedural) {
        // The generator's parameters, as the library takes them (float).
        auto number_f = [&](const char* key, float& out, const Range& r) {
          double v = out;
          s.number(key, v, r);
          out = float(v);
        };
        ProceduralKind pk = ProceduralKind::Flat;
        s.enumeration("kind", pk, kProceduralKinds);
        t.procedural = to_string(pk);
        number_f("height", t.base_height, range_of(knobs::kBaseHeight));
        number_f("slope_x", t.slope_x, range_of(knobs::kSlopeX));
        number_f("slope_z", t.slope_z, range_of(knobs::kSlopeZ));
        number_f("amplitude", t.amplitude, range_of(knobs::kAmplitude));
        number_f("wavelength", t.wavelength, range_of(knobs::kWavelength));
        if (const json* v = s.get("seed")) {
          if (auto x = read_integer(c, *v, s.at("seed"), 0, 4294967295.0)) t.noise_seed = static_cast<std::uint32_t>(*x);
        }
        s.knob("octaves", t.octaves, knobs::kOctaves);
        t.samples_x = t.samples_z = 129;
        s.knob("samples_x", t.samples_x, knobs::kSamplesX);
        s.knob("samples_z", t.samples_z, knobs::kSamplesZ);
        if (auto e = limits::check_grid_size(c.file, s.at("samples_x") + " × samples_z", t.samples_x, t.samples_z))
          c.errors.push_back(*e);
      } else {
        t.file_type = to_string(kind);
        std::string written;
        const bool raw = kind == TerrainSourceKind::RawF32;
        bool dims = true;
        if (raw) {
          dims = s.integer_req("samples_x", t.samples_x, knobs::kSamplesX.lo, knobs::kSamplesX.hi) &
                 s.integer_req("samples_z", t.samples_z, knobs::kSamplesZ.lo, knobs::kSamplesZ.hi);
          if (dims) {
            if (auto e = limits::check_grid_size(c.file, s.at("samples_x") + " × samples_z", t.samples_x, t.samples_z)) {
              c.errors.push_back(*e);
              dims = false;
            }
          }
        }
        if (s.string_req("file", written, "the heightmap's path")) {
          t.file = resolve(c, written);
          const std::string field = s.at("file");
          if (check_readable(c, field, written, t.file, "heightmap")) {
            if (kind == TerrainSourceKind::Png16) check_png16(c, field, written, t.file);
            if (raw && dims) check_raw_f32(c, field, written, t.file, t.samples_x, t.samples_z);
            if (kind == TerrainSourceKind::EsriAscii) check_esri_ascii(c, field, written, t.file);
          }
        }
      }
    }
    s.finish();
  }
  if (!o.both("spacing", "size")) {
    // An esri_ascii grid has its own cellsize: a spacing given overrides it.
    t.spacing_overrides_file = kind == TerrainSourceKind::EsriAscii && o.has("spacing");
    o.knob("spacing", t.spacing, knobs::kSpacing);
    if (const json* v = o.get("size")) {
      if (auto sz = read_numbers<2>(c, *v, o.at("size"), positive(1e7, "m"))) t.size = *sz;
    }
  }
  if (t.size && kind == TerrainSourceKind::Procedural) {
    // The grid has one spacing: size must give square cells for the generator's sample count.
    const auto sp = t.spacing_xz(t.samples_x, t.samples_z);
    if (std::abs(sp[0] - sp[1]) > 1e-9 * std::max(sp[0], sp[1])) {
      c.error(o.at("size"), show(*o.get("size")), "must give square cells: size[0] / (samples_x - 1) = size[1] / (samples_z - 1)",
              "spacing would be " + fmt_num(sp[0]) + " m in x and " + fmt_num(sp[1]) + " m in z");
    }
  }
  o.knob("vertical_scale", t.vertical_scale, knobs::kVerticalScale);
  o.knob("vertical_offset", t.vertical_offset, knobs::kVerticalOffset);
  o.vec3("origin", t.origin, kWorldCoord);
  std::optional<double> soil;
  if (!o.both("soil_depth", "bedrock_height")) {
    soil = o.number_opt("soil_depth", positive(1e4, "m"));
    t.bedrock_height = o.number_opt("bedrock_height", closed(-1e6, 1e6, "m"));
  }
  if (!soil && !t.bedrock_height && !o.has("soil_depth") && !o.has("bedrock_height")) soil = knobs::kSoilDepth.def;
  // With a flat bedrock the library's soil_depth keeps its default (the patches take the bedrock).
  t.soil_depth = soil.value_or(knobs::kSoilDepth.def);
  // patch_depth: given, at most the soil depth; left out, the default or the soil depth if less.
  if (o.has("patch_depth")) {
    o.knob("patch_depth", t.patch_depth, knobs::kPatchDepth);
    if (soil && t.patch_depth > *soil)
      c.error(o.at("patch_depth"), fmt_num(t.patch_depth), "must be at most terrain.soil_depth (" + fmt_num(*soil) + " m)");
  } else if (soil) {
    t.patch_depth = std::min(t.patch_depth, *soil);
  }
  o.string("material", t.material_name);
  o.finish();
}

}  // namespace scene_json
}  // namespace sandpatch
