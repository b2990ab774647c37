#!/usr/bin/env bash
# Builds the libFuzzer harnesses (fuzz/, clang + ASan + UBSan) and runs each for SECONDS
# (default 60), then replays the regression inputs and the whole corpus once more under the
# sanitizers. Usage: scripts/fuzz.sh [SECONDS] [BUILD_DIR]   (docs/reliability.md)
#   CI runs `scripts/fuzz.sh 25` (four harnesses: under two minutes of fuzzing).
#   A long run: `scripts/fuzz.sh 3600`; the corpus grows in BUILD_DIR/corpus and is kept.
# A crash stops the script with its input in BUILD_DIR/crashes/<harness>/; copy it into
# fuzz/regressions/<harness>/ with the fix, so that every later run replays it.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:-60}
BUILD=${2:-build-fuzz}
HARNESSES=(fuzz_scene fuzz_heightmap fuzz_obj fuzz_api)
NICE=${NICE:-nice -n 10}
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)

cmake -S . -B "$BUILD" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DSANDPATCH_FUZZ=ON "${launcher[@]}" >/dev/null
$NICE cmake --build "$BUILD" -j2 --target "${HARNESSES[@]}"

# ---- seed corpus: the shipped and the broken scenes, meshes, heightmaps ----
seed() {  # seed HARNESS NAME PREFIX_BYTES FILE
  local dir="$BUILD/seeds/$1"
  mkdir -p "$dir"
  { printf "$3"; cat "$4"; } >"$dir/$2"
}
rm -rf "$BUILD/seeds"
for f in scenes/*.json scenes/broken/*.json tests/scene/data/*.json tests/apps/data/*.json; do
  seed fuzz_scene "$(echo "$f" | tr / _)" "" "$f"
done
for f in scenes/meshes/*.obj scenes/broken/meshes/*.obj; do seed fuzz_obj "$(basename "$f")" "" "$f"; done
for f in scenes/broken/heightmaps/*.png tests/render/reference/*.png; do seed fuzz_heightmap "$(basename "$f")" '\000\010' "$f"; done
for f in tests/scene/data/*.asc tests/apps/data/*.asc; do seed fuzz_heightmap "$(basename "$f")" '\002\010\000' "$f"; done
# raw float32: 3 × 2 samples of 1.0
seed fuzz_heightmap raw_3x2 '\001\010\003\000\002\000' <(python3 -c "import struct,sys; sys.stdout.buffer.write(struct.pack('<6f',*[1.0]*6))")
mkdir -p "$BUILD/seeds/fuzz_api"
printf '\000\001\000\000\000\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\144\004\000\005\000\000\000\000\000\000\000\000\002\000\000\000\002\000\000\000' >"$BUILD/seeds/fuzz_api/drop"

# ---- fuzz each harness, then replay regressions + corpus ----
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
total_runs=0
for h in "${HARNESSES[@]}"; do
  corpus="$BUILD/corpus/$h"
  crashes="$BUILD/crashes/$h"
  mkdir -p "$corpus" "$crashes" "fuzz/regressions/$h"
  log="$BUILD/$h.log"
  # -max_len 65536: the deep-nesting class needs long inputs; -rss_limit_mb: a memory bomb is a crash.
  $NICE "$BUILD/fuzz/$h" "$corpus" "$BUILD/seeds/$h" "fuzz/regressions/$h" -max_total_time="$SECONDS_EACH" \
    -max_len=65536 -timeout=20 -rss_limit_mb=2560 -artifact_prefix="$crashes/" -print_final_stats=1 >"$log" 2>&1 || {
    echo "$h: CRASH (input in $crashes/):"; tail -40 "$log"; exit 1; }
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo 0)
  total_runs=$((total_runs + runs))
  # Replay: every corpus and regression input once more, under the sanitizers.
  n=$(find "$corpus" "fuzz/regressions/$h" -type f | wc -l)
  $NICE "$BUILD/fuzz/$h" -runs=0 "$corpus" "fuzz/regressions/$h" >"$BUILD/$h.replay.log" 2>&1 || {
    echo "$h: replay failed"; tail -40 "$BUILD/$h.replay.log"; exit 1; }
  echo "$h: $runs executions in ${SECONDS_EACH}s, corpus $(find "$corpus" -type f | wc -l) inputs, $n replayed clean, 0 crashes"
done
echo "fuzz: $total_runs executions in total, 0 crashes, 0 sanitizer reports"
