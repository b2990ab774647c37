#include "manager/scene_world.hpp"

#include "manager/terrain.hpp"
#include "manager/definitions.hpp"
#include "scene/mesh.hpp"

namespace sandpatch {
namespace {

Eigen::Vector3f vec3f(const Vec3d& v) { return {float(v[0]), float(v[1]), float(v[2])}; }

}  // namespace

// Camera pose at simulated time t: fixed, or linear between path keyframes (held outside).
render::CameraView camera_at(const CameraDef& c, double t) {
  render::CameraView v;
  Eigen::Vector3d p(c.position[0], c.position[1], c.position[2]), q(c.target[0], c.target[1], c.target[2]);
  if (!c.path.empty()) {
    auto key = [](const CameraKeyDef& k, Eigen::Vector3d& pos, Eigen::Vector3d& tgt) {
      pos = {k.position[0], k.position[1], k.position[2]};
      tgt = {k.target[0], k.target[1], k.target[2]};
    };
    key(c.path.front(), p, q);
    for (std::size_t k = 1; k < c.path.size(); ++k) {
      const CameraKeyDef& a = c.path[k - 1];
      const CameraKeyDef& b = c.path[k];
      if (t < a.time) break;
      if (t >= b.time) {
        key(b, p, q);
        continue;
      }
      Eigen::Vector3d pa, qa, pb, qb;
      key(a, pa, qa);
      key(b, pb, qb);
      const double u = (t - a.time) / (b.time - a.time);
      p = pa + u * (pb - pa);
      q = qa + u * (qb - qa);
      break;
    }
  }
  v.position = p;
  v.target = q;
  v.fov_deg = float(c.fov_deg);
  v.width = c.width;
  v.height = c.height;
  return v;
}

std::vector<World::Load> to_loads(const BodyDef& body) {
  std::vector<World::Load> out;
  for (const LoadDef& l : body.loads) {
    World::Load w;
    w.force = vec3f(l.force);
    w.torque = vec3f(l.torque);
    w.at_centre = !l.at.has_value();
    if (l.at) w.at = vec3f(*l.at);
    w.from = l.from;
    if (l.until) w.until = *l.until;
    w.body_frame = l.frame == LoadFrame::Body;
    if (l.impulse) {
      w.is_impulse = true;
      w.impulse = vec3f(*l.impulse);
    }
    out.push_back(w);
  }
  return out;
}

RigidJointDef to_rigid_joint(const JointDef& j) {
  RigidJointDef d;
  d.name = j.name;
  d.kind = j.type == JointType::Fixed ? JointKind::Fixed : j.type == JointType::Slider ? JointKind::Slider : JointKind::Hinge;
  d.anchor = {j.anchor[0], j.anchor[1], j.anchor[2]};
  d.axis = vec3f(j.axis);
  JointDof& f = d.kind == JointKind::Slider ? d.slide : d.turn;
  if (j.limits) {
    f.limited = true;
    f.lower = float((*j.limits)[0]);
    f.upper = float((*j.limits)[1]);
  }
  f.stiffness = float(j.spring_stiffness);
  f.damping = float(j.spring_damping);
  return d;  // the motor outside every phase: none
}

std::vector<World::MotorPhase> to_motor_phases(const JointDef& j) {
  std::vector<World::MotorPhase> out;
  for (const MotorPhaseDef& m : j.motor) {
    World::MotorPhase p;
    p.from = m.from;
    if (m.until) p.until = *m.until;
    p.turn = j.type != JointType::Slider;
    p.motor.mode = m.target_position ? MotorMode::Position : MotorMode::Velocity;
    p.motor.target = float(m.target_position ? *m.target_position : m.target_velocity.value_or(0.0));
    p.motor.max_force = float(m.max_force);
    p.motor.servo_speed = float(m.servo_speed);
    out.push_back(p);
  }
  return out;
}

JointMotor core_motor(const api::JointMotor& m) {
  JointMotor c;
  c.mode = m.mode == api::MotorMode::Velocity   ? MotorMode::Velocity
           : m.mode == api::MotorMode::Position ? MotorMode::Position
                                                : MotorMode::Off;
  c.target = float(m.target);
  c.max_force = float(m.max_force);
  c.servo_speed = float(m.servo_speed);
  return c;
}

RigidJointDef vehicle_joint_def(const VehicleJoint& j) {
  RigidJointDef d;
  d.name = j.name;
  d.kind = JointKind::Wheel;
  d.anchor = {j.anchor[0], j.anchor[1], j.anchor[2]};
  d.axis = {float(j.axis[0]), float(j.axis[1]), float(j.axis[2])};
  d.up = {float(j.up[0]), float(j.up[1]), float(j.up[2])};
  d.max_steer = float(j.max_steer);
  d.turn.motor = core_motor(j.drive);
  d.slide.limited = j.slide_limited;
  d.slide.lower = float(j.slide_lower);
  d.slide.upper = float(j.slide_upper);
  d.slide.stiffness = float(j.stiffness);
  d.slide.damping = float(j.damping);
  return d;
}

// The parser filled the library's BodyDef; what only scene files have (keyframes, loads, the
// spawn time) the run schedules beside it.
api::BodyDef body_def(const SceneDef& scene, std::size_t index) { return scene.bodies[index]; }

Result<RigidBodyDef> to_rigid_body(const SceneDef& scene, std::size_t index) {
  auto r = rigid_body_def(body_def(scene, index));
  if (r) return r;
  std::vector<Error> es = r.errors();
  const std::string at = "bodies[" + std::to_string(index) + "].";
  for (Error& e : es) {
    if (e.field.starts_with("BodyDef.")) e.field = at + e.field.substr(8);
    if (e.field == at + "shape.mesh_file") e.field = at + "shape.file";
    if (e.file.empty()) e.file = scene.source_path;
  }
  return es;
}

// The parser filled the library's TerrainDef (the terrain and simulation sections and the
// named material); a run gives its own thread count and backend, and renders the demotion's
// depth on GL when it can make a context.
api::TerrainDef terrain_def(const SceneDef& scene, int threads, const std::string& backend) {
  api::TerrainDef t = scene.terrain;
  t.patch_depth = std::min(t.patch_depth, t.soil_depth);  // with a flat bedrock, at most the default soil depth
  t.threads = threads;
  t.backend = backend;
  t.gl_depth_render = true;
  return t;
}

TerrainManagerDef manager_def(const SceneDef& scene, const Heightfield& hf, int threads, const std::string& backend) {
  const SceneSimulationDef& sim = scene.simulation;
  TerrainManagerDef d = manager_def(terrain_def(scene, threads, backend));
  // Particle scale by distance from a camera (scenario 2 of Leach & Marais §6.3): the bands,
  // and the camera where it is at the start; the run moves it (World::set_camera).
  if (const auto& sd = sim.scale_by_distance) {
    for (const auto& b : sd->bands) d.scale_bands.push_back({b.max_distance, b.particle_scale});
    d.camera = camera_at(*scene.find_camera(sd->camera), 0.0).position.cast<double>();
  }
  // A flat bedrock (terrain.bedrock_height) bounds the patches too (heightfield-local m).
  if (scene.terrain.bedrock_height) d.bedrock_height = bedrock_world_height(scene, hf, 0, 0) - hf.origin_y();
  return d;
}

Result<std::unique_ptr<World>> make_world(const SceneDef& scene, int threads, const std::string& backend,
                                          std::string* stage, bool patches,
                                          const std::function<void(const std::string&, double, double, double)>& on_settle) {
  std::string unused;
  std::string& part = stage ? *stage : unused;
  part = "terrain";
  auto hf_result = load_scene_terrain(scene);
  if (!hf_result) return hf_result.errors();
  part = "bodies";
  const Heightfield& hf = *hf_result;
  auto below = check_bodies_against_terrain(
      scene, [&](double x, double z) { return float(bedrock_world_height(scene, hf, x, z)); });
  if (!below.empty()) return below;
  // A body whose centre starts below the terrain surface is inside the terrain: Bullet's
  // heightfield contact pushes a body along the triangle's normal from the side its centre is
  // on, so it would be pushed down and fall for ever. Refused, naming the body and where it is
  // (docs/extremes.md). A body only partly in the ground (centre above the surface) is pushed
  // out by the contact. Checked against the terrain at the start, for every body (also those
  // spawned later).
  std::vector<Error> inside;
  const double w = (hf.samples_x() - 1) * double(hf.spacing()), d = (hf.samples_z() - 1) * double(hf.spacing());
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const BodyDef& b = scene.bodies[i];
    if (b.motion != MotionKind::Dynamic) continue;  // Bullet does not push a kinematic or static body out of the ground
    const double x = b.position[0] - hf.origin_x(), z = b.position[2] - hf.origin_z();
    if (x < 0 || z < 0 || x > w || z > d) continue;  // no terrain under it
    const double surface = hf.origin_y() + hf.sample(float(x), float(z));
    if (b.position[1] >= surface) continue;
    inside.push_back(Error{scene.source_path, "bodies[" + std::to_string(i) + "].pose.position",
                           "[" + format_number(b.position[0]) + ", " + format_number(b.position[1]) + ", " +
                               format_number(b.position[2]) + "]",
                           "body '" + b.name + "' starts inside the terrain: its centre is below the surface (world y = " +
                               format_number(surface) + " m there); it must start at or above it",
                           "its lowest point may touch or enter the ground, its centre may not"});
  }
  if (!inside.empty()) return inside;
  std::vector<RigidBodyDef> body_defs;
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    auto def = to_rigid_body(scene, i);
    if (!def) return def.errors();
    body_defs.push_back(std::move(*def));
  }
  // The vehicles' parts follow the bodies (scene/vehicle.hpp: one expansion for both doors);
  // their joints precede the scene's joints. Each part's centre must start above the terrain.
  struct SceneJoint {
    RigidJointDef def;
    std::size_t a, b;                    // indices into body_defs (b = World::kWorld: the world)
    std::vector<World::MotorPhase> phases;
    std::string field;                   // for errors: "vehicles[0]" or "joints[2]"
    JointMotor steer_default;            // a steered wheel: its steering outside every phase
  };
  std::vector<SceneJoint> joint_defs;
  std::vector<std::string> body_fields;  // for errors, by body_defs index
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) body_fields.push_back("bodies[" + std::to_string(i) + "]");
  for (std::size_t i = 0; i < scene.vehicles.size(); ++i) {
    const VehicleSceneDef& vs = scene.vehicles[i];
    const std::string field = "vehicles[" + std::to_string(i) + "]";
    const VehicleParts parts = expand_vehicle(vs.def);
    const std::size_t base = body_defs.size();
    for (const api::BodyDef& b : parts.bodies) {
      const double x = b.position[0] - hf.origin_x(), z = b.position[2] - hf.origin_z();
      if (x >= 0 && z >= 0 && x <= w && z <= d) {
        const double surface = hf.origin_y() + hf.sample(float(x), float(z));
        if (b.position[1] < surface)
          return Error{scene.source_path, field + ".position",
                       "[" + format_number(vs.def.position[0]) + ", " + format_number(vs.def.position[1]) + ", " +
                           format_number(vs.def.position[2]) + "]",
                       "the vehicle's part '" + b.name + "' starts inside the terrain: its centre is below the surface (world y = " +
                           format_number(surface) + " m there); raise the vehicle"};
      }
      // The parts go the way every body does (manager/definitions.hpp).
      auto part_def = rigid_body_def(b);
      if (!part_def) {
        std::vector<Error> es = part_def.errors();
        for (Error& e : es) {
          if (e.field.starts_with("BodyDef.")) e.field = field + " (" + b.name + ")." + e.field.substr(8);
          if (e.file.empty()) e.file = scene.source_path;
        }
        return es;
      }
      body_defs.push_back(std::move(*part_def));
      body_fields.push_back(field);
    }
    for (std::size_t k = 0; k < parts.joints.size(); ++k) {
      const VehicleJoint& j = parts.joints[k];
      SceneJoint sj{vehicle_joint_def(j), base + std::size_t(j.a), base + std::size_t(j.b), {}, field, {}};
      if (parts.steered[k]) {
        sj.steer_default.target = float(vs.def.steering_angle);
        sj.steer_default.servo_speed = float(vs.def.steering_speed);
        for (const SteeringPhaseDef& p : vs.steering) {
          World::MotorPhase m;
          m.from = p.from;
          if (p.until) m.until = *p.until;
          m.steer = true;
          m.motor.target = float(p.angle);
          m.motor.servo_speed = float(vs.def.steering_speed);
          sj.phases.push_back(m);
        }
      }
      if (parts.driven[k])
        for (const ThrottlePhaseDef& p : vs.throttle) {
          World::MotorPhase m;
          m.from = p.from;
          if (p.until) m.until = *p.until;
          m.turn = true;
          m.motor = core_motor(drive_motor(p.wheel_speed, p.max_torque));
          sj.phases.push_back(m);
        }
      joint_defs.push_back(std::move(sj));
    }
  }
  // Bodies by name, the vehicles' parts too (the parser checked that every joint's names exist).
  auto body_index = [&](const std::string& name) {
    std::size_t k = 0;
    while (k < body_defs.size() && body_defs[k].name != name) ++k;
    return k;
  };
  for (std::size_t i = 0; i < scene.joints.size(); ++i) {
    const JointDef& j = scene.joints[i];
    joint_defs.push_back({to_rigid_joint(j), body_index(j.body_a), j.body_b.empty() ? World::kWorld : body_index(j.body_b),
                          to_motor_phases(j), "joints[" + std::to_string(i) + "]", {}});
  }
  // Bodies are added at their spawn time: Bullet's own checks run now, on a scratch world, so
  // that a body it would refuse is bad input before frame 0 and not a failure mid-run.
  {
    part = "bodies";
    auto scratch = BulletWorld::create(hf, vec3f(scene.terrain.gravity));
    if (!scratch) return scratch.errors();
    std::vector<RigidBodyId> ids;
    for (std::size_t i = 0; i < body_defs.size(); ++i) {
      auto id = (*scratch)->add_body(body_defs[i]);
      if (!id) {
        std::vector<Error> es = id.errors();
        for (Error& e : es) {
          e.file = scene.source_path;
          e.field = body_fields[i] + (e.field.empty() ? "" : " (" + e.field + ")");
        }
        return es;
      }
      ids.push_back(*id);
    }
    // The joints too, between the bodies at their starting poses: what Bullet would refuse
    // when the run makes them is refused now, naming joints[i].field (vehicles[i]: the
    // joint's name says which).
    part = "joints";
    for (const SceneJoint& sj : joint_defs) {
      RigidJointDef d = sj.def;
      d.a = ids[sj.a];
      if (sj.b != World::kWorld) d.b = ids[sj.b];
      std::vector<Error> es = (*scratch)->check_joint(d);
      for (const auto& p : sj.phases)
        for (Error& e : BulletWorld::check_motor(p.motor, p.turn, "motor")) es.push_back(std::move(e));
      if (!es.empty()) {
        for (Error& e : es) {
          e.file = scene.source_path;
          if (sj.field.starts_with("vehicles")) e.detail += (e.detail.empty() ? "" : "; ") + std::string("joint '") + d.name + "'";
          e.field = sj.field + "." + e.field;
        }
        return es;
      }
    }
  }
  TerrainManagerDef md;
  if (scene.terrain.granular_patches) md = manager_def(scene, hf, threads, backend);
  md.on_settle = on_settle;
  auto world = World::create(std::move(*hf_result), vec3f(scene.terrain.gravity));
  if (!world) return world.errors();
  if (scene.terrain.granular_patches && patches) {
    part = "activation";
    if (Status s = (*world)->enable_patches(md); !s) return s.errors();
  }
  // Every body's shell (the vehicles' parts too) must fit a slot: checked here whether or not
  // the pool is built (`sandpatch check`).
  for (std::size_t i = 0; i < body_defs.size() && scene.terrain.granular_patches; ++i)
    if (Status s = check_shell(md, body_defs[i].shape); !s) {
      part = "bodies";
      std::vector<Error> es = s.errors();
      for (Error& e : es) {
        e.file = scene.source_path;
        e.detail += std::string(e.detail.empty() ? "" : "; ") + "for " + body_fields[i] + " ('" + body_defs[i].name + "')";
      }
      return es;
    }
  for (std::size_t i = 0; i < scene.bodies.size(); ++i) {
    const std::size_t entry = (*world)->schedule_body(body_defs[i], scene.bodies[i].spawn_time);
    if (!scene.bodies[i].loads.empty()) (*world)->set_loads(entry, to_loads(scene.bodies[i]));
    if (!scene.bodies[i].keyframes.empty()) {
      std::vector<World::Keyframe> keys;
      for (const KeyframeDef& k : scene.bodies[i].keyframes) {
        World::Keyframe w;
        w.t = k.t;
        w.position = {k.position[0], k.position[1], k.position[2]};
        w.orientation = Eigen::Quaterniond(k.orientation[0], k.orientation[1], k.orientation[2], k.orientation[3]);
        keys.push_back(w);
      }
      if (Status s = (*world)->set_keyframes(entry, std::move(keys)); !s) {
        std::vector<Error> es = s.errors();
        for (Error& e : es) {
          e.file = scene.source_path;
          e.field = "bodies[" + std::to_string(i) + "]." + e.field;
        }
        return es;
      }
    }
  }
  // The vehicles' parts enter at the start, after the scene's bodies (entry = body_defs index).
  for (std::size_t i = scene.bodies.size(); i < body_defs.size(); ++i) (*world)->schedule_body(body_defs[i], 0.0);
  for (const SceneJoint& sj : joint_defs) {
    const std::size_t e = (*world)->schedule_joint(sj.def, sj.a, sj.b);
    if (!sj.phases.empty() || sj.steer_default.servo_speed > 0) (*world)->set_motor_phases(e, sj.phases, sj.steer_default);
  }
  return world;
}

}  // namespace sandpatch
