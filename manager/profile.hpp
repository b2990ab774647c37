// The frame as a short list of named stages, each with one timer (World::step runs them,
// docs/manager.md "The frame"). The CLI prints this profile and the run report stores it.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <nlohmann/json.hpp>

namespace sandpatch {

// In frame order. A stage that has not run in a session is left out of the report.
enum class Stage : int {
  Spawn,      // bodies whose spawn time has come enter the Bullet world
  Lod,        // predict contacts, request patches
  Activation, // fill pool slots from the heightfield
  Dem,        // coupled granule substeps; contact forces handed to the bodies
  Bodies,     // Bullet advances the bodies one fixed step (heightfield collision outside patches)
  Sleep,      // sleep / wake bookkeeping
  Demotion,   // particles -> heightfield, slot back to the pool
  Outputs,    // heightfield exports and images the scene asks for
  Count
};

constexpr std::array<const char*, int(Stage::Count)> kStageNames = {
    "spawn", "lod", "activation", "dem", "bodies", "sleep", "demotion", "outputs"};

class Profile {
 public:
  struct Timer {
    double total_ms = 0, max_ms = 0;
    std::int64_t calls = 0;
  };

  // RAII scope: times one run of a stage.
  class Scope {
   public:
    Scope(Profile& p, Stage s) : p_(p), s_(s), t0_(std::chrono::steady_clock::now()) {}
    ~Scope() {
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0_).count();
      Timer& t = p_.timers_[int(s_)];
      t.total_ms += ms;
      t.max_ms = ms > t.max_ms ? ms : t.max_ms;
      ++t.calls;
    }
    Scope(const Scope&) = delete;
    Scope& operator=(const Scope&) = delete;

   private:
    Profile& p_;
    Stage s_;
    std::chrono::steady_clock::time_point t0_;
  };

  Scope time(Stage s) { return Scope(*this, s); }
  const Timer& timer(Stage s) const { return timers_[int(s)]; }

  // {"bodies": {"calls": n, "total_ms": .., "mean_ms": .., "max_ms": ..}, ...} in frame order.
  nlohmann::ordered_json to_json() const {
    nlohmann::ordered_json j = nlohmann::ordered_json::object();
    for (int i = 0; i < int(Stage::Count); ++i) {
      const Timer& t = timers_[i];
      if (t.calls == 0) continue;
      j[kStageNames[i]] = {{"calls", t.calls},
                           {"total_ms", t.total_ms},
                           {"mean_ms", t.total_ms / double(t.calls)},
                           {"max_ms", t.max_ms}};
    }
    return j;
  }

 private:
  std::array<Timer, int(Stage::Count)> timers_{};
};

}  // namespace sandpatch
