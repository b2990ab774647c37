#!/usr/bin/env bash
# The GL backend's checks on a machine with a GPU, in one run (docs/BENCHMARKS.md "GL backend on a
# GPU"): the GPU's name and the renderer EGL finds, the GL tests (context, GL-against-CPU
# cross-checks, a scene on the GL backend, rendering), the DEM throughput of both backends
# on the same settled beds, the default and Leach scenes on each backend, Leach & Marais'
# three scenarios at the paper's sizes, and the car scene on GL.
#
#   bash scripts/gpu_check.sh BIN_DIR OUT_DIR
#
# BIN_DIR holds `sandpatch` and the test programs (build/sandpatch and, from build/tests/,
# gl_context_test, particles_gpu_gl_{simulation,repose_heavy}_test, manager_run_test and the
# render_{render,scene_frames,particle_renderer,body_renderer}_test programs, copied flat) and,
# optionally, libgl_call_times.so (scripts/gl_call_times.c: then the scenes on the GL backend
# also report each GL call's host time); run it
# from the repository root with SANDPATCH_TILE_CACHE pointing at the build's tile_cache. Each step has its own time limit and the whole
# run GPU_CHECK_SECONDS (default 400); a failing step is logged and the next one runs. Writes
# OUT_DIR/summary.txt and OUT_DIR/logs.tar.gz (every step's output, the scenes' reports).
set -u
BIN=$(cd "${1:?usage: gpu_check.sh BIN_DIR OUT_DIR}" && pwd)
OUT=${2:?usage: gpu_check.sh BIN_DIR OUT_DIR}
mkdir -p "$OUT/logs"
OUT=$(cd "$OUT" && pwd)
SUM="$OUT/summary.txt"
: >"$SUM"

DEADLINE=$((SECONDS + ${GPU_CHECK_SECONDS:-400}))  # the whole run's limit; later steps are skipped
step() {  # step NAME LIMIT_S COMMAND...: run with a time limit, log, note rc and wall time
  local name=$1 lim=$2
  shift 2
  local left=$((DEADLINE - SECONDS))
  if ((left < 10)); then
    echo "== $name skipped: the run's time limit is reached" | tee -a "$SUM"
    return
  fi
  ((lim > left)) && lim=$left
  local t0=$SECONDS rc
  timeout --kill-after=5 "$lim" "$@" >"$OUT/logs/$name.log" 2>&1
  rc=$?
  echo "== $name rc=$rc wall=$((SECONDS - t0))s limit=${lim}s" | tee -a "$SUM"
  grep -E "PASSED|FAILED|OpenGL|renderer" "$OUT/logs/$name.log" | grep -v '^{' | head -20 >>"$SUM"
}

report() {  # report REPORT_JSON: one line of a scene run's report
  [ -f "$1" ] || return
  python3 - "$1" >>"$SUM" 2>&1 <<'EOF'
import json, sys
r = json.load(open(sys.argv[1]))
f = r["frames"]
print("  backend", r["backend"], "threads", r["threads"], "rtf", round(r["real_time_factor"], 3),
      "frames", r["frame_count"], "median_ms", round(f["median_ms"], 2), "max_ms", round(f["max_ms"], 1),
      "hash", r["final_state_hash"], "ledger_pct", round(r["ledger"]["total"]["error_pct"], 2),
      "spheres_per_substep", round(r["dem"]["total"]["spheres_per_substep"]),
      "substeps_per_frame", round(r["dem"]["total"]["substeps_per_frame"], 1),
      "sphere_steps_per_s", "%.4g" % r["dem"]["total"]["sphere_steps_per_s"],
      "granules", [p["granules"] for p in r["ledger"]["patches"]][:4],
      "gl_submit_ms", round(r["dem"]["total"]["stage_ms"]["gl_submit"]),
      "gl_readback_ms", round(r["dem"]["total"]["stage_ms"]["gl_readback"]),
      "depth_render", [p.get("depth_render") for p in r["ledger"]["patches"]][:3])
EOF
}

bench() {  # bench GRANULES SUBSTEPS: the DEM bench on both backends; its JSON line into the summary
  step "bench_dem_$1_k$2" 120 "$BIN/sandpatch" bench dem --backend gl --granules "$1" --steps $((2000 / $2)) \
    --substeps "$2" --json
  tail -n 1 "$OUT/logs/bench_dem_$1_k$2.log" >>"$SUM"
}

scene() {  # scene NAME BACKEND: a shipped scene for 4 simulated seconds
  local times="$OUT/logs/gl_call_times_$1_$2.txt"
  if [ "$2" = gl ] && [ -f "$BIN/libgl_call_times.so" ]; then
    GLTIME_OUT="$times" LD_PRELOAD="$BIN/libgl_call_times.so" step "run_$1_$2" 90 "$BIN/sandpatch" run "scenes/$1.json" \
      --backend "$2" --seconds 4 --quiet --out "$OUT/logs/run_$1_$2"
  else
    step "run_$1_$2" 90 "$BIN/sandpatch" run "scenes/$1.json" --backend "$2" --seconds 4 --quiet \
      --out "$OUT/logs/run_$1_$2"
  fi
  report "$OUT/logs/run_$1_$2/report.json"
  [ -f "$times" ] && head -8 "$times" >>"$SUM"
}

paper() {  # paper NAME BACKEND SECONDS LIMIT: a paper-size Leach & Marais scene (docs/stress.md)
  step "run_$1_$2" "$4" "$BIN/sandpatch" run "scenes/$1.json" --backend "$2" --seconds "$3" --quiet --out "$OUT/logs/run_$1_$2"
  report "$OUT/logs/run_$1_$2/report.json"
}

{ nvidia-smi -L; echo "cores: $(nproc)"; } >>"$SUM" 2>&1
step info 30 "$BIN/sandpatch" info
step gl_context 60 "$BIN/gl_context_test"
step gl_simulation 120 "$BIN/particles_gpu_gl_simulation_test"
# Leach & Marais' three scenarios at the paper's sizes (140,000 granules; 52,000 + 12,000 + 6,000;
# the first of ten balls on 83,000)
paper leach_1_barrel_paper gl 1.2 90
paper leach_2_three_scales_paper gl 4 120
paper leach_3_ten_bodies_paper gl 4 90
paper leach_1_barrel_paper cpu 0.8 90
# where scenario 2's GL step goes (its crates are shells of 12,000-48,000 spheres)
SANDPATCH_GL_PROFILE=1 step profile_leach_2_paper 60 "$BIN/sandpatch" run scenes/leach_2_three_scales_paper.json \
  --backend gl --seconds 0.8 --quiet --out "$OUT/logs/profile_leach_2_paper"
python3 -c "import json,sys; t=json.load(open(sys.argv[1]))['dem']['total']; print('  gl_kernel_ms', {k: round(v, 1) for k, v in t.get('gl_kernel_ms', {}).items()}, 'stage_ms', {k: round(v) for k, v in t['stage_ms'].items()})" \
  "$OUT/logs/profile_leach_2_paper/report.json" >>"$SUM" 2>&1
bench 16000 100
SANDPATCH_GL_PROFILE=1 step profile_16000 120 "$BIN/sandpatch" bench dem --backend gl --granules 16000 --steps 20 --substeps 100
grep -E "\.comp|GPU busy" "$OUT/logs/profile_16000.log" >>"$SUM"
scene default gl
scene default cpu
bench 16000 1
bench 4000 100
bench 1000 100
# does a context holding a pool of slots make each call dearer? the same bench with 3 idle sims
step "bench_dem_1000_k11_idle3" 120 "$BIN/sandpatch" bench dem --backend gl --granules 1000 --steps 100 --substeps 11 --idle-sims 3 --json
tail -n 1 "$OUT/logs/bench_dem_1000_k11_idle3.log" >>"$SUM"
step "bench_dem_1000_k11_idle0" 120 "$BIN/sandpatch" bench dem --backend gl --granules 1000 --steps 100 --substeps 11 --json
tail -n 1 "$OUT/logs/bench_dem_1000_k11_idle0.log" >>"$SUM"
# ... or the size of its own buffers? the same bed in a simulation sized as the car scene's slots
step "bench_dem_1000_k11_cap65536" 120 "$BIN/sandpatch" bench dem --backend gl --granules 1000 --steps 100 --substeps 11 --capacity 65536 --json
tail -n 1 "$OUT/logs/bench_dem_1000_k11_cap65536.log" >>"$SUM"
step run_gl_test 60 "$BIN/manager_run_test" --gtest_filter='Run.GlBackend*'
scene leach_3_ten_bodies gl
scene leach_3_ten_bodies cpu
scene vehicle_drive gl
# where a scene's GL step goes: every kernel's GPU time beside the host's submission
SANDPATCH_GL_PROFILE=1 step profile_vehicle 90 "$BIN/sandpatch" run scenes/vehicle_drive.json --backend gl --seconds 1 \
  --quiet --out "$OUT/logs/profile_vehicle"
python3 -c "import json,sys; t=json.load(open(sys.argv[1]))['dem']['total']; print('  gl_kernel_ms', {k: round(v, 1) for k, v in t.get('gl_kernel_ms', {}).items()}, 'stage_ms', {k: round(v) for k, v in t['stage_ms'].items()})" \
  "$OUT/logs/profile_vehicle/report.json" >>"$SUM" 2>&1
for t in render_render_test render_scene_frames_test render_particle_renderer_test render_body_renderer_test; do
  step "$t" 60 "$BIN/$t"
done
step gl_repose_heavy 200 "$BIN/particles_gpu_gl_repose_heavy_test"
(cd "$OUT" && tar czf logs.tar.gz logs && rm -rf logs)
cat "$SUM"
