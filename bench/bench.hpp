// `sandpatch bench ...` programs (docs/BENCHMARKS.md).
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "common/error.hpp"

namespace sandpatch {

struct SceneDef;  // scene/scene.hpp (not included here: particles/dem.hpp has its own SimulationDef)

// bench dem: settles a bed of `granules` tetrahedral granules (spheres d = 0.01 m,
// rho = 2500 kg/m^3, the peer's contact parameters k_n = 3292 N/m, e = 0.3, mu = 0.5,
// dt = 5e-5 s) in a walled box whose footprint gives the peer's ~11-diameter depth, then
// times `steps` steps. Prints sphere-steps/s, contacts per sphere, dt and threads; with
// json, one JSON object on the last line.
struct BenchDemArgs {
  int granules = 16000;
  int steps = 1000;
  std::string backend = "cpu";
  int threads = 0;  // 0 = OpenMP default
  int repeat = 1;   // timed blocks of `steps` steps on the one settled bed; the median is reported
  // > 0: every second block runs with this many threads instead (Simulation::set_threads), so
  // the two thread counts are timed on the same bed in the same minutes; each gets its median
  int alternate_threads = 0;
  // > 1: the hysteretic normal spring with this unloading / loading stiffness ratio (docs/dem.md)
  double unloading = 1.0;
  // the dashpot's restitution; < 0: 0.3 with the linear spring, 1 with the hysteretic one (e =
  // 1/sqrt(unloading) from the spring alone)
  double restitution = -1.0;
  // GL backend: substeps per step (one step = one frame: its substeps are queued, then the
  // status is read back once, as a scene's frame does); the CPU backend takes 1 only
  int substeps = 1;
  int workgroup = 0;  // GL backend: invocations per work group (0: the backend's default)
  int idle_sims = 0;  // GL backend: more simulations of the bed in the context, never stepped
  int capacity = 0;   // GL backend: granules the simulations have room for (0: the bed's)
  bool json = false;
};

// Exit code: 0 ok, 1 runtime failure, 2 bad input. Prints to stdout (errors to stderr).
int run_bench_dem(const BenchDemArgs& args);

// bench lod (bench/bench_lod.cpp, docs/BENCHMARKS.md "Level of detail"): the same three
// bodies dropped on the same spot of terrains of `sizes` cells per side (0.5 m cells), wall
// and CPU seconds per simulated second of each (interleaved, below) and per stage; the ratio largest / smallest; the
// "LOD off" estimate (the DEM's measured cost per granule-second times the granules the whole
// terrain would need), checked on a small terrain run fully as particles; idle terrain (no
// bodies) and a sleeping patch. With json, one JSON object on the last line:
// {"results": [{"terrain": N, "wall_s_per_sim_s": ...}, ...], "lod_off": {...}, ...}.
// Every size is set up first in one process, then all are advanced in turn, `window`
// simulated seconds each, round robin, so that all see the same machine load.
struct BenchLodArgs {
  std::vector<int> sizes = {512, 1024, 2048, 4096, 8192};  // cells per side, ascending
  double seconds = 1.0;  // simulated seconds per terrain size
  double window = 0.025; // simulated seconds per size per turn (3 frames of 1/120 s)
  int threads = 0;       // 0 = all cores
  bool quick = false;    // leave out the full-terrain checks and the sleeping patch (tests)
  bool json = false;
};

// "" when the arguments are valid, else the message (names the option, value, what is allowed).
std::string check_bench_lod_args(const BenchLodArgs& args);
int run_bench_lod(const BenchLodArgs& args);

// The bench's generated scenes (valid scene JSON, docs/scene-format.md) on a terrain of
// `cells` × `cells` cells of 0.5 m, origin (0, 0, 0): Drop three bodies at (20, 20), (26, 20),
// (20, 26) m; Idle no bodies; Asleep one light ball set down at (20, 20) m; Full the drop's
// ball at the centre of a (small, flat) terrain its patch covers; FullSlab a slab whose patch
// covers the whole (small, flat) terrain.
enum class LodBenchScene { Drop, Idle, Asleep, Full, FullSlab };
nlohmann::json lod_bench_scene(LodBenchScene kind, int cells, int threads);

// sandpatch stress SCENE (bench/stress.cpp, docs/stress.md): `sims` copies of the scene's first
// body on a grid around it, one arriving every `interval` s, pool.slots = sims; `frames` fixed
// steps. One run; every frame's time, DEM time and patch counts through run_scene's per-frame
// hook; writes OUT/stress.csv (one row a frame) and OUT/stress.json (summary), then runs
// `plot_script` (python3 + matplotlib) for OUT/frame_time.png.
struct StressArgs {
  std::string scene;
  int sims = 4;
  long long frames = 1200;
  double interval = 2.0;   // s between arrivals
  int windows = 0;         // deprecated, ignored (the old windowed method); != 0 prints a note
  int threads = 0;         // 0 = all cores
  std::string out_dir;     // "" = out/<scene>_stress_<sims>
  std::string plot_script; // "" = no plot
  bool json = false;
};
std::string check_stress_args(const StressArgs& args);
// The stress scene; errors name the scene field or the option (--sims when the grid does not fit).
Result<SceneDef> make_stress_scene(const SceneDef& base, int sims, double interval, long long frames);
int run_stress(const StressArgs& args);

}  // namespace sandpatch
