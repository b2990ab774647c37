// The library for games (include/sandpatch/sandpatch.hpp, docs/api.md): the public API over
// a World (manager/world.hpp), the frame owner a scene run steps too: the same stages, the
// same state hash and the same report sections.
//
// Public types live in sandpatch::api; the internal ones (sandpatch::Error, Result, ...) are
// reached through the `core` alias. Every public entry point validates its input and
// returns errors; nothing is thrown across the API.
#include "sandpatch/sandpatch.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string_view>
#include <nlohmann/json.hpp>

#include "common/error.hpp"
#include "common/checker.hpp"
#include "common/hash.hpp"
#include "common/knobs.hpp"
#include "common/limits.hpp"
#include "heightfield/heightfield.hpp"
#include "heightfield/io.hpp"
#include "heightfield/procedural.hpp"
#include "manager/bullet_world.hpp"
#include "manager/profile.hpp"
#include "manager/definitions.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/scene_world.hpp"
#include "manager/world.hpp"
#include "render/clipmap.hpp"
#include "scene/mesh.hpp"

namespace sandpatch::api {
namespace core = ::sandpatch;
static_assert(std::string_view(kVersion) == SANDPATCH_VERSION, "kVersion in sandpatch.hpp must match project(VERSION)");
namespace {

using ojson = nlohmann::ordered_json;

std::string num(double v) { return core::format_number(v); }

std::string vec_str(const Vec3& v) { return "[" + num(v[0]) + ", " + num(v[1]) + ", " + num(v[2]) + "]"; }

// Internal errors → public ones, with the field renamed (`rename` maps an internal field name
// to the public one; unknown names get `prefix` in front).
std::vector<Error> convert(const std::vector<core::Error>& es, const std::string& prefix,
                           std::initializer_list<std::pair<const char*, const char*>> rename = {}) {
  std::vector<Error> out;
  for (const auto& e : es) {
    std::string field = e.field;
    bool renamed = false;
    for (const auto& [from, to] : rename)
      if (field == from) {
        field = to;
        renamed = true;
        break;
      }
    if (!renamed && !field.empty()) field = prefix + field;
    out.push_back({e.file, field, e.value, e.allowed, e.detail});
  }
  return out;
}

using Checker = core::BasicChecker<Error>;

EventKind kind_of(core::PatchEventKind k) {
  switch (k) {
    case core::PatchEventKind::Requested: return EventKind::Requested;
    case core::PatchEventKind::Promoted: return EventKind::Promoted;
    case core::PatchEventKind::Ready: return EventKind::Ready;
    case core::PatchEventKind::Asleep: return EventKind::Asleep;
    case core::PatchEventKind::Woke: return EventKind::Woke;
    case core::PatchEventKind::Demoted: return EventKind::Demoted;
    case core::PatchEventKind::TooFastToFollow: return EventKind::TooFastToFollow;
    case core::PatchEventKind::TooFastForGranules: return EventKind::TooFastForGranules;
    case core::PatchEventKind::SoilDropped: return EventKind::SoilDropped;
  }
  return EventKind::Requested;
}

bool eq_norm_positive(const Quat& q) {
  return double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3] > 1e-12;
}
// Normalised in double: a float quaternion of 1e30 has a float norm² of inf, which would
// normalise to [0, 0, 0, 0] (callers check finite and non-zero first).
Eigen::Quaternionf eq(const Quat& q) {
  const double n = std::sqrt(double(q[0]) * q[0] + double(q[1]) * q[1] + double(q[2]) * q[2] + double(q[3]) * q[3]);
  return Eigen::Quaternionf(float(q[0] / n), float(q[1] / n), float(q[2] / n), float(q[3] / n));
}
// A velocity's magnitude against its limit (limits.hpp), the same rule as scene files.
void speed_limit(Checker& c, const std::string& field, const Vec3f& v, double limit, const char* unit) {
  const double n = std::sqrt(double(v[0]) * v[0] + double(v[1]) * v[1] + double(v[2]) * v[2]);
  if (std::isfinite(n) && n > limit)
    c.add(field, "[" + num(v[0]) + ", " + num(v[1]) + ", " + num(v[2]) + "]",
          "the magnitude must be at most " + num(limit) + " " + unit + " (|v| = " + num(n) + ")");
}
Eigen::Vector3f ev(const Vec3f& v) { return {v[0], v[1], v[2]}; }

}  // namespace

const char* to_string(EventKind k) {
  switch (k) {
    case EventKind::Requested: return "requested";
    case EventKind::Promoted: return "promoted";
    case EventKind::Ready: return "ready";
    case EventKind::Asleep: return "asleep";
    case EventKind::Woke: return "woke";
    case EventKind::Demoted: return "demoted";
    case EventKind::TooFastToFollow: return "too_fast_to_follow";
    case EventKind::TooFastForGranules: return "too_fast_for_granules";
    case EventKind::SoilDropped: return "soil_dropped";
  }
  return "unknown";
}

struct Terrain::Impl {
  TerrainDef def;
  std::unique_ptr<core::World> world;
  std::size_t events_read = 0;                    // manager events already handed out

  core::RigidBodyId id(BodyHandle h) const { return {h.index, h.generation}; }
  core::BulletWorld& bullet() { return world->bullet(); }
  const core::BulletWorld& bullet() const { return world->bullet(); }
  const core::Heightfield& hf() const { return world->heightfield(); }
  core::TerrainManager* manager() const { return const_cast<core::World&>(*world).manager(); }
  Status check(BodyHandle h) const {
    if (world->alive(id(h))) return Ok{};
    return Error{"", "BodyHandle", "{" + std::to_string(h.index) + ", " + std::to_string(h.generation) + "}",
                 "must be a live body of this terrain (removed, or never added)"};
  }
};

Terrain::Terrain(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Terrain::Terrain(Terrain&&) noexcept = default;
Terrain& Terrain::operator=(Terrain&&) noexcept = default;
Terrain::~Terrain() = default;

Result<Terrain> Terrain::create(const TerrainDef& def) {
  if (auto errs = core::validate(def); !errs.empty()) return convert(errs, "");
  auto impl = std::make_unique<Impl>();
  impl->def = def;
  auto hf = core::build_heightfield(def);
  if (!hf) return convert(hf.errors(), "");
  const Eigen::Vector3f gravity(float(def.gravity[0]), float(def.gravity[1]), float(def.gravity[2]));
  auto world = core::World::create(std::move(*hf), gravity);
  if (!world) return convert(world.errors(), "TerrainDef.");
  impl->world = std::move(*world);
  if (def.granular_patches) {
    const core::TerrainManagerDef m = core::manager_def(def);
    if (core::Status tm = impl->world->enable_patches(m); !tm) {
      // Fields the manager names after the scene file's become TerrainDef's; the others (from
      // settling the granule tile, making the pool's simulations) keep their internal names.
      std::vector<Error> es = convert(tm.errors(), "",
                                      {{"pool.slots", "TerrainDef.slots"},
                                       {"pool.granules_per_slot", "TerrainDef.granules_per_slot"},
                                       {"simulation.pool.granules_per_slot", "TerrainDef.granules_per_slot"},
                                       {"simulation.backend", "TerrainDef.backend"},
                                       {"particle_scale", "TerrainDef.particle_scale"},
                                       {"patch_depth", "TerrainDef.patch_depth"},
                                       {"terrain.patch_depth", "TerrainDef.patch_depth"},
                                       {"steps_per_contact", "TerrainDef.steps_per_contact"},
                                       {"max_substeps", "TerrainDef.max_substeps"}});
      for (auto& e : es)
        if (!e.field.starts_with("TerrainDef."))
          e.detail += std::string(e.detail.empty() ? "" : "; ") +
                      "while building the granule tile and the patch pool from TerrainDef.material";
      return es;
    }
  }
  return Terrain(std::move(impl));
}

// ---- bodies ----

Result<BodyHandle> Terrain::add_body(const BodyDef& d) {
  Impl& I = *impl_;
  auto def = core::rigid_body_def(d);
  if (!def) return convert(def.errors(), "");
  const core::RigidBodyDef& r = *def;
  auto id = I.world->add_body(r);
  if (!id) return convert(id.errors(), "BodyDef.", {{"simulation.pool.shell_spheres_per_slot", "TerrainDef.shell_spheres_per_slot"}});
  // The body's lowest point must start at or above the bedrock (surface − soil_depth): the
  // patches' granules stop there.
  Eigen::Vector3d lo, hi;
  I.bullet().bounds(*id, &lo, &hi);
  const double bedrock = height_at(d.position[0], d.position[2]) - I.def.soil_depth;
  if (lo.y() < bedrock) {
    I.world->discard_body(*id);
    return Error{"", "BodyDef.position", vec_str(d.position),
                 "the body's lowest point must start at or above the bedrock (world y = " + num(bedrock) + " m here)",
                 "its lowest point is at y = " + num(lo.y()) + " m" + (d.name.empty() ? "" : " (body '" + d.name + "')")};
  }
  // The scene files' rule too (manager/scene_world.cpp make_world): a body whose centre starts
  // below the surface is inside the terrain, and Bullet's contact would push it further down.
  const core::Heightfield& g = I.hf();
  const double lx = d.position[0] - g.origin_x(), lz = d.position[2] - g.origin_z();
  if (lx >= 0 && lz >= 0 && lx <= (g.samples_x() - 1) * double(g.spacing()) && lz <= (g.samples_z() - 1) * double(g.spacing())) {
    const double surface = height_at(d.position[0], d.position[2]);
    if (d.position[1] < surface) {
      I.world->discard_body(*id);
      return Error{"", "BodyDef.position", vec_str(d.position),
                   "the body starts inside the terrain: its centre is below the surface (world y = " + num(surface) +
                       " m there); it must start at or above it",
                   "its lowest point may touch or enter the ground, its centre may not" +
                       (d.name.empty() ? std::string() : " (body '" + d.name + "')")};
    }
  }
  return BodyHandle{id->index, id->generation};
}

// World::remove_body: gone to the game at once; a body a patch may carry leaves the Bullet
// world in the next step, after the dem stage has let go of its shell.
Status Terrain::remove_body(BodyHandle h) {
  Impl& I = *impl_;
  if (Status s = I.check(h); !s) return s;
  I.world->remove_body(I.id(h));
  return Ok{};
}

Result<BodyHandle> Terrain::adopt_bullet_body(void* bt_rigid_body, const std::string& name, const BulletAbi& abi) {
  Impl& I = *impl_;
  BulletAbi lib;
  core::BulletWorld::bullet_abi(&lib.scalar_bytes, &lib.version, &lib.rigid_body_bytes);
  if (abi.scalar_bytes != lib.scalar_bytes || abi.version != lib.version || abi.rigid_body_bytes != lib.rigid_body_bytes) {
    auto str = [](const BulletAbi& a) {
      return "btScalar " + std::to_string(a.scalar_bytes) + " bytes, Bullet " + std::to_string(a.version) + ", btRigidBody " +
             std::to_string(a.rigid_body_bytes) + " bytes";
    };
    return Error{"", "btRigidBody.abi", str(abi), "the Bullet libsandpatch was built with: " + str(lib)};
  }
  auto id = I.world->adopt_body(static_cast<btRigidBody*>(bt_rigid_body), name);
  if (!id) return convert(id.errors(), "");
  // As add_body: the body's lowest point must start at or above the bedrock.
  const core::BodyState st = I.bullet().state(*id);
  Eigen::Vector3d lo, hi;
  I.bullet().bounds(*id, &lo, &hi);
  const double bedrock = height_at(st.position.x(), st.position.z()) - I.def.soil_depth;
  if (lo.y() < bedrock) {
    I.world->discard_body(*id);  // given back unchanged
    return Error{"", "btRigidBody.position", vec_str({st.position.x(), st.position.y(), st.position.z()}),
                 "the body's lowest point must start at or above the bedrock (world y = " + num(bedrock) + " m here)",
                 "its lowest point is at y = " + num(lo.y()) + " m" + (name.empty() ? "" : " (body '" + name + "')")};
  }
  return BodyHandle{id->index, id->generation};
}

bool Terrain::alive(BodyHandle h) const { return impl_->check(h).ok(); }

// ---- joints ----

namespace {

using core::core_motor;

// A joint's numbers checked in double first (a float conversion would turn 1e300 into inf and
// lose the value written).
void check_joint_numbers(Checker& c, const JointDef& d) {
  c.finite("anchor", d.anchor, "m");
  c.finite("axis", d.axis, "");
  if (d.limits) c.finite("limits", *d.limits, d.kind == JointKind::Hinge ? "rad" : "m");
  if (d.motor.mode != MotorMode::Off && d.motor.mode != MotorMode::Velocity && d.motor.mode != MotorMode::Position)
    c.add("motor.mode", std::to_string(int(d.motor.mode)), "must be a MotorMode: Off, Velocity or Position");
  if (d.motor.mode != MotorMode::Off) {
    c.number("motor.target", d.motor.target, -1e4, 1e4, false, false, d.kind == JointKind::Hinge ? "(rad/s or rad)" : "(m/s or m)");
    c.number("motor.max_force", d.motor.max_force, 0, 1e9, false, false, d.kind == JointKind::Hinge ? "N m" : "N");
  }
  if (d.motor.mode == MotorMode::Position) c.number("motor.servo_speed", d.motor.servo_speed, 0, 1e4, true, false, "");
  c.closed("spring.stiffness", d.spring.stiffness, 0, 1e12);
  c.closed("spring.damping", d.spring.damping, 0, 1e12);
}

}  // namespace

Result<JointHandle> Terrain::add_joint(const JointDef& d) {
  Impl& I = *impl_;
  Checker c{"JointDef.", d.name.empty() ? "" : "joint '" + d.name + "'", {}};
  if (d.kind != JointKind::Fixed && d.kind != JointKind::Hinge && d.kind != JointKind::Slider)
    c.add("kind", std::to_string(int(d.kind)), "must be a JointKind: Fixed, Hinge or Slider");
  if (!I.world->alive(I.id(d.body_a)))
    c.add("body_a", "{" + std::to_string(d.body_a.index) + ", " + std::to_string(d.body_a.generation) + "}",
          "must be a live body of this terrain (removed, or never added)");
  if (d.body_b.valid() && !I.world->alive(I.id(d.body_b)))
    c.add("body_b", "{" + std::to_string(d.body_b.index) + ", " + std::to_string(d.body_b.generation) + "}",
          "must be a live body of this terrain, or an invalid handle (the world)");
  check_joint_numbers(c, d);
  if (!c.errs.empty()) return c.errs;
  core::RigidJointDef r;
  r.name = d.name;
  r.kind = d.kind == JointKind::Fixed ? core::JointKind::Fixed : d.kind == JointKind::Slider ? core::JointKind::Slider : core::JointKind::Hinge;
  r.a = I.id(d.body_a);
  if (d.body_b.valid()) r.b = I.id(d.body_b);
  r.anchor = {d.anchor[0], d.anchor[1], d.anchor[2]};
  r.axis = {float(d.axis[0]), float(d.axis[1]), float(d.axis[2])};
  core::JointDof& f = r.kind == core::JointKind::Slider ? r.slide : r.turn;
  if (d.limits) {
    f.limited = true;
    f.lower = float((*d.limits)[0]);
    f.upper = float((*d.limits)[1]);
  }
  f.motor = core_motor(d.motor);
  f.stiffness = float(d.spring.stiffness);
  f.damping = float(d.spring.damping);
  auto id = I.world->add_joint(r);
  if (!id) {
    std::vector<Error> es = convert(id.errors(), "JointDef.", {{"type", "JointDef.kind"}});
    for (Error& e : es)
      if (!d.name.empty()) e.detail += (e.detail.empty() ? "" : "; ") + std::string("joint '") + d.name + "'";
    return es;
  }
  return JointHandle{id->index, id->generation};
}

namespace {
Status check_joint_handle(const core::World& w, JointHandle h) {
  if (w.joint_alive(core::JointId{h.index, h.generation})) return Ok{};
  return Error{"", "JointHandle", "{" + std::to_string(h.index) + ", " + std::to_string(h.generation) + "}",
               "must be a live joint of this terrain (removed, one of its bodies removed, or never added)"};
}
}  // namespace

Status Terrain::remove_joint(JointHandle h) {
  if (Status s = check_joint_handle(*impl_->world, h); !s) return s;
  impl_->world->remove_joint({h.index, h.generation});
  return Ok{};
}

bool Terrain::alive(JointHandle h) const { return check_joint_handle(*impl_->world, h).ok(); }

Status Terrain::set_joint_motor(JointHandle h, const JointMotor& m) {
  if (Status s = check_joint_handle(*impl_->world, h); !s) return s;
  const core::JointId id{h.index, h.generation};
  const bool turn = impl_->bullet().joint_definition(id).kind != core::JointKind::Slider;
  Checker c{"set_joint_motor.", "", {}};
  JointDef probe;
  probe.kind = turn ? JointKind::Hinge : JointKind::Slider;
  probe.motor = m;
  check_joint_numbers(c, probe);
  if (!c.errs.empty()) return c.errs;
  if (core::Status s = impl_->world->set_joint_motor(id, turn, core_motor(m)); !s)
    return convert(s.errors(), "set_joint_motor.", {{"joint", "set_joint_motor.joint"}});
  return Ok{};
}

// ---- vehicles ----

Result<VehicleHandles> Terrain::add_vehicle(const VehicleDef& def) {
  Impl& I = *impl_;
  if (auto es = core::check_vehicle(def, "VehicleDef."); !es.empty()) return convert(es, "");
  const core::VehicleParts parts = core::expand_vehicle(def);
  VehicleHandles out;
  out.def = def;
  std::vector<BodyHandle> bodies;
  auto undo = [&] {
    for (BodyHandle h : bodies) I.world->discard_body(I.id(h));  // no step has seen them
  };
  for (const BodyDef& b : parts.bodies) {
    auto h = add_body(b);  // the same checks as any body's: the bedrock, the surface
    if (!h) {
      undo();
      std::vector<Error> es = h.errors();
      for (Error& e : es)
        if (e.field.starts_with("BodyDef.")) {
          e.detail += (e.detail.empty() ? "" : "; ") + std::string("part '") + b.name + "' at " + vec_str(b.position);
          e.field = e.field == "BodyDef.position" ? "VehicleDef.position" : "VehicleDef";
          e.value = vec_str(def.position);
        }
      return es;
    }
    bodies.push_back(*h);
  }
  std::vector<core::JointId> joints;
  for (const core::VehicleJoint& j : parts.joints) {
    core::RigidJointDef d = core::vehicle_joint_def(j);
    d.a = I.id(bodies[std::size_t(j.a)]);
    d.b = I.id(bodies[std::size_t(j.b)]);
    auto id = I.world->add_joint(d);
    if (!id) {  // checked with the vehicle: not expected
      for (core::JointId x : joints) I.world->remove_joint(x);
      undo();
      return convert(id.errors(), "VehicleDef.");
    }
    if (j.max_steer > 0) I.world->bullet().set_joint_steering(*id, float(def.steering_angle), float(def.steering_speed));
    joints.push_back(*id);
  }
  out.chassis = bodies[0];
  for (std::size_t k = 0; k < 4; ++k) {
    out.wheels[k] = bodies[1 + k];
    out.axles[k] = {joints[k].index, joints[k].generation};
  }
  return out;
}

Status Terrain::drive_vehicle(const VehicleHandles& v, double wheel_speed, double max_torque, double steering_angle) {
  Impl& I = *impl_;
  Checker c{"drive_vehicle.", "", {}};
  c.closed("wheel_speed", wheel_speed, -1e4, 1e4, "rad/s");
  c.closed("max_torque", max_torque, 0, 1e9, "N m");
  const double lim = v.def.max_steering_angle;
  c.closed("steering_angle", steering_angle, -lim, lim, "rad (±VehicleDef.max_steering_angle)");
  for (const JointHandle& a : v.axles)
    if (!I.world->joint_alive({a.index, a.generation})) {
      c.add("vehicle", "'" + v.def.name + "'", "must be a live vehicle of this terrain (a part or joint was removed)");
      break;
    }
  if (!c.errs.empty()) return c.errs;
  const core::VehicleParts parts = core::expand_vehicle(v.def);  // which wheels are driven and steered
  for (std::size_t k = 0; k < 4; ++k) {
    const core::JointId id{v.axles[k].index, v.axles[k].generation};
    if (parts.driven[k]) I.world->bullet().set_joint_motor(id, true, core::core_motor(core::drive_motor(wheel_speed, max_torque)));
    if (parts.steered[k]) I.world->bullet().set_joint_steering(id, float(steering_angle), float(v.def.steering_speed));
  }
  return Ok{};
}

Result<JointState> Terrain::joint_state(JointHandle h) const {
  if (Status s = check_joint_handle(*impl_->world, h); !s) return s.errors();
  const core::JointId id{h.index, h.generation};
  const core::JointState st = impl_->bullet().joint_state(id);
  JointState out;
  if (impl_->bullet().joint_definition(id).kind == core::JointKind::Slider) {
    out.position = st.position;
    out.rate = st.rate;
    out.force = st.force;
  } else {
    out.position = st.angle;
    out.rate = st.angular_rate;
    out.force = st.torque;
  }
  return out;
}

Result<BodyState> Terrain::body_state(BodyHandle h) const {
  if (Status s = impl_->check(h); !s) return s.errors();
  const core::BodyState st = impl_->bullet().state(impl_->id(h));
  BodyState out;
  out.position = {st.position.x(), st.position.y(), st.position.z()};
  out.orientation = {st.orientation.w(), st.orientation.x(), st.orientation.y(), st.orientation.z()};
  out.linear_velocity = {st.linear_velocity.x(), st.linear_velocity.y(), st.linear_velocity.z()};
  out.angular_velocity = {st.angular_velocity.x(), st.angular_velocity.y(), st.angular_velocity.z()};
  return out;
}

namespace {
Eigen::Vector3d evd(const Vec3& v) { return {v[0], v[1], v[2]}; }
}  // namespace

// A static body never moves: set_body_transform and set_body_velocity refuse it.
static Status refuse_static(const core::World& w, core::RigidBodyId id, const std::string& call) {
  if (w.bullet().motion(id) != core::RigidMotion::Static) return Ok{};
  return Error{"", call + ".body", "'" + w.bullet().definition(id).name + "' (static)", "must not be a static body: it never moves", ""};
}

// Only a kinematic body follows targets and keyframes: set_kinematic_target and set_keyframes
// refuse the others.
static Status require_kinematic(const core::World& w, core::RigidBodyId id, const std::string& call) {
  if (w.bullet().motion(id) == core::RigidMotion::Kinematic) return Ok{};
  return Error{"", call + ".body", "'" + w.bullet().definition(id).name + "' (" + core::to_string(w.bullet().motion(id)) + ")",
               "must be a kinematic body (BodyDef.motion)", ""};
}

// A pose given to `call`: a finite position (m) and a finite, non-zero quaternion [w, x, y, z].
static Status check_pose(const std::string& call, const Vec3& position, const Quat& orientation) {
  Checker c{call + ".", "", {}};
  c.finite("position", position, "m");
  c.finite("orientation", orientation, "");
  if (c.errs.empty() && !eq_norm_positive(orientation))
    c.add("orientation", "[0, 0, 0, 0]", "must be a non-zero quaternion [w, x, y, z]");
  if (!c.errs.empty()) return c.errs;
  return Ok{};
}

Status Terrain::set_body_transform(BodyHandle h, const Vec3& position, const Quat& orientation) {
  if (Status s = impl_->check(h); !s) return s;
  if (Status s = refuse_static(*impl_->world, impl_->id(h), "set_body_transform"); !s) return s;
  if (Status s = check_pose("set_body_transform", position, orientation); !s) return s;
  core::BodyState st = impl_->bullet().state(impl_->id(h));
  st.position = {position[0], position[1], position[2]};
  st.orientation = eq(orientation);
  impl_->bullet().set_state(impl_->id(h), st);
  return Ok{};
}

Status Terrain::set_body_velocity(BodyHandle h, const Vec3f& linear, const Vec3f& angular) {
  if (Status s = impl_->check(h); !s) return s;
  if (Status s = refuse_static(*impl_->world, impl_->id(h), "set_body_velocity"); !s) return s;
  Checker c{"set_body_velocity.", "", {}};
  c.finite("linear", linear, "m/s");
  c.finite("angular", angular, "rad/s");
  speed_limit(c, "linear", linear, core::limits::kMaxBodySpeed, "m/s");
  speed_limit(c, "angular", angular, core::limits::kMaxBodySpin, "rad/s");
  if (!c.errs.empty()) return c.errs;
  if (impl_->world->bullet().motion(impl_->id(h)) == core::RigidMotion::Kinematic) {
    if (core::Status s = impl_->world->set_kinematic_velocity(impl_->id(h), ev(linear), ev(angular)); !s)
      return convert(s.errors(), "set_body_velocity.");
    return Ok{};
  }
  core::BodyState st = impl_->bullet().state(impl_->id(h));
  st.linear_velocity = ev(linear);
  st.angular_velocity = ev(angular);
  impl_->bullet().set_state(impl_->id(h), st);
  return Ok{};
}

// The lowest point of body `id` at a pose must be at or above the bedrock (surface − soil_depth).
static std::optional<Error> below_bedrock(const Terrain& t, const core::World& w, double soil_depth, core::RigidBodyId id,
                                          const std::string& field, const Vec3& p, const Eigen::Quaternionf& q) {
  const double low = p[1] - core::World::extent_below(w.bullet().definition(id).shape, q);
  const double bedrock = t.height_at(p[0], p[2]) - soil_depth;
  if (low >= bedrock) return std::nullopt;
  return Error{"", field, vec_str(p),
               "the body's lowest point must stay at or above the bedrock (world y = " + num(bedrock) + " m here)",
               "its lowest point would be at y = " + num(low) + " m"};
}

Status Terrain::set_kinematic_target(BodyHandle h, const Vec3& position, const Quat& orientation) {
  Impl& I = *impl_;
  if (Status s = I.check(h); !s) return s;
  if (Status s = check_pose("set_kinematic_target", position, orientation); !s) return s;
  if (Status s = require_kinematic(*I.world, I.id(h), "set_kinematic_target"); !s) return s;
  if (auto e = below_bedrock(*this, *I.world, I.def.soil_depth, I.id(h), "set_kinematic_target.position", position, eq(orientation)))
    return *e;
  if (core::Status s = I.world->set_kinematic_target(I.id(h), evd(position), eq(orientation)); !s)
    return convert(s.errors(), "set_kinematic_target.");
  return Ok{};
}

Status Terrain::set_keyframes(BodyHandle h, const std::vector<Keyframe>& keys) {
  Impl& I = *impl_;
  if (Status s = I.check(h); !s) return s;
  if (Status s = require_kinematic(*I.world, I.id(h), "set_keyframes"); !s) return s;
  std::vector<core::World::Keyframe> ks;
  for (const Keyframe& k : keys) {
    core::World::Keyframe w;
    w.t = k.t;
    w.position = evd(k.position);
    w.orientation = Eigen::Quaterniond(k.orientation[0], k.orientation[1], k.orientation[2], k.orientation[3]);
    ks.push_back(w);
  }
  std::vector<Error> errs = convert(core::World::check_keyframes(ks, "keyframes"), "");
  for (std::size_t k = 0; k < keys.size() && errs.empty(); ++k)
    if (auto e = below_bedrock(*this, *I.world, I.def.soil_depth, I.id(h), "keyframes[" + std::to_string(k) + "].position",
                               keys[k].position, eq(keys[k].orientation)))
      errs.push_back(*e);
  if (!errs.empty()) return errs;
  const auto& entries = I.world->entries();
  for (std::size_t e = 0; e < entries.size(); ++e)
    if (!entries[e].removed && entries[e].id.index == h.index && entries[e].id.generation == h.generation) {
      if (core::Status s = I.world->set_keyframes(e, std::move(ks)); !s) return convert(s.errors(), "");
      return Ok{};
    }
  return Error{"", "body", std::to_string(h.index), "must be a live body of this terrain", ""};
}

std::vector<BodyHandle> Terrain::bodies() const {
  std::vector<BodyHandle> out;
  for (const auto& id : impl_->world->bodies()) out.push_back({id.index, id.generation});
  return out;
}

// ---- driving bodies (World::apply_force, apply_torque, apply_impulse) ----


// apply_force and apply_impulse: the World call `apply` on body h with vector v (N or N s) at
// world_point (null: the centre of mass); errors under `call`.
using ApplyAt = core::Status (core::World::*)(core::RigidBodyId, const Eigen::Vector3f&, const Eigen::Vector3d*);
static Status apply_at(core::World& w, core::RigidBodyId id, ApplyAt apply, const Vec3f& v, const Vec3* world_point,
                       const std::string& call) {
  const Eigen::Vector3d p = world_point ? evd(*world_point) : Eigen::Vector3d::Zero();
  if (core::Status s = (w.*apply)(id, ev(v), world_point ? &p : nullptr); !s) return convert(s.errors(), call + ".");
  return Ok{};
}

Status Terrain::apply_force(BodyHandle h, const Vec3f& force, const Vec3* world_point) {
  if (Status s = impl_->check(h); !s) return s;
  return apply_at(*impl_->world, impl_->id(h), &core::World::apply_force, force, world_point, "apply_force");
}

Status Terrain::apply_torque(BodyHandle h, const Vec3f& torque) {
  if (Status s = impl_->check(h); !s) return s;
  if (core::Status s = impl_->world->apply_torque(impl_->id(h), ev(torque)); !s) return convert(s.errors(), "apply_torque.");
  return Ok{};
}

Status Terrain::apply_impulse(BodyHandle h, const Vec3f& impulse, const Vec3* world_point) {
  if (Status s = impl_->check(h); !s) return s;
  return apply_at(*impl_->world, impl_->id(h), &core::World::apply_impulse, impulse, world_point, "apply_impulse");
}

Result<BodyForces> Terrain::granular_force(BodyHandle h) const {
  if (Status s = impl_->check(h); !s) return s.errors();
  const core::World::SoilForce f = impl_->world->soil_force(impl_->id(h));
  return BodyForces{{f.force.x(), f.force.y(), f.force.z()}, {f.torque.x(), f.torque.y(), f.torque.z()}, f.carried};
}

Result<BodyContact> Terrain::body_contact(BodyHandle h) const {
  if (Status s = impl_->check(h); !s) return s.errors();
  const core::World::Contact c = impl_->world->contact(impl_->id(h));
  BodyContact out;
  out.granular_force = {c.granular.force.x(), c.granular.force.y(), c.granular.force.z()};
  out.granular_torque = {c.granular.torque.x(), c.granular.torque.y(), c.granular.torque.z()};
  out.on_particles = c.granular.carried;
  out.heightfield_force = {c.heightfield_force.x(), c.heightfield_force.y(), c.heightfield_force.z()};
  out.sinkage = c.sinkage;
  out.lowest_y = c.lowest_y;
  out.original_surface_y = c.original_surface_y;
  return out;
}

// ---- the step ----

Status Terrain::step(double dt, int substeps) {
  Checker c{"step.", "", {}};
  c.number("dt", dt, 0.0, 0.1, true, false, "s");
  c.integer("substeps", substeps, 1, 1000);
  if (!c.errs.empty()) return c.errs;
  if (core::Status s = impl_->world->step(dt, substeps); !s) return convert(s.errors(), "");
  return Ok{};
}

Status Terrain::prepare(double dt) {
  Checker c{"prepare.", "", {}};
  c.number("dt", dt, 0.0, 0.1, true, false, "s");
  if (!c.errs.empty()) return c.errs;
  if (core::Status s = impl_->world->prepare(dt); !s) return convert(s.errors(), "");
  return Ok{};
}

double Terrain::time() const { return impl_->world->time(); }

Status Terrain::request_patch(double x0, double z0, double x1, double z1) {
  Checker c{"request_patch.", "", {}};
  c.finite("rectangle", std::array<double, 4>{x0, z0, x1, z1}, "m");
  if (c.errs.empty() && !(x1 > x0 && z1 > z0))
    c.add("rectangle", "[" + num(x0) + ", " + num(z0) + ", " + num(x1) + ", " + num(z1) + "]", "must have x1 > x0 and z1 > z0");
  if (!c.errs.empty()) return c.errs;
  if (!impl_->manager()) return Error{"", "TerrainDef.granular_patches", "false", "patches need granular_patches = true"};
  impl_->manager()->request_patch(x0, z0, x1, z1, impl_->world->time());
  return Ok{};
}

Status Terrain::demote_all() {
  if (core::Status s = impl_->world->demote_all(); !s) return convert(s.errors(), "");
  return Ok{};
}

// ---- queries ----

double Terrain::height_at(double x, double z) const {
  const core::Heightfield& hf = impl_->hf();
  return hf.origin_y() + double(hf.sample(float(x - hf.origin_x()), float(z - hf.origin_z())));
}

Vec3f Terrain::normal_at(double x, double z) const {
  const core::Heightfield& hf = impl_->hf();
  const Eigen::Vector3f n = hf.normal(float(x - hf.origin_x()), float(z - hf.origin_z()));
  return {n.x(), n.y(), n.z()};
}

// ---- patches and events ----

std::vector<Event> Terrain::poll_events() {
  Impl& I = *impl_;
  std::vector<Event> out;
  if (!I.manager()) return out;
  const auto& es = I.manager()->events();
  for (; I.events_read < es.size(); ++I.events_read) {
    const core::PatchEvent& e = es[I.events_read];
    out.push_back({kind_of(e.kind), e.patch, e.time, e.wall_ms, e.granules, e.body, e.value, e.limit, e.volume});
  }
  return out;
}

int Terrain::active_patches() const { return impl_->manager() ? impl_->manager()->active_patches() : 0; }
int Terrain::granules() const { return impl_->manager() ? impl_->manager()->granules() : 0; }

void Terrain::particles(std::vector<float>& xyzr) const {
  xyzr.clear();
  if (impl_->manager()) impl_->manager()->particles(xyzr);
}

std::vector<ParticleGroup> Terrain::particle_groups() const {
  std::vector<ParticleGroup> out;
  if (!impl_->manager()) return out;
  std::size_t first = 0;
  for (const auto& [count, fade] : impl_->manager()->particle_groups()) {
    out.push_back({first, count, fade});
    first += count;
  }
  return out;
}

// ---- heightfield data for renderers ----

HeightfieldInfo Terrain::heightfield() const {
  const core::Heightfield& hf = impl_->hf();
  return {hf.samples_x(), hf.samples_z(), double(hf.spacing()), origin(), double(hf.min_height()), double(hf.max_height())};
}

Vec3 Terrain::origin() const {
  const core::Heightfield& hf = impl_->hf();
  return {hf.origin_x(), hf.origin_y(), hf.origin_z()};
}

Status Terrain::read_heights(GridRegion r, std::vector<float>& out) const {
  const core::Heightfield& hf = impl_->hf();
  const core::GridRegion g{r.i0, r.j0, r.ni, r.nj};
  if (r.empty() || !hf.contains(g))
    return Error{"", "GridRegion", "{" + std::to_string(r.i0) + ", " + std::to_string(r.j0) + ", " + std::to_string(r.ni) + ", " +
                                      std::to_string(r.nj) + "}",
                 "must be non-empty and inside the grid [0, " + std::to_string(hf.samples_x()) + ") x [0, " +
                     std::to_string(hf.samples_z()) + ")"};
  out.resize(std::size_t(r.ni) * std::size_t(r.nj));
  hf.read(g, out.data());
  return Ok{};
}

std::vector<GridRegion> Terrain::take_dirty_regions() {
  std::vector<GridRegion> out;
  for (const auto& r : impl_->world->take_dirty_regions()) out.push_back({r.i0, r.j0, r.ni, r.nj});
  return out;
}

Status Terrain::select_clipmap(const ClipmapDef& def, const ClipmapView& view, ClipmapSelection& out) const {
  core::render::ClipmapDef d;
  d.n = def.n;
  d.levels = def.levels;
  d.base_spacing = def.base_spacing;
  d.transition = def.transition;
  d.height_factor = def.height_factor;
  if (core::Status s = core::render::validate(d); !s) {
    std::vector<Error> es = convert(s.errors(), "");
    for (auto& e : es)
      if (e.field.starts_with("clipmap.")) e.field = "ClipmapDef." + e.field.substr(8);
    return es;
  }
  Checker c{"ClipmapView.", "", {}};
  c.finite("viewer", view.viewer, "m");
  c.finite("view_proj", view.view_proj, "");
  if (!c.errs.empty()) return c.errs;
  const core::Heightfield& hf = impl_->hf();
  core::render::ClipmapView v;
  const float lx = float(view.viewer[0] - hf.origin_x()), lz = float(view.viewer[2] - hf.origin_z());
  v.viewer = {lx, float(view.viewer[1] - hf.origin_y()), lz};
  v.view_proj = Eigen::Map<const Eigen::Matrix4f>(view.view_proj.data());
  v.cull = view.cull;
  v.extent_x = hf.extent_x();
  v.extent_z = hf.extent_z();
  v.min_height = hf.min_height();
  v.max_height = hf.max_height();
  v.ground_height = hf.sample(lx, lz);
  core::render::ClipmapSelection sel;
  core::render::select_clipmap(d, v, sel);
  out.levels.clear();
  out.pieces.clear();
  for (const auto& l : sel.levels) out.levels.push_back({l.level, l.spacing, l.origin_x, l.origin_z, l.n, l.active, l.finest});
  for (const auto& p : sel.pieces) out.pieces.push_back({p.level, int(p.kind), p.gx, p.gz, p.cells_x, p.cells_z});
  out.triangles = sel.triangles;
  return Ok{};
}

// ---- report ----

std::string Terrain::report_json() const {
  ojson r;
  r["sandpatch_version"] = kVersion;
  const ojson w = impl_->world->report();
  for (const auto& [key, value] : w.items()) r[key] = value;
  return r.dump(2);
}

std::uint64_t Terrain::state_hash() const { return impl_->world->state_hash(); }

}  // namespace sandpatch::api
