// scene_to_json (scene.hpp): a SceneDef written back as JSON, every field with its value
// (`sandpatch stress` derives its scenes from it). The reader is scene/scene.cpp.
#include <cmath>
#include <nlohmann/json.hpp>

#include "scene/scene.hpp"

namespace sandpatch {

using json = nlohmann::json;

nlohmann::json scene_to_json(const SceneDef& s) {
  json j;
  j["version"] = kSceneFormatVersion;
  j["name"] = s.name;
  j["description"] = s.description;

  const TerrainDef& ter = s.terrain;
  json t;
  json src;
  src["type"] = to_string(ter.source_kind());
  if (!ter.procedural.empty()) {
    src["kind"] = ter.procedural;
    src["height"] = ter.base_height;
    src["slope_x"] = ter.slope_x;
    src["slope_z"] = ter.slope_z;
    src["amplitude"] = ter.amplitude;
    src["wavelength"] = ter.wavelength;
    src["seed"] = ter.noise_seed;
    src["octaves"] = ter.octaves;
    src["samples_x"] = ter.samples_x;
    src["samples_z"] = ter.samples_z;
  } else {
    src["file"] = ter.file;
    if (ter.source_kind() == TerrainSourceKind::RawF32) {
      src["samples_x"] = ter.samples_x;
      src["samples_z"] = ter.samples_z;
    }
  }
  t["source"] = src;
  if (ter.size) t["size"] = *ter.size;
  else t["spacing"] = ter.spacing;
  t["vertical_scale"] = ter.vertical_scale;
  t["vertical_offset"] = ter.vertical_offset;
  t["origin"] = ter.origin;
  if (ter.bedrock_height) t["bedrock_height"] = *ter.bedrock_height;
  else t["soil_depth"] = ter.soil_depth;
  t["patch_depth"] = ter.patch_depth;
  t["material"] = ter.material_name;
  j["terrain"] = t;

  j["materials"] = json::array();
  for (const auto& m : s.materials) {
    json mj;
    mj["name"] = m.name;
    mj["density"] = m.density;
    mj["friction"] = m.friction;
    if (m.damping_ratio) mj["damping_ratio"] = *m.damping_ratio;
    else mj["restitution"] = m.restitution;
    mj["stiffness"] = m.stiffness;
    mj["tangential_stiffness_ratio"] = m.tangential_stiffness_ratio;
    mj["unloading_stiffness_ratio"] = m.unloading_stiffness_ratio;
    mj["granule_radius"] = m.granule_radius;
    mj["packing_fraction"] = m.packing_fraction;
    j["materials"].push_back(mj);
  }

  j["bodies"] = json::array();
  for (const auto& b : s.bodies) {
    json bj, sh;
    bj["name"] = b.name;
    sh["type"] = to_string(b.shape.kind);
    switch (b.shape.kind) {
      case ShapeKind::Sphere: sh["radius"] = b.shape.radius; break;
      case ShapeKind::Box: sh["half_extents"] = b.shape.half_extents; break;
      case ShapeKind::Cylinder:
      case ShapeKind::Capsule:
        sh["radius"] = b.shape.radius;
        sh["height"] = b.shape.height;
        break;
      case ShapeKind::Mesh:
        sh["file"] = b.shape.mesh_file;
        sh["scale"] = b.shape.mesh_scale;
        sh["solid"] = b.shape.solid;
        break;
    }
    bj["shape"] = sh;
    bj["motion"] = to_string(b.motion);
    if (b.density) bj["density"] = *b.density;
    else if (b.motion == MotionKind::Dynamic) bj["mass"] = b.mass;
    if (b.keyframes.empty()) {
      bj["pose"] = {{"position", b.position}, {"orientation", b.orientation}};
    } else {
      json ks = json::array();
      for (const KeyframeDef& k : b.keyframes) ks.push_back({{"t", k.t}, {"position", k.position}, {"orientation", k.orientation}});
      bj["keyframes"] = ks;
    }
    bj["linear_velocity"] = b.linear_velocity;
    bj["angular_velocity"] = b.angular_velocity;
    bj["spawn_time"] = b.spawn_time;
    bj["friction"] = b.friction;
    bj["restitution"] = b.restitution;
    bj["rolling_friction"] = b.rolling_friction;
    if (!b.loads.empty()) {
      json loads = json::array();
      for (const LoadDef& l : b.loads) {
        json lj = json::object();
        if (l.impulse) {
          lj["impulse"] = *l.impulse;
        } else {
          lj["force"] = l.force;
          lj["torque"] = l.torque;
        }
        if (l.at) lj["at"] = *l.at;
        lj["from"] = l.from;
        if (l.until) lj["until"] = *l.until;
        lj["frame"] = to_string(l.frame);
        loads.push_back(lj);
      }
      bj["loads"] = loads;
    }
    j["bodies"].push_back(bj);
  }

  // Only when there are vehicles, so scenes without them keep their canonical JSON and hash.
  if (!s.vehicles.empty()) {
    j["vehicles"] = json::array();
    for (const VehicleSceneDef& vs : s.vehicles) {
      const api::VehicleDef& v = vs.def;
      json vj = {{"name", v.name},
                 {"position", v.position},
                 {"orientation", {double(v.orientation[0]), double(v.orientation[1]), double(v.orientation[2]), double(v.orientation[3])}},
                 {"chassis_half_extents", v.chassis_half_extents},
                 {"chassis_mass", v.chassis_mass},
                 {"wheel_radius", v.wheel_radius},
                 {"wheel_width", v.wheel_width},
                 {"wheel_mass", v.wheel_mass},
                 {"wheel_friction", v.wheel_friction},
                 {"wheel_rolling_friction", v.wheel_rolling_friction},
                 {"wheelbase", v.wheelbase},
                 {"track", v.track},
                 {"axle_height", v.axle_height},
                 {"drive", to_string(v.drive)},
                 {"wheel_speed", v.wheel_speed},
                 {"max_torque", v.max_torque},
                 {"steering_angle", v.steering_angle},
                 {"max_steering_angle", v.max_steering_angle},
                 {"steering_speed", v.steering_speed},
                 {"suspension_stiffness", v.suspension_stiffness},
                 {"suspension_damping", v.suspension_damping},
                 {"suspension_travel", v.suspension_travel}};
      json th = json::array(), st = json::array();
      for (const ThrottlePhaseDef& t : vs.throttle) {
        json pj = {{"from", t.from}, {"wheel_speed", t.wheel_speed}, {"max_torque", t.max_torque}};
        if (t.until) pj["until"] = *t.until;
        th.push_back(pj);
      }
      for (const SteeringPhaseDef& t : vs.steering) {
        json pj = {{"from", t.from}, {"angle", t.angle}};
        if (t.until) pj["until"] = *t.until;
        st.push_back(pj);
      }
      if (!th.empty()) vj["throttle"] = th;
      if (!st.empty()) vj["steering"] = st;
      j["vehicles"].push_back(vj);
    }
  }
  // Only when there are joints, so scenes without them keep their canonical JSON and hash.
  if (!s.joints.empty()) {
    j["joints"] = json::array();
    for (const JointDef& d : s.joints) {
      json jj = {{"name", d.name}, {"type", to_string(d.type)}, {"body_a", d.body_a}};
      if (!d.body_b.empty()) jj["body_b"] = d.body_b;
      jj["anchor"] = d.anchor;
      if (d.type != JointType::Fixed) {
        jj["axis"] = d.axis;
        if (d.limits) jj["limits"] = *d.limits;
        jj["spring"] = {{"stiffness", d.spring_stiffness}, {"damping", d.spring_damping}};
        json phases = json::array();
        for (const MotorPhaseDef& m : d.motor) {
          json pj = {{"from", m.from}};
          if (m.until) pj["until"] = *m.until;
          if (m.target_velocity) pj["target_velocity"] = *m.target_velocity;
          if (m.target_position) {
            pj["target_position"] = *m.target_position;
            pj["servo_speed"] = m.servo_speed;
          }
          pj[d.type == JointType::Hinge ? "max_torque" : "max_force"] = m.max_force;
          phases.push_back(pj);
        }
        if (!phases.empty()) jj["motor"] = phases;
      }
      j["joints"].push_back(jj);
    }
  }

  const auto& sim = s.simulation;
  j["simulation"] = {
      {"dt", sim.dt},
      {"substeps", sim.substeps},
      {"duration", sim.duration},
      {"backend", ter.backend},
      {"threads", ter.threads},
      {"pool", {{"slots", ter.slots}, {"granules_per_slot", ter.granules_per_slot},
                {"shell_spheres_per_slot", ter.shell_spheres_per_slot}}},
      {"particle_scale", ter.particle_scale},
      {"steps_per_contact", ter.steps_per_contact},
      {"max_substeps", ter.max_substeps},
      {"lod", {{"horizon", ter.lod_horizon}, {"margin", ter.lod_margin}, {"apron", ter.lod_apron}, {"travel", ter.lod_travel}}},
      {"sleep", {{"speed_threshold", ter.sleep_speed}, {"hold_time", ter.sleep_time}, {"region_hold_time", ter.region_sleep_time}, {"regions", ter.sleep_regions}}},
      {"idle_timeout", ter.idle_timeout},
      {"granular_patches", ter.granular_patches},
      {"gravity", ter.gravity},
      {"seed", ter.seed},
  };
  // Only when one was applied (every field above already holds its values), so scenes without
  // a preset keep their canonical JSON and hash.
  if (!sim.preset.empty()) j["simulation"]["preset"] = sim.preset;
  // Only when given (absent: half of dt), so scenes without one keep their canonical JSON.
  if (ter.frame_budget_ms) {
    if (std::isinf(*ter.frame_budget_ms)) j["simulation"]["frame_budget_ms"] = "off";
    else j["simulation"]["frame_budget_ms"] = *ter.frame_budget_ms;
  }
  if (sim.scale_by_distance) {
    json bands = json::array();
    for (const auto& b : sim.scale_by_distance->bands)
      bands.push_back({{"max_distance", b.max_distance}, {"particle_scale", b.particle_scale}});
    j["simulation"]["scale_by_distance"] = {{"camera", sim.scale_by_distance->camera}, {"bands", bands}};
  }

  j["cameras"] = json::array();
  for (const auto& cam : s.cameras) {
    json cj;
    cj["name"] = cam.name;
    if (cam.path.empty()) {
      cj["position"] = cam.position;
      cj["target"] = cam.target;
    } else {
      cj["path"] = json::array();
      for (const auto& k : cam.path) {
        cj["path"].push_back({{"time", k.time}, {"position", k.position}, {"target", k.target}});
      }
    }
    cj["fov_deg"] = cam.fov_deg;
    cj["width"] = cam.width;
    cj["height"] = cam.height;
    j["cameras"].push_back(cj);
  }

  json out;
  out["frames"] = json::array();
  for (const auto& f : s.outputs.frames) {
    json fj{{"camera", f.camera}, {"file", f.file}};
    if (f.every_k_frames > 0) fj["every_k_frames"] = f.every_k_frames;
    else fj["times"] = f.times;
    out["frames"].push_back(fj);
  }
  out["heightfields"] = json::array();
  for (const auto& h : s.outputs.heightfields) {
    json hj{{"format", to_string(h.format)}, {"at_end", h.at_end}, {"file", h.file}};
    if (!h.times.empty()) hj["times"] = h.times;
    out["heightfields"].push_back(hj);
  }
  out["report"] = s.outputs.report;
  if (!s.outputs.csv.empty()) out["csv"] = s.outputs.csv;
  j["outputs"] = out;
  return j;
}

}  // namespace sandpatch
