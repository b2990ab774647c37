#include "particles/backend.hpp"

namespace sandpatch {
namespace {

class CpuBackend final : public DemBackend {
 public:
  explicit CpuBackend(Simulation s) : sim_(std::move(s)) {}
  const char* name() const override { return "cpu"; }
  Status reset(const SimulationDef& def) override { return sim_.reset(def); }
  Result<BodyId> add_granule(Vec3 p, Quat q) override { return sim_.add_granule(p, q); }
  Result<BodyId> add_shell(const ShellDef& s) override { return sim_.add_shell(s); }
  Status set_body_state(BodyId b, Vec3 p, Quat q, Vec3 v, Vec3 w) override { return sim_.set_body_state(b, p, q, v, w); }
  Status set_body_enabled(BodyId b, bool e) override { return sim_.set_body_enabled(b, e); }
  Status step(double dt) override { return sim_.step(dt); }
  bool asleep() const override { return sim_.asleep(); }
  void wake() override { sim_.wake(); }
  Vec3 body_velocity(BodyId b) const override { return sim_.body_velocity(b); }
  Vec3 body_angular_velocity(BodyId b) const override { return sim_.body_angular_velocity(b); }
  std::vector<Vec3> particle_positions() const override { return sim_.particle_positions(); }
  const SimulationDef& def() const override { return sim_.def(); }
  const GranuleShape& granule_shape() const override { return sim_.granule_shape(); }
  std::uint64_t state_hash() const override { return sim_.state_hash(); }

 private:
  Simulation sim_;
};

}  // namespace

std::unique_ptr<DemBackend> make_cpu_backend(Simulation sim) { return std::make_unique<CpuBackend>(std::move(sim)); }

}  // namespace sandpatch
