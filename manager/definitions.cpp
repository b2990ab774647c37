#include "manager/definitions.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "common/checker.hpp"
#include "common/knobs.hpp"
#include "common/limits.hpp"
#include "heightfield/io.hpp"
#include "heightfield/procedural.hpp"
#include "scene/mesh.hpp"

namespace sandpatch {
namespace {

using Checker = BasicChecker<Error>;

// Errors of a part (a loader, a generator) with their fields put under `prefix`.
std::vector<Error> renamed(const std::vector<Error>& es, const std::string& prefix,
                           std::initializer_list<std::pair<const char*, const char*>> rename = {}) {
  std::vector<Error> out;
  for (Error e : es) {
    bool done = false;
    for (const auto& [from, to] : rename)
      if (e.field == from) {
        e.field = to;
        done = true;
        break;
      }
    if (!done && !e.field.empty()) e.field = prefix + e.field;
    out.push_back(std::move(e));
  }
  return out;
}

bool eq_norm_positive(const api::Quat& q) {
  return double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3] > 1e-12;
}
// Normalised in double: a float quaternion of 1e30 has a float norm² of inf, which would
// normalise to [0, 0, 0, 0] (callers check finite and non-zero first).
Eigen::Quaternionf eq(const api::Quat& q) {
  const double n = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
  return Eigen::Quaternionf(float(q[0] / n), float(q[1] / n), float(q[2] / n), float(q[3] / n));
}
// A velocity's magnitude against its limit (limits.hpp), the same rule as scene files.
void speed_limit(Checker& c, const std::string& field, const api::Vec3f& v, double limit, const char* unit) {
  const double n = std::sqrt(double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2]);
  if (std::isfinite(n) && n > limit)
    c.add(field, "[" + format_number(v[0]) + ", " + format_number(v[1]) + ", " + format_number(v[2]) + "]",
          "the magnitude must be at most " + format_number(limit) + " " + unit + " (|v| = " + format_number(n) + ")");
}
Eigen::Vector3f ev(const api::Vec3f& v) { return {v[0], v[1], v[2]}; }

std::string lower_extension(const std::string& path) {
  std::string e = std::filesystem::path(path).extension().string();
  for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  return e;
}

// ".png", ".raw" or ".asc" from file_type or else the extension; "" when neither names one.
std::string file_format(const api::TerrainDef& d) {
  if (!d.file_type.empty())
    return d.file_type == "png16" ? ".png" : d.file_type == "raw_f32" ? ".raw" : d.file_type == "esri_ascii" ? ".asc" : "";
  const std::string e = lower_extension(d.file);
  return e == ".png" || e == ".raw" || e == ".asc" ? e : "";
}

}  // namespace

std::vector<Error> validate(const api::TerrainDef& d) {
  Checker c{"TerrainDef.", "", {}};
  const int sources = int(!d.heights.empty()) + int(!d.file.empty()) + int(!d.procedural.empty());
  if (sources != 1)
    c.add("heights", sources == 0 ? "(none)" : std::to_string(sources) + " sources",
          "give exactly one of heights (an array), file (a heightmap) or procedural (a generator)");
  // The heightmap's format: file_type, or the file's extension.
  const std::string ext = file_format(d);
  const bool need_grid = !d.heights.empty() || !d.procedural.empty() || (!d.file.empty() && ext == ".raw");
  if (need_grid) {
    c.knob(knobs::kSamplesX, d.samples_x);
    c.knob(knobs::kSamplesZ, d.samples_z);
    if (auto e = limits::check_grid_size("", "TerrainDef.samples_x × samples_z", d.samples_x, d.samples_z))
      c.errs.push_back({e->file, e->field, e->value, e->allowed, e->detail});
  }
  if (!d.heights.empty()) {
    const long long n = (long long)(std::max(d.samples_x, 0)) * std::max(d.samples_z, 0);
    if ((long long)d.heights.size() != n)
      c.add("heights", std::to_string(d.heights.size()) + " values",
            "must hold samples_x * samples_z = " + std::to_string(n) + " values (row-major, x fastest)");
    for (std::size_t k = 0; k < d.heights.size(); ++k)
      if (!std::isfinite(d.heights[k])) {
        c.add("heights[" + std::to_string(k) + "]", format_number(d.heights[k]), "must be finite (m)");
        break;
      }
  }
  if (!d.file_type.empty() && ext.empty())
    c.add("file_type", "\"" + d.file_type + "\"", "must be \"\" (from the file's extension), png16, raw_f32 or esri_ascii");
  else if (!d.file.empty() && ext.empty())
    c.add("file", d.file, "the extension must be .png (16-bit greyscale), .raw (float32) or .asc (ESRI ASCII grid), or give file_type");
  if (!d.procedural.empty()) {
    if (d.procedural != "flat" && d.procedural != "plane" && d.procedural != "hills" && d.procedural != "noise")
      c.add("procedural", "\"" + d.procedural + "\"", "must be one of flat, plane, hills, noise");
    c.knob(knobs::kBaseHeight, d.base_height);
    c.knob(knobs::kSlopeX, d.slope_x);
    c.knob(knobs::kSlopeZ, d.slope_z);
    c.knob(knobs::kAmplitude, d.amplitude);
    c.knob(knobs::kWavelength, d.wavelength);
    c.knob(knobs::kOctaves, d.octaves);
  }
  c.knob(knobs::kVerticalScale, d.vertical_scale);
  c.knob(knobs::kVerticalOffset, d.vertical_offset);
  c.knob(knobs::kSpacing, d.spacing);
  c.finite("origin", d.origin, "m");
  c.knob(knobs::kSoilDepth, d.soil_depth);
  c.knob(knobs::kGranuleRadius, d.material.granule_radius);
  c.knob(knobs::kDensity, d.material.density);
  c.knob(knobs::kFriction, d.material.friction);
  c.knob(knobs::kRestitution, d.material.restitution);
  c.knob(knobs::kStiffness, d.material.stiffness);
  c.knob(knobs::kTangentialRatio, d.material.tangential_stiffness_ratio);
  c.knob(knobs::kUnloadingRatio, d.material.unloading_stiffness_ratio);
  c.knob(knobs::kSlots, d.slots);
  c.knob(knobs::kGranulesPerSlot, d.granules_per_slot);
  c.knob(knobs::kShellSpheresPerSlot, d.shell_spheres_per_slot);
  if (d.granular_patches && double(d.slots) * double(d.granules_per_slot) > double(limits::kMaxPoolGranules))
    c.add("slots", std::to_string(d.slots) + " × granules_per_slot " + std::to_string(d.granules_per_slot),
          "slots × granules_per_slot must be at most " + std::to_string(limits::kMaxPoolGranules) +
              " granules (every slot is allocated at full capacity); lower slots or granules_per_slot");
  c.knob(knobs::kPatchDepth, d.patch_depth);
  if (knobs::kPatchDepth.allows(d.patch_depth) && std::isfinite(d.soil_depth) && d.patch_depth > d.soil_depth)
    c.add("patch_depth", format_number(d.patch_depth), "must be at most soil_depth (" + format_number(d.soil_depth) + " m)");
  c.knob(knobs::kParticleScale, d.particle_scale);
  c.knob(knobs::kStepsPerContact, d.steps_per_contact);
  c.knob(knobs::kMaxSubsteps, d.max_substeps);
  c.knob(knobs::kSleepSpeed, d.sleep_speed);
  c.knob(knobs::kSleepTime, d.sleep_time);
  c.knob(knobs::kRegionSleepTime, d.region_sleep_time);
  c.knob(knobs::kIdleTimeout, d.idle_timeout);
  if (d.backend != "cpu" && d.backend != "gl") c.add("backend", "\"" + d.backend + "\"", "must be cpu or gl");
  c.knob(knobs::kThreads, d.threads);
  c.knob(knobs::kLodHorizon, d.lod_horizon);
  c.knob(knobs::kLodMargin, d.lod_margin);
  c.knob(knobs::kLodApron, d.lod_apron);
  if (d.frame_budget_ms && !(*d.frame_budget_ms > 0))
    c.add("frame_budget_ms", format_number(*d.frame_budget_ms), "must be > 0 ms, +infinity for no budget, or unset for half of each step's dt");
  c.finite("gravity", d.gravity, "m/s^2");
  return c.errs;
}

Result<Heightfield> build_heightfield(const api::TerrainDef& d) {
  auto fail = [](const auto& r) { return renamed(r.errors(), "TerrainDef.", {{"kind", "TerrainDef.procedural"},
                                                                              {"height", "TerrainDef.base_height"},
                                                                              {"seed", "TerrainDef.noise_seed"},
                                                                              {"import.vertical_scale", "TerrainDef.vertical_scale"},
                                                                              {"import.vertical_offset", "TerrainDef.vertical_offset"}}); };
  HeightfieldDef g;
  g.samples_x = d.samples_x;
  g.samples_z = d.samples_z;
  g.spacing = float(d.spacing);
  g.origin_x = d.origin[0];
  g.origin_y = d.origin[1];
  g.origin_z = d.origin[2];
  if (!d.heights.empty()) {
    auto hf = Heightfield::create(g);
    if (!hf) return fail(hf);
    hf->write(hf->whole(), d.heights.data());
    return std::move(*hf);
  }
  if (!d.procedural.empty()) {
    ProceduralHeightsDef p;
    p.kind = d.procedural;
    p.height = d.base_height;
    p.slope_x = d.slope_x;
    p.slope_z = d.slope_z;
    p.amplitude = d.amplitude;
    p.wavelength = d.wavelength;
    p.seed = d.noise_seed;
    p.octaves = d.octaves;
    auto hf = make_procedural(g, p);
    if (!hf) return fail(hf);
    // The generator's heights are values like a file's: height = offset + scale · value.
    if (d.vertical_scale != 1.0 || d.vertical_offset != 0.0)
      for (int j = 0; j < hf->samples_z(); ++j)
        for (int i = 0; i < hf->samples_x(); ++i)
          hf->set_height(i, j, float(d.vertical_offset + d.vertical_scale * hf->height(i, j)));
    return std::move(*hf);
  }
  HeightmapImport im;
  im.origin_x = d.origin[0];
  im.origin_y = d.origin[1];
  im.origin_z = d.origin[2];
  im.spacing = float(d.spacing);
  im.vertical_scale = float(d.vertical_scale);
  im.vertical_offset = float(d.vertical_offset);
  im.override_spacing = d.spacing_overrides_file;
  const std::string ext = file_format(d);
  auto hf = ext == ".png"   ? load_png16(d.file, im)
            : ext == ".raw" ? load_raw_f32(d.file, d.samples_x, d.samples_z, im)
                            : load_esri_ascii(d.file, im);
  if (!hf) return fail(hf);
  return std::move(*hf);
}

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
  m.shell_particles_per_slot = def.shell_spheres_per_slot;
  m.patch_depth = def.patch_depth;
  m.soil_depth = def.soil_depth;
  m.sleep_speed = def.sleep_speed;
  m.sleep_time = def.sleep_time;
  m.region_sleep_time = def.region_sleep_time;
  m.sleep_regions = def.sleep_regions;
  m.idle_timeout = def.idle_timeout;
  m.use_gl = def.gl_depth_render;
  m.backend = def.backend;
  m.threads = def.threads;
  m.lod.horizon = def.lod_horizon;
  m.lod.margin = def.lod_margin;
  m.lod.apron = def.lod_apron;
  m.lod.travel = def.lod_travel;
  // The frame budget: unset = half of each frame's dt; +infinity = none.
  if (!def.frame_budget_ms) m.frame_budget_fraction = 0.5;
  else m.frame_budget_ms = *def.frame_budget_ms;
  m.gravity = {def.gravity[0], def.gravity[1], def.gravity[2]};
  m.seed = def.seed;
  return m;
}


Result<RigidBodyDef> rigid_body_def(const api::BodyDef& d) {
  Checker c{"BodyDef.", d.name.empty() ? "" : "body '" + d.name + "'", {}};
  const api::ShapeDef& s = d.shape;
  RigidBodyDef r;
  r.name = d.name;
  switch (s.kind) {
    case api::ShapeKind::Sphere:
      c.knob(knobs::kShapeRadius, s.radius);
      r.shape.kind = RigidShapeKind::Sphere;
      break;
    case api::ShapeKind::Box:
      for (int k = 0; k < 3; ++k) c.knob(knobs::kShapeHalfExtent, s.half_extents[k], "[" + std::to_string(k) + "]");
      r.shape.kind = RigidShapeKind::Box;
      break;
    case api::ShapeKind::Cylinder:
      c.knob(knobs::kShapeRadius, s.radius);
      c.knob(knobs::kCylinderHeight, s.height);
      r.shape.kind = RigidShapeKind::Cylinder;
      break;
    case api::ShapeKind::Capsule:
      c.knob(knobs::kShapeRadius, s.radius);
      c.knob(knobs::kCapsuleHeight, s.height);
      r.shape.kind = RigidShapeKind::Capsule;
      break;
    default:
      c.add("shape.kind", std::to_string(static_cast<int>(s.kind)), "must be a ShapeKind: Sphere, Box, Cylinder, Capsule or Mesh");
      break;
    case api::ShapeKind::Mesh: {
      r.shape.kind = RigidShapeKind::Mesh;
      if (s.mesh_file.empty() == s.vertices.empty()) {
        c.add("shape.mesh_file", s.mesh_file.empty() ? "(none)" : s.mesh_file,
              "a mesh needs exactly one of mesh_file (an OBJ) or vertices + triangles");
        break;
      }
      TriangleMesh mesh;
      if (!s.mesh_file.empty()) {
        c.knob(knobs::kMeshScale, s.mesh_scale);
        if (!c.errs.empty()) break;
        auto m = load_obj_mesh(s.mesh_file, s.mesh_scale);
        if (!m) {
          for (auto& e : renamed(m.errors(), "BodyDef.shape.")) c.errs.push_back(e);
          break;
        }
        mesh = std::move(*m);
      } else {
        if (s.vertices.size() % 3 != 0 || s.vertices.size() < 12)
          c.add("shape.vertices", std::to_string(s.vertices.size()) + " values", "must be x, y, z per vertex, at least 4 vertices");
        if (s.triangles.size() % 3 != 0 || s.triangles.size() < 12)
          c.add("shape.triangles", std::to_string(s.triangles.size()) + " values", "must be 3 indices per triangle, at least 4 triangles");
        const int nv = int(s.vertices.size() / 3);
        for (std::size_t k = 0; k < s.triangles.size(); ++k)
          if (s.triangles[k] < 0 || s.triangles[k] >= nv) {
            c.add("shape.triangles[" + std::to_string(k) + "]", std::to_string(s.triangles[k]),
                  "must be a vertex index in [0, " + std::to_string(nv - 1) + "]");
            break;
          }
        for (std::size_t k = 0; k < s.vertices.size(); ++k)
          if (!std::isfinite(s.vertices[k])) {
            c.add("shape.vertices[" + std::to_string(k) + "]", format_number(s.vertices[k]), "must be finite (m)");
            break;
          }
        if (!c.errs.empty()) break;
        for (std::size_t k = 0; k + 2 < s.vertices.size(); k += 3)
          mesh.vertices.emplace_back(s.vertices[k], s.vertices[k + 1], s.vertices[k + 2]);
        for (std::size_t k = 0; k + 2 < s.triangles.size(); k += 3)
          mesh.triangles.push_back({s.triangles[k], s.triangles[k + 1], s.triangles[k + 2]});
      }
      if (s.solid)
        for (auto& e : check_solid_mesh(mesh, s.mesh_file, "BodyDef.shape")) c.errs.push_back(e);
      if (!c.errs.empty()) break;
      const Eigen::Vector3f centre = mesh.centroid().cast<float>();  // bodies are centred on their centre of mass
      for (const auto& v : mesh.vertices) r.shape.vertices.push_back(v - centre);
      r.shape.triangles = mesh.triangles;
      break;
    }
  }
  if (d.motion != api::BodyMotion::Dynamic && d.motion != api::BodyMotion::Kinematic && d.motion != api::BodyMotion::Static)
    c.add("motion", std::to_string(static_cast<int>(d.motion)), "must be a BodyMotion: Dynamic, Kinematic or Static");
  if (d.motion == api::BodyMotion::Dynamic) c.closed("mass", d.mass, limits::kMinBodyMass, limits::kMaxBodyMass, "kg");
  c.finite("position", d.position, "m");
  c.finite("orientation", d.orientation, "");
  if (c.errs.empty() && !(eq_norm_positive(d.orientation)))
    c.add("orientation", "[0, 0, 0, 0]", "must be a non-zero quaternion [w, x, y, z]");
  c.finite("linear_velocity", d.linear_velocity, "m/s");
  c.finite("angular_velocity", d.angular_velocity, "rad/s");
  speed_limit(c, "linear_velocity", d.linear_velocity, limits::kMaxBodySpeed, "m/s");
  speed_limit(c, "angular_velocity", d.angular_velocity, limits::kMaxBodySpin, "rad/s");
  c.knob(knobs::kBodyFriction, d.friction);
  c.knob(knobs::kBodyRestitution, d.restitution);
  c.knob(knobs::kBodyRollingFriction, d.rolling_friction);
  if (!c.errs.empty()) return c.errs;

  r.shape.radius = float(s.radius);
  r.shape.height = float(s.height);
  r.shape.half_extents = {float(s.half_extents[0]), float(s.half_extents[1]), float(s.half_extents[2])};
  r.motion = d.motion == api::BodyMotion::Kinematic ? RigidMotion::Kinematic
             : d.motion == api::BodyMotion::Static  ? RigidMotion::Static
                                               : RigidMotion::Dynamic;
  r.mass = d.motion == api::BodyMotion::Dynamic ? float(d.mass) : 0.0f;
  r.position = {d.position[0], d.position[1], d.position[2]};
  r.orientation = eq(d.orientation);
  r.linear_velocity = ev(d.linear_velocity);
  r.angular_velocity = ev(d.angular_velocity);
  r.friction = float(d.friction);
  r.restitution = float(d.restitution);
  r.rolling_friction = float(d.rolling_friction);
  return r;
}

}  // namespace sandpatch
