#!/usr/bin/env bash
# The DEM inside a scene against `bench dem` at the same sphere count, in one run (the issue's
# yardstick, docs/BENCHMARKS.md "The DEM inside a scene"): PAIRS times, alternated, the scene
# (`sandpatch run`, default budget) and then `bench dem` with the scene's mean spheres per
# substep (granules = spheres / 4), the same thread count, the median of five blocks of 1,000
# steps (one block swung by 2x on a shared machine); prints each pair's sphere-steps/s
# (all spheres, and the awake ones), the bench's, and their ratio.
#
#   bash scripts/scene_vs_bench.sh SCENE SECONDS THREADS [PAIRS] [BIN]
#
# SCENE: a scene file ("" = the embedded default); BIN: the sandpatch binary (default
# ./build/sandpatch). Needs python3 (to read report.json).
set -eu
SCENE=${1?usage: scene_vs_bench.sh SCENE SECONDS THREADS [PAIRS] [BIN]}
SECONDS_SIM=${2?usage}
THREADS=${3?usage}
PAIRS=${4:-2}
BIN=${5:-./build/sandpatch}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
for ((k = 1; k <= PAIRS; ++k)); do
  # shellcheck disable=SC2086
  "$BIN" run $SCENE --threads "$THREADS" --seconds "$SECONDS_SIM" --quiet --out "$OUT/run" >/dev/null
  read -r spheres rate awake < <(python3 -c "import json,sys; t=json.load(open(sys.argv[1]))['dem']['total']; print(round(t['spheres_per_substep']), t['sphere_steps_per_s'], t['awake_sphere_steps_per_s'])" "$OUT/run/report.json")
  granules=$(( (spheres + 2) / 4 ))
  bench=$("$BIN" bench dem --granules "$granules" --steps 1000 --repeat 5 --threads "$THREADS" --json | tail -n 1 |
    python3 -c "import json,sys; print(json.loads(sys.stdin.read())['sphere_steps_per_s'])")
  python3 -c "import sys; s, r, a, b = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]); print(f'pair {sys.argv[5]}: scene {r/1e6:.1f} M sphere-steps/s (awake {a/1e6:.1f} M) at {s} spheres a substep; bench dem {b/1e6:.1f} M at {4 * ((s + 2) // 4)}; scene / bench {r/b:.2f} (awake {a/b:.2f})')" \
    "$spheres" "$rate" "$awake" "$bench" "$k"
done
