// Pool of GPU granule simulations; see gl_pool.hpp.
#include "particles/gpu/gl_pool.hpp"

#include <cassert>
#include <cstdio>

namespace sandpatch::gpu {

Result<GlPool> GlPool::create(const GlPoolDef& d) {
  if (d.slots < 1 || d.slots > 256)
    return Error{"", "GlPoolDef.slots", std::to_string(d.slots), "must be in [1, 256]", ""};
  if (d.upload_bytes_per_frame < 1)
    return Error{"", "GlPoolDef.upload_bytes_per_frame", "0", "must be > 0 (bytes)", ""};
  GlPool pool;
  pool.def_ = d;
  GlOptions o = d.options;
  o.upload_in_step = false;  // the pool applies its own per-frame budget
  for (int k = 0; k < d.slots; ++k) {
    auto s = GlSimulation::create(d.capacity, o);
    if (!s) {
      std::vector<Error> es = s.errors();
      for (auto& e : es) e.field = "GlPoolDef.capacity: " + e.field;
      return es;
    }
    pool.sims_.push_back(std::move(*s));
  }
  pool.used_.assign(std::size_t(d.slots), false);
  return pool;
}

Result<int> GlPool::acquire(const SimulationDef& def) {
  int slot = -1;
  for (int k = 0; k < int(used_.size()) && slot < 0; ++k)
    if (!used_[k]) slot = k;
  if (slot < 0)
    return Error{"", "GlPoolDef.slots", std::to_string(def_.slots),
                 "all slots are in use: raise GlPoolDef.slots or release a slot", ""};
  if (auto st = sims_[slot].reset(def, "GlPoolDef.capacity."); !st) return st.errors();
  used_[slot] = true;
  return slot;
}

Status GlPool::release(int slot) {
  if (slot < 0 || slot >= int(used_.size()) || !used_[slot])
    return Error{"", "GlPool.release.slot", std::to_string(slot), "must be a slot in use", ""};
  // empty it now (bodies, springs), so nothing of this patch survives into the next one
  if (auto st = sims_[slot].reset(def_.capacity, "GlPoolDef.capacity."); !st) return st;
  used_[slot] = false;
  return Ok{};
}

GlSimulation& GlPool::sim(int slot) {
  assert(slot >= 0 && slot < int(used_.size()) && used_[slot]);
  return sims_[slot];
}
const GlSimulation& GlPool::sim(int slot) const {
  assert(slot >= 0 && slot < int(used_.size()) && used_[slot]);
  return sims_[slot];
}

Status GlPool::step(double dt_frame) {
  // uploads: whole bodies, slots in order, until the frame's budget is spent
  std::size_t budget = def_.upload_bytes_per_frame;
  last_upload_ = 0;
  for (int k = 0; k < int(sims_.size()); ++k) {
    if (!used_[k]) continue;
    // a body larger than the whole budget goes alone, in a frame that uploads nothing else
    const std::size_t n = sims_[k].upload(budget, last_upload_ == 0);
    last_upload_ += n;
    budget = n >= budget ? 0 : budget - n;
  }
  for (int k = 0; k < int(sims_.size()); ++k) {
    if (!used_[k]) continue;
    if (auto st = sims_[k].step(dt_frame); !st) {
      std::vector<Error> es = st.errors();
      for (auto& e : es) e.detail = "pool slot " + std::to_string(k) + (e.detail.empty() ? "" : ": " + e.detail);
      return es;
    }
  }
  return Ok{};
}

int GlPool::slots() const { return int(sims_.size()); }
int GlPool::in_use() const {
  int n = 0;
  for (bool u : used_) n += u ? 1 : 0;
  return n;
}
bool GlPool::in_use(int slot) const { return slot >= 0 && slot < int(used_.size()) && used_[slot]; }
std::size_t GlPool::gpu_bytes() const {
  std::size_t n = 0;
  for (const auto& s : sims_) n += s.gpu_bytes();
  return n;
}
std::size_t GlPool::last_frame_upload_bytes() const { return last_upload_; }

std::string GlPool::report() const {
  char b[256];
  std::snprintf(b, sizeof b, "GL pool: %d slots x (%d bodies, %d particles), %.1f MB of GPU buffers, %d in use",
                slots(), def_.capacity.max_bodies, def_.capacity.max_particles, double(gpu_bytes()) / (1 << 20),
                in_use());
  return b;
}

}  // namespace sandpatch::gpu
