// Scene files: parsing and validation (see scene.hpp and docs/scene-format.md).
//
// Outline: the text is parsed into a JSON DOM by nlohmann's SAX parser through a small
// handler that also records duplicate keys with their path; numbers that overflow a double
// (1e999) are turned into marked strings and the text re-parsed, so that they become field
// errors instead of stopping the parse. The DOM is then walked section by section with
// readers that check type, range and presence, remember which keys each object was asked
// for (the rest are unknown keys, reported with a "did you mean"), and append every
// problem to one error list. Cross references and file contents are checked last; the
// scene is returned only when the list is empty.
#include "scene/scene.hpp"

#include "particles/material.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>
#include <tuple>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "common/hash.hpp"
#include "common/limits.hpp"
#include "scene/json_reader.hpp"
#include "scene/scene_joints.hpp"
#include "scene/scene_terrain.hpp"
#include "scene/mesh.hpp"

namespace sandpatch {
namespace {

using namespace scene_json;
namespace fs = std::filesystem;
using json = nlohmann::json;

// ---------------------------------------------------------------------------------------
// Sections

const std::vector<std::string> kShapeKinds = {"sphere", "box", "cylinder", "capsule", "mesh"};
const std::vector<std::string> kBackends = {"cpu", "gl"};
const std::vector<std::string> kLoadFrames = {"world", "body"};
const std::vector<std::string> kBodyMotions = {"dynamic", "kinematic", "static"};
const std::vector<std::string> kHeightfieldFormats = {"png16", "raw_f32", "esri_ascii"};

MaterialDef parse_material(Ctx& c, const json& j, const std::string& path) {
  MaterialDef m;
  Obj o(c, j, path);
  o.string_req("name", m.name, "a unique name");
  o.knob("density", m.density, knobs::kDensity);
  o.knob("friction", m.friction, knobs::kFriction);
  if (!o.both("restitution", "damping_ratio")) {
    const bool given = o.has("restitution") || o.has("damping_ratio");
    const auto e = o.number_opt("restitution", range_of(knobs::kRestitution));
    m.damping_ratio = o.number_opt("damping_ratio", {0.0, 100.0, false, false, ""});
    // The library takes e; ζ given gives e through the contact law (particles/material.hpp).
    if (e) m.restitution = *e;
    else if (m.damping_ratio) m.restitution = clamped_restitution(*m.damping_ratio);
    if (!given && o.valid()) c.missing(o.at("restitution"), "one of 'restitution' (e in (0, 1]) or 'damping_ratio' (ζ in [0, 100])");
  }
  o.knob("stiffness", m.stiffness, knobs::kStiffness);
  o.knob("tangential_stiffness_ratio", m.tangential_stiffness_ratio, knobs::kTangentialRatio);
  o.knob("unloading_stiffness_ratio", m.unloading_stiffness_ratio, knobs::kUnloadingRatio);
  o.knob("granule_radius", m.granule_radius, knobs::kGranuleRadius);
  o.number("packing_fraction", m.packing_fraction, {0.0, 0.74, true, false, ""});
  o.finish();
  return m;
}

// The library's float quaternion and vectors from the file's doubles (as the library takes them).
api::Quat to_quat(const std::array<double, 4>& q) { return {float(q[0]), float(q[1]), float(q[2]), float(q[3])}; }
api::Vec3f to_vec3f(const Vec3d& v) { return {float(v[0]), float(v[1]), float(v[2])}; }

// Quaternion [w, x, y, z] from extrinsic x-y-z Euler angles in degrees: R = Rz(γ)·Ry(β)·Rx(α).
std::array<double, 4> euler_deg_to_quaternion(const Vec3d& e) {
  const double d = kPi / 180.0;
  const Eigen::Quaterniond q = Eigen::AngleAxisd(e[2] * d, Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(e[1] * d, Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(e[0] * d, Eigen::Vector3d::UnitX());
  return {q.w(), q.x(), q.y(), q.z()};
}

// The mesh of a body's shape if it loads (errors added to `c` otherwise).
std::optional<TriangleMesh> load_body_mesh(Ctx& c, BodyDef& b, const std::string& field, const std::string& written) {
  const api::ShapeDef& s = b.shape;
  auto r = load_obj_mesh(s.mesh_file, s.mesh_scale);
  if (!r) {
    for (const auto& e : r.errors()) {
      c.error(field, json_quote(written), e.allowed.empty() ? "must be a readable Wavefront OBJ file" : "must be " + e.allowed,
              e.file + (e.field.empty() ? "" : ", " + e.field) + (e.value.empty() ? "" : " (" + e.value + ")") + ": " + e.detail);
    }
    return std::nullopt;
  }
  if (s.solid) {
    const auto errs = check_solid_mesh(*r, s.mesh_file, field);
    for (const auto& e : errs) c.error(field, json_quote(written), "must be " + e.allowed + " for a solid body", e.file + ": " + e.detail);
    if (!errs.empty()) return std::nullopt;
    b.mesh_volume = r->signed_volume();
  }
  return std::move(r).value();
}

double lowest_offset(const BodyDef& b, const TriangleMesh* mesh);

// One of a body's loads (docs/scene-format.md "loads").
LoadDef parse_load(Ctx& c, const json& j, const std::string& path) {
  LoadDef l;
  Obj o(c, j, path);
  // A vector no longer than kMaxLoad (the API's limit on |force| and |torque|).
  auto bounded = [&](const char* key, Vec3d& out, const char* unit) {
    Vec3d v = out;
    o.vec3(key, v, closed(-kMaxLoad, kMaxLoad, unit));
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (n > kMaxLoad)
      c.error(o.at(key), show(*o.get(key)), "its magnitude must be at most " + fmt_num(kMaxLoad) + " " + unit,
              "|" + std::string(key) + "| = " + fmt_num(n));
    else
      out = v;
  };
  bounded("force", l.force, "N");
  bounded("torque", l.torque, "N m");
  if (o.has("impulse")) {
    Vec3d j{0.0, 0.0, 0.0};
    bounded("impulse", j, "N s");
    l.impulse = j;
    // An impulse is given once: a load is one or the other.
    for (const char* other : {"force", "torque", "until"})
      if (o.has(other))
        c.error(o.at(other), show(*o.get(other)),
                "leave it out beside 'impulse': an impulse is given once, at 'from'; put a force or torque in a load of its own");
  }
  if (const json* a = o.get("at")) {
    if (auto v = read_numbers<3>(c, *a, o.at("at"), closed(-1e4, 1e4, "m"))) l.at = *v;
    if (!o.has("force") && !o.has("impulse"))
      c.error(o.at("at"), show(*a), "'at' is where the force or impulse acts: give 'force' or 'impulse' too");
    else if (l.at && l.impulse && std::sqrt((*l.at)[0] * (*l.at)[0] + (*l.at)[1] * (*l.at)[1] + (*l.at)[2] * (*l.at)[2]) > 1e4)
      c.error(o.at("at"), show(*a), "an impulse's point must be within 10000 m of the centre of mass (World::kMaxArm)");
  }
  o.number("from", l.from, closed(0.0, 1e6, "s"));
  l.until = o.number_opt("until", positive(1e6, "s"));
  if (l.until && !(*l.until > l.from))
    c.error(o.at("until"), show(*o.get("until")), "must be greater than 'from' (" + fmt_num(l.from) + " s)",
            "a load acts for from <= t < until");
  o.enumeration("frame", l.frame, kLoadFrames);
  if (o.valid() && !o.has("force") && !o.has("torque") && !o.has("impulse"))
    c.missing(o.at("force"), "'force' (N), 'torque' (N m) or both, or 'impulse' (N s)");
  o.finish();
  return l;
}

// "orientation" (a unit quaternion) or "euler_deg" of object `p` into q. `float_unit`: a
// quaternion already unit to float precision (|q| within 1e-6 of 1, as scene_to_json writes a
// body's float orientation back) is kept as written, so that it reads back the same floats.
void parse_orientation(Ctx& c, Obj& p, std::array<double, 4>& q_out, bool float_unit = false) {
  if (p.both("orientation", "euler_deg")) return;
  if (const json* q = p.get("orientation")) {
    if (auto v = read_numbers<4>(c, *q, p.at("orientation"), closed(-1.0 - 1e-3, 1.0 + 1e-3, ""))) {
      const double n = std::sqrt((*v)[0] * (*v)[0] + (*v)[1] * (*v)[1] + (*v)[2] * (*v)[2] + (*v)[3] * (*v)[3]);
      if (std::abs(n - 1.0) > 1e-3) {
        c.error(p.at("orientation"), show(*q), "must be a unit quaternion [w, x, y, z] (|q| = 1 ± 0.001)",
                "|q| = " + fmt_num(n));
      } else {
        const double k = float_unit && std::abs(n - 1.0) <= 1e-6 ? 1.0 : n;
        q_out = {(*v)[0] / k, (*v)[1] / k, (*v)[2] / k, (*v)[3] / k};
      }
    }
  }
  if (const json* e = p.get("euler_deg")) {
    if (auto v = read_numbers<3>(c, *e, p.at("euler_deg"), closed(-720.0, 720.0, "deg"))) q_out = euler_deg_to_quaternion(*v);
  }
}

// One keyframe of a kinematic body (docs/scene-format.md "keyframes").
KeyframeDef parse_keyframe(Ctx& c, const json& j, const std::string& path) {
  KeyframeDef k;
  Obj o(c, j, path);
  o.number_req("t", k.t, closed(0.0, 1e6, "s"));
  o.vec3_req("position", k.position, kWorldCoord);
  parse_orientation(c, o, k.orientation);
  o.finish();
  return k;
}

BodyDef parse_body(Ctx& c, const json& j, const std::string& path, std::optional<TriangleMesh>& mesh) {
  BodyDef b;
  Obj o(c, j, path);
  o.string_req("name", b.name, "a unique name");
  o.enumeration("motion", b.motion, kBodyMotions);
  const bool dynamic = b.motion == MotionKind::Dynamic;
  if (const json* sj = o.require("shape", "an object with \"type\": " + join(kShapeKinds, " | "))) {
    Obj s(c, *sj, o.at("shape"));
    auto& sh = b.shape;
    if (s.enumeration_req("type", sh.kind, kShapeKinds) && s.valid()) {
      switch (sh.kind) {
        case ShapeKind::Sphere: s.number_req("radius", sh.radius, range_of(knobs::kShapeRadius)); break;
        case ShapeKind::Box: s.vec3_req("half_extents", sh.half_extents, range_of(knobs::kShapeHalfExtent)); break;
        case ShapeKind::Cylinder:
          s.number_req("radius", sh.radius, range_of(knobs::kShapeRadius));
          s.number_req("height", sh.height, range_of(knobs::kCylinderHeight));
          break;
        case ShapeKind::Capsule:
          s.number_req("radius", sh.radius, range_of(knobs::kShapeRadius));
          s.number_req("height", sh.height, range_of(knobs::kCapsuleHeight));
          break;
        case ShapeKind::Mesh: {
          bool scale_ok = true;
          if (const json* v = s.get("scale")) {
            const auto x = read_number(c, *v, s.at("scale"), range_of(knobs::kMeshScale));
            if (x) sh.mesh_scale = *x;
            scale_ok = x.has_value();
          }
          s.boolean("solid", sh.solid);
          std::string written;
          if (s.string_req("file", written, "the OBJ file's path")) {
            sh.mesh_file = resolve(c, written);
            if (check_readable(c, s.at("file"), written, sh.mesh_file, "OBJ file") && scale_ok) {
              mesh = load_body_mesh(c, b, s.at("file"), written);
            }
          }
          break;
        }
      }
    }
    s.finish();
  }
  if (!dynamic) {
    // Nothing moves a kinematic or static body: it has no mass to give.
    for (const char* key : {"mass", "density"})
      if (o.has(key))
        c.error(o.at(key), show(*o.get(key)),
                "leave it out: a " + std::string(to_string(b.motion)) + " body has no mass (nothing moves it)");
  } else if (!o.both("mass", "density")) {
    const bool given = o.has("mass") || o.has("density");
    const auto mass = o.number_opt("mass", positive(1e9, "kg"));
    b.density = o.number_opt("density", positive(1e5, "kg/m^3"));
    if (!given && o.valid()) c.missing(o.at("mass"), "one of 'mass' (kg) or 'density' (kg/m^3)");
    // The library takes the mass: given, or density × the shape's volume.
    b.mass = mass ? *mass : b.density.value_or(0.0) * b.volume();
    // The mass run gives Bullet (a float): a tiny shape or density must not make it 0.
    const bool shape_known = b.shape.kind != ShapeKind::Mesh || b.mesh_volume > 0;
    if (b.density && shape_known && o.valid()) {
      const double m = b.mass;
      if (!(m >= limits::kMinBodyMass && m <= limits::kMaxBodyMass))
        c.error(o.at("density"), show(*o.get("density")),
                "density × shape volume must give a mass in [" + fmt_num(limits::kMinBodyMass) + ", " +
                    fmt_num(limits::kMaxBodyMass) + "] kg",
                "mass = " + fmt_num(m) + " kg (volume " + fmt_num(b.volume()) + " m^3)");
    }
    if (mass && *mass < limits::kMinBodyMass)
      c.error(o.at("mass"), show(*o.get("mass")), "must be in [" + fmt_num(limits::kMinBodyMass) + ", " +
                                                      fmt_num(limits::kMaxBodyMass) + "] kg");
    if (o.has("density") && b.shape.kind == ShapeKind::Mesh && !b.shape.solid) {
      c.error(o.at("density"), show(*o.get("density")), "give 'mass' for a mesh with \"solid\": false",
              "an open surface has no volume");
    }
  }
  if (const json* pj = o.get("pose")) {
    Obj p(c, *pj, o.at("pose"));
    p.vec3("position", b.position, kWorldCoord);
    std::array<double, 4> q = {1.0, 0.0, 0.0, 0.0};
    parse_orientation(c, p, q, /*float_unit=*/true);
    b.orientation = to_quat(q);
    p.finish();
  }
  Vec3d linear = {0.0, 0.0, 0.0}, angular = {0.0, 0.0, 0.0};
  o.vec3("linear_velocity", linear, closed(-limits::kMaxBodySpeed, limits::kMaxBodySpeed, "m/s"));
  o.vec3("angular_velocity", angular, closed(-limits::kMaxBodySpin, limits::kMaxBodySpin, "rad/s"));
  // The limits are on the magnitudes (common/limits.hpp), as in the library.
  for (const auto& [key, v, limit, unit] : {std::tuple{"linear_velocity", linear, limits::kMaxBodySpeed, "m/s"},
                                            std::tuple{"angular_velocity", angular, limits::kMaxBodySpin, "rad/s"}}) {
    const double n = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    if (n > limit)
      c.error(o.at(key), show(*o.get(key)), "the magnitude must be at most " + fmt_num(limit) + " " + unit,
              "|v| = " + fmt_num(n) + " " + unit);
  }
  b.linear_velocity = to_vec3f(linear);
  b.angular_velocity = to_vec3f(angular);
  o.number("spawn_time", b.spawn_time, closed(0.0, 1e6, "s"));
  o.knob("friction", b.friction, knobs::kBodyFriction);
  o.knob("restitution", b.restitution, knobs::kBodyRestitution);
  o.knob("rolling_friction", b.rolling_friction, knobs::kBodyRollingFriction);
  if (const json* kj = o.get("keyframes")) {
    if (b.motion != MotionKind::Kinematic) {
      c.error(o.at("keyframes"), "keyframes", "only a kinematic body follows keyframes (\"motion\": \"kinematic\")",
              "this body is " + std::string(to_string(b.motion)));
    } else if (kj->is_array() && (kj->empty() || kj->size() > std::size_t(kMaxKeyframesPerBody))) {
      c.error(o.at("keyframes"), std::to_string(kj->size()) + " keyframes",
              "must hold 1 to " + std::to_string(kMaxKeyframesPerBody) + " keyframes");
    } else {
      for_each_element(c, *kj, o.at("keyframes"),
                       [&](const json& e, const std::string& p) { b.keyframes.push_back(parse_keyframe(c, e, p)); });
      for (std::size_t k = 1; k < b.keyframes.size(); ++k)
        if (!(b.keyframes[k].t > b.keyframes[k - 1].t))
          c.error(o.at("keyframes") + "[" + std::to_string(k) + "].t", fmt_num(b.keyframes[k].t),
                  "must be greater than the keyframe before it (" + fmt_num(b.keyframes[k - 1].t) +
                      " s): times strictly increasing");
      if (o.has("pose"))
        c.error(o.at("pose"), show(*o.get("pose")), "leave it out: a body with keyframes starts at their pose",
                "its pose at spawn_time is the keyframes'");
    }
  }
  if (b.motion == MotionKind::Static) {
    for (const char* key : {"linear_velocity", "angular_velocity"})
      if (o.has(key) && o.valid() && (key[0] == 'l' ? b.linear_velocity : b.angular_velocity) != api::Vec3f{0.0f, 0.0f, 0.0f})
        c.error(o.at(key), show(*o.get(key)), "must be [0, 0, 0] or left out: a static body never moves");
  }
  if (!dynamic && o.has("loads"))
    c.error(o.at("loads"), show(*o.get("loads")), "leave it out: loads move only a dynamic body",
            "this body is " + std::string(to_string(b.motion)) + (b.motion == MotionKind::Kinematic ? "; give it keyframes" : ""));
  else if (const json* lj = o.get("loads")) {
    if (lj->is_array() && lj->size() > std::size_t(kMaxLoadsPerBody))
      c.error(o.at("loads"), std::to_string(lj->size()) + " loads", "at most " + std::to_string(kMaxLoadsPerBody) + " loads per body");
    else
      for_each_element(c, *lj, o.at("loads"), [&](const json& e, const std::string& p) { b.loads.push_back(parse_load(c, e, p)); });
  }
  if (!b.keyframes.empty()) {  // the pose at spawn_time: the keyframes', as the run places it
    const auto& ks = b.keyframes;
    std::size_t k = 0;
    while (k + 1 < ks.size() && ks[k + 1].t <= b.spawn_time) ++k;
    const KeyframeDef& a = ks[k];
    b.position = a.position;
    b.orientation = to_quat(a.orientation);
    if (k + 1 < ks.size() && b.spawn_time > a.t) {
      const KeyframeDef& n = ks[k + 1];
      const double u = (b.spawn_time - a.t) / (n.t - a.t);
      for (int i = 0; i < 3; ++i) b.position[i] = a.position[i] + u * (n.position[i] - a.position[i]);
      const Eigen::Quaterniond qa(a.orientation[0], a.orientation[1], a.orientation[2], a.orientation[3]);
      const Eigen::Quaterniond qn(n.orientation[0], n.orientation[1], n.orientation[2], n.orientation[3]);
      const Eigen::Quaterniond q = qa.slerp(u, qn);
      b.orientation = to_quat({q.w(), q.x(), q.y(), q.z()});
    }
  }
  o.finish();
  return b;
}

// The simulation section: its knobs into the library's fields of `t` (scene.hpp TerrainDef),
// the rest into `s`.
void parse_simulation(Ctx& c, const json& j, TerrainDef& t, SceneSimulationDef& s) {
  Obj o(c, j, "simulation");
  // A preset first: the fields below override it.
  if (const json* pj = o.get("preset")) {
    std::vector<std::string> names;
    for (const auto& p : simulation_presets()) names.push_back(p.name);
    if (auto x = read_enum(c, *pj, o.at("preset"), names)) {
      const SimulationPreset& p = simulation_presets()[std::size_t(*x)];
      s.preset = p.name;
      t.particle_scale = p.particle_scale;
      t.granules_per_slot = p.granules_per_slot;
      t.steps_per_contact = p.steps_per_contact;
    }
  }
  o.number("dt", s.dt, {0.0, 0.1, true, false, "s"});
  o.integer("substeps", s.substeps, 1, 1000);
  o.number("duration", s.duration, positive(1e6, "s"));
  if (std::ceil(s.duration / s.dt - 1e-9) > kMaxRunFrames)
    c.error(o.at("duration"), fmt_num(s.duration),
            "simulation.duration / simulation.dt must be at most " + fmt_num(kMaxRunFrames) + " steps",
            "dt = " + fmt_num(s.dt) + " s gives " + fmt_num(std::ceil(s.duration / s.dt)) + " steps");
  Backend backend = Backend::Cpu;
  o.enumeration("backend", backend, kBackends);
  t.backend = to_string(backend);
  o.knob("threads", t.threads, knobs::kThreads);
  if (const json* pj = o.get("pool")) {
    Obj p(c, *pj, o.at("pool"));
    p.knob("slots", t.slots, knobs::kSlots);
    p.knob("granules_per_slot", t.granules_per_slot, knobs::kGranulesPerSlot);
    p.knob("shell_spheres_per_slot", t.shell_spheres_per_slot, knobs::kShellSpheresPerSlot);
    if (double(t.slots) * t.granules_per_slot > double(limits::kMaxPoolGranules))
      c.error(p.at("slots"), std::to_string(t.slots) + " × granules_per_slot " + std::to_string(t.granules_per_slot),
              "slots × granules_per_slot must be at most " + std::to_string(limits::kMaxPoolGranules) +
                  " granules (every slot is allocated at full capacity)",
              "lower slots or granules_per_slot");
    p.finish();
  }
  o.knob("particle_scale", t.particle_scale, knobs::kParticleScale);
  o.knob("steps_per_contact", t.steps_per_contact, knobs::kStepsPerContact);
  o.knob("max_substeps", t.max_substeps, knobs::kMaxSubsteps);
  if (const json* bj = o.get("frame_budget_ms")) {
    if (bj->is_string() && bj->get<std::string>() == "off") {
      t.frame_budget_ms = std::numeric_limits<double>::infinity();
    } else if (bj->is_string()) {
      c.error(o.at("frame_budget_ms"), show(*bj), "must be a number of ms in (0, 1e+06] or \"off\"");
    } else if (auto x = read_number(c, *bj, o.at("frame_budget_ms"), {0.0, 1e6, true, false, "ms"})) {
      t.frame_budget_ms = *x;
    }
  }
  if (const json* lj = o.get("lod")) {
    Obj p(c, *lj, o.at("lod"));
    p.knob("horizon", t.lod_horizon, knobs::kLodHorizon);
    p.knob("margin", t.lod_margin, knobs::kLodMargin);
    p.knob("apron", t.lod_apron, knobs::kLodApron);
    p.boolean("travel", t.lod_travel);
    p.finish();
  }
  if (const json* bj = o.get("scale_by_distance")) {
    Obj p(c, *bj, o.at("scale_by_distance"));
    ScaleByDistanceDef d;
    p.string_req("camera", d.camera, "the name of a camera in cameras");
    if (const json* arr = p.require("bands", "an array of 1 to 16 objects {\"max_distance\", \"particle_scale\"}")) {
      if (arr->is_array() && (arr->empty() || arr->size() > 16)) {
        c.error(p.at("bands"), show(*arr), "must hold 1 to 16 bands", "got " + std::to_string(arr->size()));
      } else {
        for_each_element(c, *arr, p.at("bands"), [&](const json& e, const std::string& path) {
          ScaleBandDef band;
          Obj bo(c, e, path);
          const bool ok = bo.number_req("max_distance", band.max_distance, positive(1e7, "m"));
          bo.number_req("particle_scale", band.particle_scale, closed(1e-3, 1e3, ""));
          bo.finish();
          if (ok && !d.bands.empty() && band.max_distance <= d.bands.back().max_distance)
            c.error(bo.at("max_distance"), fmt_num(band.max_distance), "must be greater than the previous band's",
                    "follows " + fmt_num(d.bands.back().max_distance) + " m");
          d.bands.push_back(band);
        });
      }
    }
    p.finish();
    s.scale_by_distance = d;
  }
  if (const json* sj = o.get("sleep")) {
    Obj p(c, *sj, o.at("sleep"));
    p.knob("speed_threshold", t.sleep_speed, knobs::kSleepSpeed);
    p.knob("hold_time", t.sleep_time, knobs::kSleepTime);
    p.knob("region_hold_time", t.region_sleep_time, knobs::kRegionSleepTime);
    p.boolean("regions", t.sleep_regions);
    p.finish();
  }
  o.knob("idle_timeout", t.idle_timeout, knobs::kIdleTimeout);
  o.boolean("granular_patches", t.granular_patches);
  o.vec3("gravity", t.gravity, closed(-1e3, 1e3, "m/s^2"));
  o.u64("seed", t.seed);
  o.finish();
}

CameraDef parse_camera(Ctx& c, const json& j, const std::string& path) {
  CameraDef cam;
  Obj o(c, j, path);
  o.string_req("name", cam.name, "a unique name");
  const auto check_view = [&](const Vec3d& pos, const Vec3d& tgt, const std::string& field, const json& v) {
    if (pos == tgt) c.error(field, show(v), "must differ from the position", "the camera has no view direction");
  };
  if (const json* pj = o.get("path")) {
    if (o.has("position") || o.has("target")) {
      c.error(o.at("path"), show(*pj), "give either 'path' or 'position' and 'target'", "both are given");
    }
    for_each_element(c, *pj, o.at("path"), [&](const json& e, const std::string& p) {
      CameraKeyDef k;
      Obj ko(c, e, p);
      const bool t_ok = ko.number_req("time", k.time, range_of(knobs::kCameraKeyTime));
      const bool v_ok = ko.vec3_req("position", k.position, kWorldCoord) & ko.vec3_req("target", k.target, kWorldCoord);
      ko.finish();
      if (t_ok && !cam.path.empty() && k.time <= cam.path.back().time) {
        c.error(ko.at("time"), show(e["time"]), "keyframe times must be strictly ascending",
                "follows " + fmt_num(cam.path.back().time));
      }
      if (v_ok) check_view(k.position, k.target, ko.at("target"), e["target"]);
      cam.path.push_back(k);
    });
    if (pj->is_array() && pj->empty()) c.error(o.at("path"), show(*pj), "must hold at least one keyframe");
  } else {
    const bool ok = o.vec3_req("position", cam.position, kWorldCoord) & o.vec3_req("target", cam.target, kWorldCoord);
    if (ok) check_view(cam.position, cam.target, o.at("target"), *o.get("target"));
  }
  o.knob("fov_deg", cam.fov_deg, knobs::kCameraFov);
  o.knob("width", cam.width, knobs::kCameraWidth);
  o.knob("height", cam.height, knobs::kCameraHeight);
  o.finish();
  return cam;
}

OutputsDef parse_outputs(Ctx& c, const json& j) {
  OutputsDef out;
  Obj o(c, j, "outputs");
  if (const json* fj = o.get("frames")) {
    for_each_element(c, *fj, o.at("frames"), [&](const json& e, const std::string& p) {
      FrameOutputDef f;
      Obj fo(c, e, p);
      fo.string_req("camera", f.camera, "the name of a camera");
      if (!fo.both("times", "every_k_frames")) {
        if (const json* t = fo.get("times")) f.times = read_times(c, *t, fo.at("times"));
        fo.knob("every_k_frames", f.every_k_frames, knobs::kEveryKFrames);
        if (!fo.has("times") && !fo.has("every_k_frames") && fo.valid()) {
          c.missing(fo.at("times"), "one of 'times' (s) or 'every_k_frames'");
        }
      }
      fo.string("file", f.file);
      valid_pattern(c, fo.at("file"), f.file, {"{camera}", "{frame}", "{time_ms}"});
      fo.finish();
      out.frames.push_back(std::move(f));
    });
  }
  if (const json* hj = o.get("heightfields")) {
    for_each_element(c, *hj, o.at("heightfields"), [&](const json& e, const std::string& p) {
      HeightfieldOutputDef h;
      Obj ho(c, e, p);
      ho.enumeration("format", h.format, kHeightfieldFormats);
      if (const json* t = ho.get("times")) h.times = read_times(c, *t, ho.at("times"));
      ho.boolean("at_end", h.at_end);
      if (h.times.empty() && !h.at_end && ho.valid() && !ho.has("times")) {
        c.missing(ho.at("times"), "'times' (s) and/or \"at_end\": true");
      }
      ho.string("file", h.file);
      valid_pattern(c, ho.at("file"), h.file, {"{frame}", "{time_ms}", "{ext}"});
      ho.finish();
      out.heightfields.push_back(std::move(h));
    });
  }
  o.boolean("report", out.report);
  if (o.has("csv")) {
    o.string("csv", out.csv);
    if (out.csv.empty() || out.csv.find("..") != std::string::npos || out.csv.front() == '/')
      c.error(o.at("csv"), json_quote(out.csv), "must be a file name relative to the run's output directory (no '..')");
  }
  o.finish();
  return out;
}

template <class T>
void check_unique_names(Ctx& c, const std::vector<T>& items, const std::string& section) {
  std::map<std::string, std::size_t> seen;
  for (std::size_t i = 0; i < items.size(); ++i) {
    if (items[i].name.empty()) continue;
    const auto [it, inserted] = seen.emplace(items[i].name, i);
    if (!inserted) {
      c.error(section + "[" + std::to_string(i) + "].name", json_quote(items[i].name), "names must be unique",
              "the same as " + section + "[" + std::to_string(it->second) + "].name");
    }
  }
}

template <class T>
std::vector<std::string> names_of(const std::vector<T>& items) {
  std::vector<std::string> n;
  for (const auto& i : items) n.push_back(i.name);
  return n;
}

std::array<double, 9> rotation_rows(const api::Quat& q) {
  const Eigen::Matrix3d r = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized().toRotationMatrix();
  return {r(0, 0), r(0, 1), r(0, 2), r(1, 0), r(1, 1), r(1, 2), r(2, 0), r(2, 1), r(2, 2)};
}

// Distance (m, ≥ 0) from the body's position down to its lowest point.
double lowest_offset(const BodyDef& b, const TriangleMesh* mesh) {
  const auto r = rotation_rows(b.orientation);
  const double r10 = r[3], r11 = r[4], r12 = r[5];  // world y row
  const auto& s = b.shape;
  switch (s.kind) {
    case ShapeKind::Sphere: return s.radius;
    case ShapeKind::Box:
      return std::abs(r10) * s.half_extents[0] + std::abs(r11) * s.half_extents[1] + std::abs(r12) * s.half_extents[2];
    case ShapeKind::Cylinder:  // axis = body y; the rim's extent is radius·sin(tilt)
      return std::abs(r11) * s.height / 2 + s.radius * std::sqrt(std::max(0.0, 1.0 - r11 * r11));
    case ShapeKind::Capsule: return std::abs(r11) * s.height / 2 + s.radius;
    case ShapeKind::Mesh: {
      if (!mesh) return 0.0;
      double lowest = 0.0;
      for (const auto& v : mesh->vertices) lowest = std::min(lowest, r10 * v.x() + r11 * v.y() + r12 * v.z());
      return -lowest;
    }
  }
  return 0.0;
}

void check_flat_bedrock(Ctx& c, const SceneDef& s, const std::vector<std::optional<TriangleMesh>>& meshes) {
  if (!s.terrain.bedrock_height) return;
  const double bedrock = s.terrain.origin[1] + *s.terrain.bedrock_height;
  for (std::size_t i = 0; i < s.bodies.size(); ++i) {
    const auto& b = s.bodies[i];
    if (b.shape.kind == ShapeKind::Mesh && !meshes[i]) continue;
    const double low = b.position[1] - lowest_offset(b, meshes[i] ? &*meshes[i] : nullptr);
    if (low < bedrock) {
      c.error("bodies[" + std::to_string(i) + "].pose.position", json(b.position).dump(),
              "the body's lowest point must start at or above the bedrock (world y = " + fmt_num(bedrock) +
                  " m: terrain.origin[1] + terrain.bedrock_height)",
              "body below bedrock: its lowest point is at y = " + fmt_num(low) + " m");
    }
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API

// e and ζ are related through the contact law the DEM integrates, the linear dashpot that
// never pulls (particles/material.hpp; docs/dem.md "Restitution").
double MaterialDef::damping_ratio_value() const {
  if (damping_ratio) return *damping_ratio;
  return damping_ratio_from_restitution(restitution);
}

double BodyDef::volume() const {
  const double radius = shape.radius, height = shape.height;
  const auto& half_extents = shape.half_extents;
  switch (shape.kind) {
    case ShapeKind::Sphere: return 4.0 / 3.0 * kPi * radius * radius * radius;
    case ShapeKind::Box: return 8.0 * half_extents[0] * half_extents[1] * half_extents[2];
    case ShapeKind::Cylinder: return kPi * radius * radius * height;
    case ShapeKind::Capsule: return kPi * radius * radius * height + 4.0 / 3.0 * kPi * radius * radius * radius;
    case ShapeKind::Mesh: return mesh_volume;
  }
  return 0.0;
}


const MaterialDef* SceneDef::find_material(const std::string& n) const {
  for (const auto& m : materials) {
    if (m.name == n) return &m;
  }
  return nullptr;
}

const CameraDef* SceneDef::find_camera(const std::string& n) const {
  for (const auto& cam : cameras) {
    if (cam.name == n) return &cam;
  }
  return nullptr;
}

const char* to_string(ShapeKind k) { return kShapeKinds[static_cast<int>(k)].c_str(); }
const std::vector<SimulationPreset>& simulation_presets() {
  // Chosen from the Pareto front of `sandpatch bench tradeoff` (docs/tradeoff.md has the table).
  static const std::vector<SimulationPreset> presets = {
      // crater_s2_n10_p6: depth 6-10 % from the reference (t_c/50, scale 1) at 1/26-1/33 of its
      // cost; N = 10 at 0.65-0.7 of N = 20's cost, within the crater's seed scatter of it;
      // piles of <= 100 granules flatten (angle 55-77 % low)
      {"game", 2.0, 4096, 10, "crater_s2_n10_p6_cpu"},
      // crater_s1.5_n10_p6: 1/10-1/19 of the reference's cost; N = 10 and 20 within the crater's
      // seed scatter of each other (two runs disagree on the order); pile 30-45 % low (s = 1.26)
      {"balanced", 1.5, 10240, 10, "crater_s1.5_n10_p6_cpu"},
      // crater_s1_n20_p6: depth within 0.5-4 % of t_c/50; pile within its seed-to-seed scatter and
      // at rest after its relaxation (at N = 10 it still crept)
      {"engineering", 1.0, 32768, 20, "crater_s1_n20_p6_cpu, pile_s1_n20"},
  };
  return presets;
}

const SimulationPreset* find_simulation_preset(const std::string& name) {
  for (const auto& p : simulation_presets())
    if (name == p.name) return &p;
  return nullptr;
}

const char* to_string(Backend b) { return kBackends[static_cast<int>(b)].c_str(); }
const char* to_string(HeightfieldFormat f) { return kHeightfieldFormats[static_cast<int>(f)].c_str(); }
const char* to_string(LoadFrame f) { return kLoadFrames[static_cast<int>(f)].c_str(); }
const char* to_string(MotionKind m) { return kBodyMotions[static_cast<int>(m)].c_str(); }

Result<SceneDef> parse_scene(const std::string& json_text, const std::string& source_name,
                             const std::string& base_dir) {
  ParsedText parsed = parse_json_text(json_text, source_name);
  if (parsed.error) return *parsed.error;
  const json& root = parsed.root;

  Ctx c;
  c.file = source_name;
  c.base_dir = base_dir.empty() ? fs::path(".") : fs::path(base_dir);
  for (const auto& p : parsed.duplicate_keys) {
    c.error(p, "", "each key may appear once per object", "duplicate key");
  }

  SceneDef s;
  s.source_path = source_name;
  s.name = fs::path(source_name).stem().string();
  Obj top(c, root, "");
  if (const json* v = top.get("version")) {
    read_integer(c, *v, "version", kSceneFormatVersion, kSceneFormatVersion);
  }
  if (top.has("name")) {
    top.string("name", s.name);
    // The name is the output directory under the run's root (out/<name>): one path component.
    const bool control = std::any_of(s.name.begin(), s.name.end(), [](char ch) { return (unsigned char)ch < 0x20; });
    if (s.name == "." || s.name == ".." || s.name.find_first_of("/\\") != std::string::npos || control ||
        s.name.size() > 255)
      c.error("name", json_quote(s.name), "must be a file name: no '/', '\\' or control characters, not '.' or '..', at most 255 bytes",
              "it names the output directory out/<name>");
  }
  top.string("description", s.description, /*non_empty=*/false);
  if (const json* mj = top.require("materials", "an array of at least one material")) {
    for_each_element(c, *mj, "materials", [&](const json& e, const std::string& p) {
      s.materials.push_back(parse_material(c, e, p));
    });
    if (mj->is_array() && mj->empty()) c.error("materials", "[]", "must hold at least one material");
  }
  if (const json* tj = top.require("terrain", "an object with a \"source\"")) parse_terrain(c, *tj, s.terrain);
  std::vector<std::optional<TriangleMesh>> meshes;
  if (const json* bj = top.get("bodies")) {
    for_each_element(c, *bj, "bodies", [&](const json& e, const std::string& p) {
      std::optional<TriangleMesh> mesh;
      s.bodies.push_back(parse_body(c, e, p, mesh));
      meshes.push_back(std::move(mesh));
    });
  }
  if (const json* vj = top.get("vehicles")) s.vehicles = parse_vehicles(c, *vj);
  if (const json* jj = top.get("joints")) s.joints = parse_joints(c, *jj);
  if (const json* sj = top.get("simulation")) parse_simulation(c, *sj, s.terrain, s.simulation);
  if (const json* cj = top.get("cameras")) {
    for_each_element(c, *cj, "cameras", [&](const json& e, const std::string& p) {
      s.cameras.push_back(parse_camera(c, e, p));
    });
  }
  if (const json* oj = top.get("outputs")) s.outputs = parse_outputs(c, *oj);
  top.finish();

  // Cross references.
  check_unique_names(c, s.materials, "materials");
  check_unique_names(c, s.bodies, "bodies");
  check_unique_names(c, s.cameras, "cameras");
  check_joints(c, s);
  if (s.terrain.material_name.empty()) {
    if (!s.materials.empty()) s.terrain.material_name = s.materials.front().name;
  } else if (!s.find_material(s.terrain.material_name) && !s.materials.empty()) {
    const auto names = names_of(s.materials);
    c.error("terrain.material", json_quote(s.terrain.material_name), "must name a material: " + join(names),
            did_you_mean(s.terrain.material_name, names));
  }
  for (std::size_t i = 0; i < s.outputs.frames.size(); ++i) {
    const auto& cam = s.outputs.frames[i].camera;
    if (!cam.empty() && !s.find_camera(cam)) {
      const auto names = names_of(s.cameras);
      c.error("outputs.frames[" + std::to_string(i) + "].camera", json_quote(cam),
              names.empty() ? "must name a camera (the scene has none)" : "must name a camera: " + join(names),
              did_you_mean(cam, names));
    }
  }
  if (const auto& sd = s.simulation.scale_by_distance; sd && !sd->camera.empty() && !s.find_camera(sd->camera)) {
    const auto names = names_of(s.cameras);
    c.error("simulation.scale_by_distance.camera", json_quote(sd->camera),
            names.empty() ? "must name a camera (the scene has none)" : "must name a camera: " + join(names),
            did_you_mean(sd->camera, names));
  }
  check_flat_bedrock(c, s, meshes);
  // With a procedural source and a size, the library's spacing is the size's (square cells).
  if (s.terrain.size && !s.terrain.procedural.empty()) s.terrain.spacing = s.terrain.spacing_xz(s.terrain.samples_x, s.terrain.samples_z)[0];
  if (const MaterialDef* m = s.find_material(s.terrain.material_name)) s.terrain.material = *m;

  if (!c.errors.empty()) return std::move(c.errors);

  // Hash: canonical JSON (keys sorted, no whitespace) + the bytes of every referenced file.
  Hasher h;
  h.str(root.dump());
  for (const auto& f : c.referenced_files) {
    std::ifstream in(f, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    h.str(f.substr(f.find_last_of('/') + 1));
    h.str(bytes.str());
  }
  s.hash = h.hex();
  return s;
}

Result<SceneDef> load_scene_file(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) return Error{path, "", "", "must be an existing scene file", "file not found"};
  if (!fs::is_regular_file(path, ec)) return Error{path, "", "", "must be an existing scene file", "not a regular file"};
  std::ifstream in(path, std::ios::binary);
  if (!in) return Error{path, "", "", "must be a readable scene file", "file cannot be opened"};
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) return Error{path, "", "", "must be a readable scene file", "read failed"};
  std::string base = fs::path(path).parent_path().string();
  return parse_scene(text.str(), path, base.empty() ? "." : base);
}

namespace {
#include "scene/default_scene.inc"  // const char kDefaultSceneJson[] = R"(...)": scenes/default.json
}  // namespace

const char* default_scene_json() { return kDefaultSceneJson; }

Result<SceneDef> load_default_scene() { return parse_scene(default_scene_json(), "<embedded default>", ""); }

double body_extent_below(const BodyDef& body) {
  if (body.shape.kind != ShapeKind::Mesh) return lowest_offset(body, nullptr);
  auto mesh = load_obj_mesh(body.shape.mesh_file, body.shape.mesh_scale);
  return mesh ? lowest_offset(body, &*mesh) : 0.0;
}

std::vector<Error> check_bodies_against_terrain(
    const SceneDef& scene, const std::function<float(double x, double z)>& bedrock_world_height) {
  std::vector<Error> errors;
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const auto& b = scene.bodies[i];
    const double x = b.position[0], z = b.position[2];
    const double bedrock = bedrock_world_height(x, z);
    const double low = b.position[1] - body_extent_below(b);
    if (low < bedrock) {
      errors.push_back({scene.source_path, "bodies[" + std::to_string(i) + "].pose.position",
                        json(b.position).dump(),
                        "the body's lowest point must start at or above the bedrock (world y = " + fmt_num(bedrock) +
                            " m under x = " + fmt_num(x) + ", z = " + fmt_num(z) + ")",
                        "body below bedrock: its lowest point is at y = " + fmt_num(low) + " m"});
    }
    // A kinematic body goes where its keyframes send it: none may put it through the bedrock.
    for (std::size_t k = 0; k < b.keyframes.size(); ++k) {
      BodyDef at = b;
      at.position = b.keyframes[k].position;
      at.orientation = to_quat(b.keyframes[k].orientation);
      const double kx = at.position[0], kz = at.position[2];
      const double rock = bedrock_world_height(kx, kz), klow = at.position[1] - body_extent_below(at);
      if (klow < rock)
        errors.push_back({scene.source_path, "bodies[" + std::to_string(i) + "].keyframes[" + std::to_string(k) + "].position",
                          json(at.position).dump(),
                          "the body's lowest point must stay at or above the bedrock (world y = " + fmt_num(rock) +
                              " m under x = " + fmt_num(kx) + ", z = " + fmt_num(kz) + ")",
                          "at t = " + fmt_num(b.keyframes[k].t) + " s its lowest point would be at y = " + fmt_num(klow) + " m"});
    }
  }
  return errors;
}

}  // namespace sandpatch
