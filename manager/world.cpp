#include "manager/world.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "common/hash.hpp"

namespace sandpatch {
namespace {

using Clock = std::chrono::steady_clock;
using ojson = nlohmann::ordered_json;

ojson vec_json(const Eigen::Vector3d& v) { return ojson::array({v.x(), v.y(), v.z()}); }
ojson vec_json(const Eigen::Vector3f& v) { return ojson::array({v.x(), v.y(), v.z()}); }

bool same(RigidBodyId a, RigidBodyId b) { return a.index == b.index && a.generation == b.generation; }

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

}  // namespace

Result<std::unique_ptr<World>> World::create(Heightfield terrain, const Eigen::Vector3f& gravity) {
  std::unique_ptr<World> w(new World());
  w->hf_ = std::make_unique<Heightfield>(std::move(terrain));
  auto bullet = BulletWorld::create(*w->hf_, gravity);
  if (!bullet) return bullet.errors();
  w->bullet_ = std::move(*bullet);
  return w;
}

World::~World() = default;

Status World::enable_patches(const TerrainManagerDef& def) {
  if (manager_) return Error{"", "World.patches", "", "enable_patches may be called once"};
  auto m = TerrainManager::create(def, *hf_, *bullet_);
  if (!m) return m.errors();
  manager_ = std::move(*m);
  return Ok{};
}

// ---- bodies ----

Result<RigidBodyId> World::add_body(const RigidBodyDef& def) {
  auto id = bullet_->add_body(def);
  if (id) entries_.push_back({def.name, time(), *id, false});
  return id;
}

Result<RigidBodyId> World::adopt_body(btRigidBody* body, const std::string& name) {
  auto id = bullet_->adopt_body(body, name);
  if (id) entries_.push_back({name, time(), *id, false});
  return id;
}

std::size_t World::schedule_body(const RigidBodyDef& def, double spawn_time) {
  entries_.push_back({def.name, spawn_time, RigidBodyId{}, false});
  pending_.emplace_back(entries_.size() - 1, def);
  return entries_.size() - 1;
}

void World::remove_body(RigidBodyId id) {
  if (!alive(id)) return;
  for (Entry& e : entries_)
    if (same(e.id, id)) e.removed = true;
  if (!manager_ || bullet_->adopted(id)) {
    bullet_->remove_body(id);
    return;
  }
  BodyState st = bullet_->state(id);
  st.position.y() = hf_->origin_y() + double(hf_->max_height()) + 1000.0;  // m, far above any patch
  st.linear_velocity.setZero();
  st.angular_velocity.setZero();
  bullet_->set_state(id, st);
  removing_.push_back(id);
}

void World::discard_body(RigidBodyId id) {
  if (!alive(id)) return;
  for (Entry& e : entries_)
    if (same(e.id, id)) e.removed = true;
  bullet_->remove_body(id);
}

bool World::alive(RigidBodyId id) const {
  if (!bullet_->alive(id)) return false;
  return std::none_of(removing_.begin(), removing_.end(), [&](RigidBodyId r) { return same(r, id); });
}

std::vector<RigidBodyId> World::bodies() const {
  std::vector<RigidBodyId> out;
  for (RigidBodyId id : bullet_->bodies())
    if (alive(id)) out.push_back(id);
  return out;
}

// ---- the frame ----

void World::set_camera(const Eigen::Vector3d& position) {
  if (manager_) manager_->set_camera(position);
}

Status World::fail(const char* stage, Status s) {
  failed_stage_ = stage;
  std::vector<Error> es = s.errors();
  for (Error& e : es)
    e.detail += std::string(e.detail.empty() ? "" : "; ") + "in the " + stage + " stage at t = " + format_number(time()) + " s";
  return es;
}

// Position, orientation and velocities of every body in the Bullet world finite.
Status World::check_bodies(const char* stage) {
  for (RigidBodyId id : bullet_->bodies()) {
    const BodyState st = bullet_->state(id);
    if (st.position.allFinite() && st.orientation.coeffs().allFinite() && st.linear_velocity.allFinite() &&
        st.angular_velocity.allFinite())
      continue;
    const std::string& name = bullet_->definition(id).name;
    failed_stage_ = stage;
    return Error{"", "body",
                 name.empty() ? "{" + std::to_string(id.index) + ", " + std::to_string(id.generation) + "}" : "'" + name + "'",
                 "has a non-finite state after the " + std::string(stage) + " stage at t = " + format_number(time()) + " s"};
  }
  return Ok{};
}

Status World::step(double dt, int substeps) {
  if (!(dt > 0) || !std::isfinite(dt) || substeps < 1)
    return Error{"", "step", "dt = " + format_number(dt) + ", substeps = " + std::to_string(substeps),
                 "dt must be finite and > 0 (s), substeps >= 1"};
  failed_stage_ = "";
  if (dt != dt_) {  // a new step size: the time so far becomes the base
    time_base_ = time();
    dt_ = dt;
    steps_at_dt_ = 0;
  }
  const double t = time();  // s, at the start of this frame
  const auto f0 = Clock::now();
  const std::size_t events_before = manager_ ? manager_->events().size() : 0;
  bool conversion = filling_ > 0;

  if (!entries_.empty()) {
    auto timer = profile_.time(Stage::Spawn);
    for (auto it = pending_.begin(); it != pending_.end();) {
      Entry& e = entries_[it->first];
      if (e.spawn_time > t + 1e-9) {
        ++it;
        continue;
      }
      auto id = bullet_->add_body(it->second);
      if (!id) return fail("spawn", id.errors());
      e.id = *id;
      it = pending_.erase(it);
    }
  }
  if (manager_) {
    if (Status s = manager_->before_bodies(t, dt, profile_); !s) return fail("dem", s);
    if (Status s = check_bodies("dem"); !s) return s;
  }
  for (RigidBodyId id : removing_) bullet_->remove_body(id);  // their shells are let go of now
  removing_.clear();
  {
    auto timer = profile_.time(Stage::Bodies);
    bullet_->step_frame(float(dt), substeps);  // the patches' forces act over every substep
    if (Status s = check_bodies("bodies"); !s) return s;
  }
  if (manager_) {
    if (Status s = manager_->after_bodies(t, dt, profile_); !s) return fail("demotion", s);
    if (Status s = check_bodies("demotion"); !s) return s;
    for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
    peak_granules_ = std::max(peak_granules_, manager_->granules());
    const auto& ev = manager_->events();
    for (std::size_t k = events_before; k < ev.size(); ++k) {
      const PatchEventKind kind = ev[k].kind;
      filling_ += kind == PatchEventKind::Promoted;
      filling_ -= kind == PatchEventKind::Ready;
      conversion = conversion || kind == PatchEventKind::Promoted || kind == PatchEventKind::Ready ||
                   kind == PatchEventKind::Demoted;
    }
  }
  ++steps_at_dt_;
  ++steps_;
  last_frame_ = {std::chrono::duration<double, std::milli>(Clock::now() - f0).count(), conversion};
  if (frame_ms_.size() < kFrameWindow) frame_ms_.push_back(last_frame_.wall_ms);
  else frame_ms_[std::size_t(steps_ - 1) % kFrameWindow] = last_frame_.wall_ms;
  frame_max_ms_ = std::max(frame_max_ms_, last_frame_.wall_ms);
  if (conversion) conversion_max_ms_ = std::max(conversion_max_ms_, last_frame_.wall_ms), ++conversion_frames_;
  return Ok{};
}

Status World::demote_all() {
  if (!manager_) return Ok{};
  if (Status s = manager_->demote_all(time(), profile_); !s) return fail("demotion", s);
  for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
  return Ok{};
}

std::vector<GridRegion> World::take_dirty_regions() {
  if (manager_)
    for (const GridRegion& r : manager_->take_dirty_regions()) dirty_.push_back(r);
  std::vector<GridRegion> out;
  out.swap(dirty_);
  return out;
}

// ---- results ----

std::uint64_t World::state_hash() const {
  Hasher h;
  h.pod(time());
  for (RigidBodyId id : bodies()) {
    const BodyState s = bullet_->state(id);
    h.pod(id.index);
    h.pod(s.position);
    h.pod(s.orientation.coeffs());
    h.pod(s.linear_velocity);
    h.pod(s.angular_velocity);
  }
  h.pod(hf_->hash());
  if (manager_) h.pod(manager_->state_hash());
  return h.value();
}

nlohmann::ordered_json World::report() const {
  ojson r;
  r["simulated_s"] = time();
  r["steps"] = steps_;
  r["stages"] = profile_.to_json();

  // Frame times (the step only) and stutter: the longest frame in which a patch was
  // promoted, uploaded or demoted, against the median frame.
  const double med = median(frame_ms_);
  const double mx = frame_max_ms_, conv_max = conversion_max_ms_;
  const long long conv_frames = conversion_frames_;
  r["frames"] = {{"median_ms", med},
                 {"max_ms", mx},
                 {"max_over_median", med > 0 ? mx / med : 0.0},
                 {"conversion_frames", conv_frames},
                 {"conversion_max_ms", conv_max},
                 {"conversion_max_over_median", med > 0 ? conv_max / med : 0.0}};

  ojson bodies = ojson::array();
  int live = 0, spawned = 0, resting = 0;
  for (const Entry& e : entries_) {
    if (e.removed) continue;
    ++live;
    ojson b = {{"name", e.name}, {"spawned", e.spawned()}};
    if (e.spawned()) {
      ++spawned;
      const BodyState s = bullet_->state(e.id);
      const bool rest = s.linear_velocity.norm() < 0.05f && s.angular_velocity.norm() < 0.05f;
      resting += rest;
      b["position_m"] = vec_json(s.position);
      b["orientation_wxyz"] = ojson::array({s.orientation.w(), s.orientation.x(), s.orientation.y(), s.orientation.z()});
      b["linear_velocity_m_s"] = vec_json(s.linear_velocity);
      b["angular_velocity_rad_s"] = vec_json(s.angular_velocity);
      b["at_rest"] = rest;
    }
    bodies.push_back(b);
  }
  const Heightfield& hf = *hf_;
  r["counts"] = {{"bodies", live},
                 {"bodies_spawned", spawned},
                 {"bodies_at_rest", resting},
                 {"terrain_samples", std::int64_t(hf.samples_x()) * hf.samples_z()},
                 {"terrain_tiles", bullet_->terrain_tile_count()},
                 {"peak_granules", peak_granules_}};
  if (manager_) {
    r["patches_live"] = manager_->active_patches();
    r["granules_live"] = manager_->granules();
    const ojson m = manager_->report();  // named: iterating a temporary's items() dangles
    for (const auto& [key, value] : m.items()) r[key] = value;
    // The frame's dem stage against the DEM's step calls in it: the rest is the coupling
    // (carriers, shells, forces to and from Bullet).
    if (r.contains("dem")) {
      ojson& t = r["dem"]["total"];
      const double stage_ms = profile_.timer(Stage::Dem).total_ms, step_ms = t["wall_ms"].get<double>();
      t["frame_stage_ms"] = stage_ms;
      t["step_share_of_frame_stage"] = stage_ms > 0 ? step_ms / stage_ms : 0.0;
    }
  }
  r["terrain"] = {{"samples_x", hf.samples_x()},
                  {"samples_z", hf.samples_z()},
                  {"spacing_m", hf.spacing()},
                  {"origin_m", ojson::array({hf.origin_x(), hf.origin_y(), hf.origin_z()})},
                  {"min_height_m", hf.origin_y() + hf.min_height()},
                  {"max_height_m", hf.origin_y() + hf.max_height()},
                  {"hash", Hasher::to_hex(hf.hash())}};
  r["bodies"] = bodies;
  r["final_state_hash"] = Hasher::to_hex(state_hash());
  return r;
}

}  // namespace sandpatch
