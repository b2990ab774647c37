// sandpatch: the command-line program (docs/cli.md).
//   sandpatch run [SCENE] [--out DIR] [--seconds S | --frames N] [--backend cpu|gl] [--threads T] [--shells]
//                 [--video FILE [--video-fps F]] [--csv FILE]
//   sandpatch render [SCENE] --at T [--camera NAME] [--image FILE] [--out DIR] [--frame-budget MS|off] [--shells]
//   sandpatch view [SCENE] [--frames N [--screenshot FILE]] [--size WxH] [--camera NAME] [--backend cpu|gl]
//                  [--threads T] [--frame-budget MS|off] [--keys K,...] [--quality high|low]
//   sandpatch check SCENE
//   sandpatch info
//   sandpatch bench dem [--granules N] [--steps S] [--repeat K] [--alternate-threads T2] [--backend cpu|gl] [--threads T] [--unloading L] [--restitution E] [--json]
//   sandpatch bench render [--terrain N]... [--frames F] [--width W] [--height H] [--json]
//   sandpatch bench lod [--sizes N,N,...] [--seconds S] [--threads T] [--json]
//   sandpatch bench collapse [--aspects A,A,...] [--friction MU,...] [--length N] [--width N] [--seed S] [--unloading L] [--restitution E] [--threads T] [--json]
//   sandpatch bench terra [--scene FILE] [--plates B,B] [--sigmas PA,...] [--slips S,...] [--bed-depth M] [--plates-only] [--out DIR] [--threads T] [--json]
//   sandpatch bench tradeoff [--quick | --full] [--threads T] [--out DIR] [--no-gl] [--no-plot] [--json]
//   sandpatch stress SCENE [--sims N] [--frames F] [--interval S] [--threads T] [--out DIR] [--no-plot] [--json]
// Exit codes: 0 ok, 1 runtime failure (with the stage that failed), 2 bad input.
#include <CLI/CLI.hpp>
#include <Eigen/Core>
#include <LinearMath/btScalar.h>
#include <fcl/config.h>
#include <omp.h>
#include <png.h>
#include <unistd.h>
#if __has_include(<valgrind/valgrind.h>)
#include <valgrind/valgrind.h>
#endif

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <iostream>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "apps/sandpatch/view.hpp"
#include "bench/bench.hpp"
#include "bench/bench_tradeoff.hpp"
#include "bench/collapse.hpp"
#include "bench/terra.hpp"
#include "common/knobs.hpp"
#include "gl/context.hpp"
#include "manager/run.hpp"
#include "manager/run_outputs.hpp"
#include "manager/terrain_manager.hpp"
#include "manager/scene_world.hpp"
#include "particles/gpu/bench_gl.hpp"
#include "render/render.hpp"
#include "scene/scene.hpp"

using namespace sandpatch;

namespace {

int code(ExitCode c) { return static_cast<int>(c); }

Result<SceneDef> load(const std::string& path) {
  return path.empty() ? load_default_scene() : load_scene_file(path);
}

void print_errors(const std::string& what, const std::string& text) {
  std::fprintf(stderr, "sandpatch: %s\n%s", what.c_str(), text.c_str());
  if (!text.empty() && text.back() != '\n') std::fputc('\n', stderr);
}

int cmd_info() {
  std::printf("sandpatch %s\n", SANDPATCH_VERSION);
  std::printf("threads: %d (OpenMP max), %d hardware\n", omp_get_max_threads(), omp_get_num_procs());
  const char* policy = std::getenv("OMP_WAIT_POLICY");
  const char* spins = std::getenv("GOMP_SPINCOUNT");
  std::printf("OpenMP wait policy: %s%s%s\n", policy ? policy : "(libgomp's default)", spins ? ", GOMP_SPINCOUNT " : "",
              spins ? spins : "");
  std::printf("libraries: Eigen %d.%d.%d, Bullet %d.%02d, FCL %s, libpng %s, nlohmann_json %d.%d.%d, CLI11 %s\n",
              EIGEN_WORLD_VERSION, EIGEN_MAJOR_VERSION, EIGEN_MINOR_VERSION, btGetVersion() / 100,
              btGetVersion() % 100, FCL_VERSION, PNG_LIBPNG_VER_STRING, NLOHMANN_JSON_VERSION_MAJOR,
              NLOHMANN_JSON_VERSION_MINOR, NLOHMANN_JSON_VERSION_PATCH, CLI11_VERSION);
  auto ctx = gl::Context::create();
  if (!ctx) {
    std::printf("OpenGL: none: %s\n", ctx.message().c_str());
    return code(ExitCode::Ok);
  }
  const auto& i = (*ctx)->info();
  std::printf("OpenGL: %s (%s) via EGL %s, %s platform%s\n", i.gl_renderer.c_str(), i.gl_version.c_str(),
              i.egl_version.c_str(), i.platform.c_str(), i.software ? ", software rasteriser" : "");
  std::printf("OpenGL limits: %d SSBO bindings, %lld MiB per SSBO, %d invocations per work group\n",
              i.max_ssbo_bindings, i.max_ssbo_bytes >> 20, i.max_work_group_invocations);
  return code(ExitCode::Ok);
}

// ---- run and render: a scene run to the end (run) or to time T with a picture (render) ----

struct RunCli {
  std::string scene, out_dir, backend, video, csv;
  double video_fps = 30;
  double seconds = -1;
  long long frames = -1;
  int threads = -1;
  std::string frame_budget;
  std::string sleep_regions;
  std::string travel;
  bool quiet = false;
  bool shells = false;
};

void add_run(CLI::App& app, RunCli& a) {
  auto* run = app.add_subcommand("run", "Run a scene headless and write DIR/report.json (default scene if none given)");
  run->add_option("scene", a.scene, "Scene file (JSON, docs/scene-format.md); omitted = the embedded default");
  run->add_option("--out", a.out_dir, "Output directory (default: out/<scene name>)");
  auto* o_sec = run->add_option("--seconds", a.seconds, "Simulated seconds (overrides simulation.duration)")
                    ->check(CLI::PositiveNumber);
  auto* o_frames = run->add_option("--frames", a.frames, "Number of fixed steps to run")->check(CLI::PositiveNumber);
  o_sec->excludes(o_frames);
  run->add_option("--backend", a.backend, "DEM backend")->check(CLI::IsMember({"cpu", "gl"}));
  run->add_option("--threads", a.threads, "Worker threads (0 = all)")->check(CLI::NonNegativeNumber);
  run->add_option("--frame-budget", a.frame_budget,
                  "Wall-clock ms a frame's patches may take, or off (overrides simulation.frame_budget_ms)");
  run->add_option("--sleep-regions", a.sleep_regions,
                  "Whether the still parts of an awake patch sleep (overrides simulation.sleep.regions)")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_option("--travel", a.travel,
                  "Whether a patch travels with the body it carries (overrides simulation.lod.travel)")
      ->check(CLI::IsMember({"on", "off"}));
  run->add_flag("--quiet", a.quiet, "No progress output");
  run->add_flag("--shells", a.shells, "Images and video also draw the bodies' particle shells (a debug overlay)");
  run->add_option("--video", a.video, "Also write a video of the scene's first camera to this file, through ffmpeg");
  run->add_option("--video-fps", a.video_fps, "Video frames per simulated second (default 30; at most 1 / dt)");
  run->add_option("--csv", a.csv, "Also write each body's pose, velocity, soil forces and sinkage per frame to this CSV file (patches: its stem + _patches.csv; frames: + _frames.csv)");
}

struct RenderCli {
  std::string scene, image, camera, out_dir, frame_budget, backend;
  double at = 0;
  int threads = -1;
  bool shells = false;
};

void add_render(CLI::App& app, RenderCli& a) {
  auto* rend = app.add_subcommand("render", "Run a scene to time T and write one picture (PNG)");
  rend->add_option("scene", a.scene, "Scene file; omitted = the embedded default");
  rend->add_option("--at", a.at, "Simulated time of the picture (s)")->required()->check(CLI::NonNegativeNumber);
  rend->add_option("--camera", a.camera, "Camera of the scene (default: its first, or a view of the whole terrain)");
  rend->add_option("--image", a.image, "PNG to write (default: DIR/render_<ms>.png)");
  rend->add_option("--out", a.out_dir, "Output directory for the report (default: out/<scene name>)");
  rend->add_option("--backend", a.backend, "DEM backend")->check(CLI::IsMember({"cpu", "gl"}));
  rend->add_flag("--shells", a.shells, "Also draw the bodies' particle shells (a debug overlay)");
  rend->add_option("--threads", a.threads, "Worker threads (0 = all)")->check(CLI::NonNegativeNumber);
  rend->add_option("--frame-budget", a.frame_budget,
                   "Wall-clock ms a frame's patches may take, or off (overrides simulation.frame_budget_ms)");
}

void add_view(CLI::App& app, ViewArgs& a) {
  auto* view = app.add_subcommand("view", "Run a scene live in a window: orbit camera, pause / step / speed, patch overlay");
  view->add_option("scene", a.scene, "Scene file; omitted = the embedded default");
  view->add_option("--frames", a.frames, "Advance this many frames, then exit")->check(CLI::PositiveNumber);
  view->add_option("--screenshot", a.screenshot, "With --frames: save the window's contents after the last frame (PNG)");
  view->add_option("--size", a.size, "Window size WxH in pixels (default 1280x720)");
  view->add_option("--camera", a.camera, "Scene camera to start at (default: its first)");
  view->add_option("--backend", a.backend, "DEM backend")->check(CLI::IsMember({"cpu", "gl"}));
  view->add_option("--threads", a.threads, "Worker threads (0 = all)")->check(CLI::NonNegativeNumber);
  view->add_option("--frame-budget", a.frame_budget,
                   "Wall-clock ms a frame's patches may take, or off (overrides simulation.frame_budget_ms)");
  view->add_option("--keys", a.keys,
                   "Scripted input, one token a frame, then exit: keys (space . n + - r q), rotate:DX:DY, pan:DX:DY, zoom:N");
  view->add_option("--quality", a.quality, "high (default) or low: half resolution, no ambient occlusion, small shadow map");
}

// Loads the scene (the embedded default when scene_path is empty), runs it with the options
// make_options gives for it and prints the summary.
int run_and_report(const std::string& scene_path, const std::function<RunOptions(const SceneDef&)>& make_options,
                   int argc, char** argv) {
  auto scene = load(scene_path);
  if (!scene) {
    print_errors((scene_path.empty() ? std::string("<embedded default>") : scene_path) + ": invalid scene (" +
                     std::to_string(scene.errors().size()) + " error(s))",
                 scene.message());
    return code(ExitCode::BadInput);
  }
  RunOptions opt = make_options(*scene);
  for (int i = 0; i < argc; ++i) opt.command_line += (i ? " " : "") + std::string(argv[i]);
  RunResult r = run_scene(*scene, opt);
  if (r.code != ExitCode::Ok) {
    print_errors(r.code == ExitCode::BadInput ? "bad input (stage " + r.stage + ")"
                                              : "run failed in stage '" + r.stage + "'",
                 r.message);
    return code(r.code);
  }
  const auto& rep = r.report;
  std::printf("scene '%s': %lld frames, %.2f s simulated in %.2f s (real-time factor %.2fx; the frames alone, without "
              "writing outputs: %.2f s, %.2fx), final state %s\n",
              scene->name.c_str(), rep["frame_count"].get<long long>(), rep["simulated_s"].get<double>(),
              rep["wall_s"].get<double>(), rep["real_time_factor"].get<double>(), rep["frames_wall_s"].get<double>(),
              rep["frames_real_time_factor"].get<double>(), rep["final_state_hash"].get<std::string>().c_str());
  std::printf("stages (total ms):");
  for (const auto& [name, t] : rep["stages"].items()) std::printf(" %s %.1f", name.c_str(), t["total_ms"].get<double>());
  std::printf("\n");
  for (const auto& w : rep["warnings"]) std::printf("warning: %s\n", w.get<std::string>().c_str());
  if (!r.report_path.empty()) std::printf("report: %s\n", r.report_path.c_str());
  return code(ExitCode::Ok);
}

// --frame-budget's number (ms); NaN when it is not one, which run_scene refuses naming the option.
double parse_budget(const std::string& s) {
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  return end && *end == '\0' && end != s.c_str() ? v : std::numeric_limits<double>::quiet_NaN();
}

int cmd_run(const RunCli& a, int argc, char** argv) {
  return run_and_report(a.scene, [&](const SceneDef&) {
    RunOptions opt;
    opt.out_dir = a.out_dir;
    opt.seconds = a.seconds;
    opt.frames = a.frames;
    opt.backend = a.backend;
    opt.threads = a.threads;
    if (a.frame_budget == "off") opt.frame_budget_ms = std::numeric_limits<double>::infinity();
    else if (!a.frame_budget.empty()) opt.frame_budget_ms = parse_budget(a.frame_budget);
    if (!a.sleep_regions.empty()) opt.sleep_regions = a.sleep_regions == "on";
    if (!a.travel.empty()) opt.travel = a.travel == "on";
    opt.progress = a.quiet ? ProgressStyle::None : ProgressStyle::Auto;
    opt.video = a.video;
    opt.video_fps = a.video_fps;
    opt.csv = a.csv;
    opt.show_shells = a.shells;
    return opt;
  }, argc, argv);
}

int cmd_render(const RenderCli& a, int argc, char** argv) {
  return run_and_report(a.scene, [&](const SceneDef& scene) {
    RunOptions opt;
    opt.out_dir = a.out_dir;
    opt.progress = ProgressStyle::Auto;
    opt.seconds = a.at;
    opt.frames = a.at > 0 ? -1 : 1;
    opt.final_camera = a.camera;
    opt.backend = a.backend;
    opt.threads = a.threads;
    opt.show_shells = a.shells;
    if (a.frame_budget == "off") opt.frame_budget_ms = std::numeric_limits<double>::infinity();
    else if (!a.frame_budget.empty()) opt.frame_budget_ms = parse_budget(a.frame_budget);
    char ms[32];
    std::snprintf(ms, sizeof ms, "%08lld", static_cast<long long>(std::llround(a.at * 1000)));
    opt.final_image = !a.image.empty() ? a.image
                      : (a.out_dir.empty() ? "out/" + scene.name : a.out_dir) + "/render_" + ms + ".png";
    return opt;
  }, argc, argv);
}

// ---- check ----

void add_check(CLI::App& app, std::string& path, bool& tiles) {
  auto* check = app.add_subcommand("check", "Validate a scene file and exit (0 valid, 2 invalid)");
  check->add_option("scene", path, "Scene file")->required();
  check->add_flag("--tiles", tiles,
                  "Also make the patch pool: settle (or read from the tile cache) the pre-settled granule tiles the "
                  "scene needs, so that its first run starts at once");
}

int cmd_check(const std::string& path, bool tiles) {
  auto scene = load_scene_file(path);
  if (!scene) {
    print_errors(path + ": invalid scene (" + std::to_string(scene.errors().size()) + " error(s))", scene.message());
    return code(ExitCode::BadInput);
  }
  // Everything run does before its first frame but the patch pool: the terrain loaded (a
  // heightmap's every sample, NODATA cells, its geometry), the bodies checked against it and
  // made as Bullet bodies (docs/reliability.md).
  std::string stage;
  // --tiles: the pool too, as run makes it (one thread: the tiles do not depend on it, and a
  // build running beside other jobs gains nothing from two)
  ProgressPrinter progress(ProgressStyle::Lines, 1, scene->simulation.dt);
  auto world = make_world(*scene, 1, scene->terrain.backend, &stage, /*patches=*/tiles,
                          [&](const std::string& what, double done, double max, double wall) { progress.note(what, done / max, wall); });
  if (!world) {
    print_errors(path + ": invalid scene (" + std::to_string(world.errors().size()) + " error(s) at the " + stage +
                     " stage of building the world)",
                 world.message());
    return code(ExitCode::BadInput);
  }
  std::printf("%s: valid scene '%s' (hash %s): %zu bodies, %zu materials\n", path.c_str(), scene->name.c_str(),
              scene->hash.c_str(), scene->bodies.size(), scene->materials.size());
  if (tiles) {
    const TerrainManager* m = (*world)->manager();
    if (!m) {
      std::printf("%s: no granule tiles: the scene turns patches off\n", path.c_str());
    } else {
      const auto c = m->report()["tile"]["cache"];
      std::printf("%s: granule tiles ready in %s (%d from disk, %d settled now)\n", path.c_str(),
                  c["dir"].get<std::string>().empty() ? "memory only (no tile cache)" : c["dir"].get<std::string>().c_str(),
                  c["from_disk"].get<int>(), c["settled"].get<int>());
    }
  }
  return code(ExitCode::Ok);
}

// ---- bench ----

struct BenchCli {
  CLI::App* bench = nullptr;
  BenchDemArgs dem;
  render::BenchRenderArgs render;
  BenchLodArgs lod;
  std::string lod_sizes;
  BenchTradeoffArgs tradeoff;
  bool trade_quick = false, trade_full = false, trade_no_gl = false, trade_no_plot = false;
  BenchCollapseArgs collapse;
  terra::BenchTerraArgs terra;
};

void add_bench(CLI::App& app, BenchCli& a) {
  auto* bench = app.add_subcommand("bench", "Benchmarks (programs, not tests; docs/BENCHMARKS.md)");
  a.bench = bench;
  bench->require_subcommand(1);
  BenchDemArgs& dem = a.dem;
  auto* bdem = bench->add_subcommand("dem", "Granule DEM throughput on a settled bed (sphere-steps/s)");
  bdem->add_option("--granules", dem.granules, "Granules in the bed (4 spheres each)")->check(CLI::PositiveNumber);
  bdem->add_option("--steps", dem.steps, "Timed steps")->check(CLI::PositiveNumber);
  bdem->add_option("--backend", dem.backend, "DEM backend")->check(CLI::IsMember({"cpu", "gl"}));
  bdem->add_option("--threads", dem.threads, "Worker threads (0 = all)")->check(CLI::NonNegativeNumber);
  bdem->add_option("--repeat", dem.repeat, "Time the settled bed this many times (blocks of --steps); reports the median")
      ->check(CLI::Range(1, 1000));
  bdem->add_option("--alternate-threads", dem.alternate_threads,
                   "Run every second block with this many threads (scaling on one bed); needs --repeat >= 2")
      ->check(CLI::Range(1, 1024));
  bdem->add_option("--unloading", dem.unloading,
                   "Hysteretic normal spring: unloading / loading stiffness ratio (default 1: linear)")
      ->check(CLI::Range(1.0, 100.0));
  bdem->add_option("--restitution", dem.restitution,
                   "Dashpot restitution (default 0.3 with the linear spring, 1 with --unloading above 1)")
      ->check(CLI::Range(0.0, 1.0));
  bdem->add_option("--substeps", dem.substeps,
                   "GL backend: substeps per timed step, read back once per step as a scene's frame (default 1)")
      ->check(CLI::Range(1, 10000));
  bdem->add_option("--workgroup", dem.workgroup,
                   "GL backend: invocations per work group, a power of two (default: the backend's, 64)")
      ->check(CLI::IsMember({1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024}));
  bdem->add_option("--idle-sims", dem.idle_sims,
                   "GL backend: this many more simulations of the bed in the same context, never stepped (does a pool of slots make each call dearer?)")
      ->check(CLI::Range(0, 16));
  bdem->add_option("--capacity", dem.capacity,
                   "GL backend: room for this many granules in the simulations (a pool slot's size; default the bed's)")
      ->check(CLI::NonNegativeNumber);
  bdem->add_flag("--json", dem.json, "Print one JSON object on the last line");
  render::BenchRenderArgs& brend = a.render;
  auto* bren = bench->add_subcommand("render", "Clipmap vs full-grid triangles and frame time per terrain size");
  bren->add_option("--terrain", brend.terrains, "Terrain size N (N x N samples); repeat for several (default 1024..8192)")
      ->check(CLI::Range(64, 16384));
  bren->add_option("--frames", brend.frames, "Frames timed per case")->check(CLI::PositiveNumber);
  bren->add_option("--width", brend.width, "Image width (px)")->check(CLI::Range(16, 8192));
  bren->add_option("--height", brend.height, "Image height (px)")->check(CLI::Range(16, 8192));
  bren->add_flag("--json", brend.json, "Print one JSON object on the last line");
  BenchLodArgs& blod = a.lod;
  auto* blodc = bench->add_subcommand("lod", "Wall time per simulated second against terrain size; LOD off estimate; idle and sleeping cost");
  blodc->add_option("--sizes", a.lod_sizes, "Terrain sizes in cells per side, ascending, comma-separated (default 512,1024,2048,4096,8192)");
  blodc->add_option("--seconds", blod.seconds, "Simulated seconds per terrain size (default 1)");
  blodc->add_option("--threads", blod.threads, "Worker threads (0 = all)");
  blodc->add_option("--window", blod.window, "Simulated seconds per size per turn (default 0.025)");
  blodc->add_flag("--quick", blod.quick, "No full-terrain checks, no sleeping patch (tests)");
  blodc->add_flag("--json", blod.json, "Print one JSON object on the last line");

  BenchTradeoffArgs& btrade = a.tradeoff;
  auto* btradec = bench->add_subcommand("tradeoff", "Cost and error of the knobs (particle scale, dt / t_c, patch size, "
                                                    "backend, substeps, slot capacity, LOD on/off) on a poured pile, a "
                                                    "crater and a drop through the terrain manager; Pareto front; CSV + PNG");
  auto* o_quick = btradec->add_flag("--quick", a.trade_quick, "Small sweep (seconds; used by the tests)");
  auto* o_full = btradec->add_flag("--full", a.trade_full, "Finer sweep (finer scales, t_c/100; long: see docs/tradeoff.md)");
  o_quick->excludes(o_full);
  btradec->add_option("--threads", btrade.threads, "Worker threads (0 = all)")->check(CLI::NonNegativeNumber);
  btradec->add_option("--out", btrade.out_dir, "Output directory (default: out/bench_tradeoff_<sweep>)");
  btradec->add_flag("--no-gl", a.trade_no_gl, "Skip the gl backend settings");
  btradec->add_flag("--no-plot", a.trade_no_plot, "Write the data only (no python3/matplotlib plot)");
  btradec->add_flag("--json", btrade.json, "Print one JSON object on the last line");

  BenchCollapseArgs& bcol = a.collapse;
  auto* bcolc = bench->add_subcommand("collapse", "Quasi-2D granular column collapse: runout and final height against "
                                                  "aspect ratio, fitted exponents (docs/validation.md)");
  bcolc->add_option("--aspects", bcol.aspects, "Aspect ratios H0/L0, comma-separated (default 0.5,0.75,1,1.5,2,3,4,6,8)")
      ->delimiter(',');
  bcolc->add_option("--friction", bcol.frictions, "Friction coefficients, comma-separated: a sweep each (default 0.5)")
      ->delimiter(',');
  bcolc->add_option("--length", bcol.length_granules, "Column length L0 in granules (default 10)");
  bcolc->add_option("--width", bcol.width_granules, "Slot width in granules (default 3)");
  bcolc->add_option("--split", bcol.split, "Target aspect ratio between the low-a and high-a fits (default 2.5)");
  bcolc->add_option("--seed", bcol.seed, "Lattice seed (orientations, jitter) (default 1)");
  bcolc->add_option("--unloading", bcol.unloading,
                    "Hysteretic normal spring: unloading / loading stiffness ratio (default 1: linear)")
      ->check(CLI::Range(1.0, 100.0));
  bcolc->add_option("--restitution", bcol.restitution,
                    "Dashpot restitution (default 0.3 with the linear spring, 1 with --unloading above 1)")
      ->check(CLI::Range(0.0, 1.0));
  bcolc->add_option("--threads", bcol.threads, "Worker threads per run (default 1; 0 = all)");
  bcolc->add_flag("--json", bcol.json, "Print one JSON object on the last line");

  terra::BenchTerraArgs& bter = a.terra;
  bter.scene = std::string(SANDPATCH_SOURCE_DIR) + "/scenes/wheel_on_sand.json";
  auto* bterc = bench->add_subcommand("terra", "Terramechanics on the wheel rig's bed: plate sinkage (Bekker), grousered "
                                               "shear plate (Janosi-Hanamoto), a wheel at set slips against the rigid-wheel "
                                               "model (docs/validation.md)");
  bterc->add_option("--scene", bter.scene, "The bed and wheel (default scenes/wheel_on_sand.json)");
  bterc->add_option("--plates", bter.plates, "Square plate widths, m, comma-separated (default 0.3,0.5)")->delimiter(',');
  bterc->add_option("--sigmas", bter.sigmas, "Shear plate normal stresses, Pa, comma-separated (default 2000,4000,8000)")
      ->delimiter(',');
  bterc->add_option("--slips", bter.slips, "Wheel slips, comma-separated (default 0,0.15,0.3,0.45,0.6)")->delimiter(',');
  bterc->add_option("--bed-depth", bter.bed_depth, "Bed (patch) depth, m, instead of the scene's (default: the scene's)");
  bterc->add_flag("--plates-only", bter.plates_only, "Stop after the plates and the Bekker fit");
  bterc->add_option("--out", bter.out, "Directory for the series (CSV) and terra.json (default: none)");
  bterc->add_option("--threads", bter.threads, "Worker threads (default 1; 0 = all)");
  bterc->add_flag("--json", bter.json, "Print one JSON object on the last line");
}

// "512,1024,..." into sizes; false (with the message on stderr) when an item is not an integer.
bool parse_lod_sizes(const std::string& lod_sizes, std::vector<int>& sizes) {
  sizes.clear();
  std::size_t p = 0;
  while (p <= lod_sizes.size()) {
    const std::size_t q = std::min(lod_sizes.find(',', p), lod_sizes.size());
    const std::string item = lod_sizes.substr(p, q - p);
    std::size_t used = 0;
    int n = 0;
    try {
      n = std::stoi(item, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (item.empty() || used != item.size()) {
      std::fprintf(stderr, "bench lod: --sizes = %s: '%s' is not an integer; give cell counts in [64, 16384], "
                           "ascending, comma-separated (e.g. 512,1024,2048)\n",
                   lod_sizes.c_str(), item.c_str());
      return false;
    }
    sizes.push_back(n);
    p = q + 1;
  }
  return true;
}

int cmd_bench(BenchCli& a) {
  CLI::App* bench = a.bench;
  if (bench->got_subcommand("dem")) {
    // GL: the same bed on the compute-shader backend, timed beside the CPU backend.
    if (a.dem.backend == "gl") return gpu::run_bench_dem_gl(a.dem.granules, a.dem.steps, a.dem.substeps, a.dem.workgroup, a.dem.json, a.dem.idle_sims, a.dem.capacity);
    if (a.dem.substeps != 1 || a.dem.workgroup != 0 || a.dem.idle_sims != 0 || a.dem.capacity != 0) {
      std::fprintf(stderr, "bench dem: --substeps = %d, --workgroup = %d, --idle-sims = %d: the GL backend's options (the CPU backend reads nothing back between steps and has no work groups)\n",
                   a.dem.substeps, a.dem.workgroup, a.dem.idle_sims);
      return 2;
    }
    return run_bench_dem(a.dem);
  }
  if (bench->got_subcommand("render")) return render::run_bench_render(a.render);
  if (bench->got_subcommand("tradeoff")) {
    BenchTradeoffArgs& btrade = a.tradeoff;
    btrade.sweep = a.trade_quick ? TradeoffSweep::Quick : a.trade_full ? TradeoffSweep::Full : TradeoffSweep::Default;
    btrade.gl = !a.trade_no_gl;
    if (!a.trade_no_plot) btrade.plot_script = std::string(SANDPATCH_SOURCE_DIR) + "/scripts/plot_tradeoff.py";
    return run_bench_tradeoff(btrade);
  }
  if (bench->got_subcommand("collapse")) return run_bench_collapse(a.collapse);
  if (bench->got_subcommand("terra")) return terra::run_bench_terra(a.terra);
  if (bench->got_subcommand("lod")) {
    if (!a.lod_sizes.empty() && !parse_lod_sizes(a.lod_sizes, a.lod.sizes)) return code(ExitCode::BadInput);
    return run_bench_lod(a.lod);
  }
  return code(ExitCode::BadInput);
}

// ---- stress ----

struct StressCli {
  StressArgs args;
  bool no_plot = false;
};

void add_stress(CLI::App& app, StressCli& a) {
  StressArgs& stress = a.args;
  auto* st = app.add_subcommand("stress", "Many simulations sharing the pool: frame time against time, live simulations, plots");
  st->add_option("scene", stress.scene, "Scene file: its terrain, material and first body (copied --sims times)")->required();
  st->add_option("--sims", stress.sims, "Simulations (copies of the first body, pool slots) (default 4)");
  st->add_option("--frames", stress.frames, "Fixed steps of the run (default 1200)");
  st->add_option("--interval", stress.interval, "Seconds between arrivals (default 2)");
  st->add_option("--windows", stress.windows, "Deprecated, ignored: frame times are measured per frame");
  st->add_option("--threads", stress.threads, "Worker threads (0 = all)");
  st->add_option("--out", stress.out_dir, "Output directory (default: out/<scene>_stress_<sims>)");
  st->add_flag("--no-plot", a.no_plot, "Write the data only (no python3/matplotlib plot)");
  st->add_flag("--json", stress.json, "Print one JSON object on the last line");
}

int cmd_stress(StressCli& a) {
  if (!a.no_plot) a.args.plot_script = std::string(SANDPATCH_SOURCE_DIR) + "/scripts/plot_frames.py";
  return run_stress(a.args);
}

}  // namespace

// OpenMP's threads wait at the end of a parallel region. GCC's libgomp spins first (300,000
// iterations) and sleeps after. On a quiet machine spinning is the faster (bench dem, two
// threads: 1.8 times the sphere-steps/s of sleeping); on cores other programs also use, a
// thread spinning at one of a DEM substep's barriers holds the core its partner needs, and the
// step runs several times slower than sleeping (9 times at a load average of 9 on two cores;
// docs/BENCHMARKS.md "OpenMP's wait policy"). libgomp reads its policy once, when it is
// loaded, so when the machine is busy at start-up (1-minute load average at least its
// hardware threads) the program starts itself again with OMP_WAIT_POLICY=passive, unless the
// user chose a policy (OMP_WAIT_POLICY or GOMP_SPINCOUNT). `bench` keeps libgomp's default (it
// measures the peak). Not under valgrind: its tools would lose the program at the exec.
void sleep_at_barriers_if_busy(int argc, char** argv) {
  if (std::getenv("OMP_WAIT_POLICY") || std::getenv("GOMP_SPINCOUNT")) return;
  if (argc > 1 && std::string(argv[1]) == "bench") return;
#if __has_include(<valgrind/valgrind.h>)
  if (RUNNING_ON_VALGRIND) return;
#endif
  double load1 = 0;
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    if (std::fscanf(f, "%lf", &load1) != 1) load1 = 0;
    std::fclose(f);
  }
  if (!(load1 >= double(omp_get_num_procs()))) return;
  char self[4096];
  const ssize_t n = ::readlink("/proc/self/exe", self, sizeof self - 1);
  if (n <= 0 || n >= ssize_t(sizeof self - 1)) return;
  self[n] = '\0';
  if (::setenv("OMP_WAIT_POLICY", "passive", 1) != 0) return;
  ::execv(self, argv);  // returns only if it failed: go on as we are
  ::unsetenv("OMP_WAIT_POLICY");
}

int main(int argc, char** argv) {
  sleep_at_barriers_if_busy(argc, argv);
  CLI::App app{"Sandpatch: real-time granular terrain (hybrid heightfield / DEM level of detail)", "sandpatch"};
  app.require_subcommand(1);
  app.set_version_flag("--version", std::string("sandpatch ") + SANDPATCH_VERSION);

  // Subcommands in the order --help lists them.
  RunCli run;
  RenderCli render;
  std::string check_path;
  bool check_tiles = false;
  BenchCli bench;
  StressCli stress;
  add_run(app, run);
  add_render(app, render);
  add_check(app, check_path, check_tiles);
  bool info_knobs = false;
  app.add_subcommand("info", "Print versions, thread count and the OpenGL renderer EGL finds")
      ->add_flag("--knobs", info_knobs, "Print the table of settings (scene field, library field, default, range) as markdown");
  add_bench(app, bench);
  add_stress(app, stress);
  ViewArgs view;
  add_view(app, view);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? 0 : code(ExitCode::BadInput);
  }

  if (app.got_subcommand("info")) {
    if (!info_knobs) return cmd_info();
    std::fputs(knobs::knob_table_markdown().c_str(), stdout);  // docs/scene-format.md, docs/api.md
    return code(ExitCode::Ok);
  }
  if (app.got_subcommand("check")) return cmd_check(check_path, check_tiles);
  if (app.got_subcommand("stress")) return cmd_stress(stress);
  if (app.got_subcommand("bench")) return cmd_bench(bench);
  if (app.got_subcommand("render")) return cmd_render(render, argc, argv);
  if (app.got_subcommand("run")) return cmd_run(run, argc, argv);
  if (app.got_subcommand("view")) return run_view(view);
  return code(ExitCode::BadInput);
}
