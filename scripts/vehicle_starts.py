#!/usr/bin/env python3
"""A scene's vehicle started from several places along its path: whether it drives off in each.
A vehicle on granules about as wide as its wheels may drive from one start and dig itself in
from another a few decimetres away (where the tile's granules happen to lie under the wheels),
so one run says little; this runs the scene once per start and prints, per run, how far the
first vehicle's chassis went along x, its wheels' mean and deepest sinkage while on particles
after the first second, the particle scales the frame budget chose, the frames' real-time
factor, the longest frame over the frame budget, the frames over it and the patches filled at
once (report.json frames.max_over_budget, frames.over_budget, pool.urgent_fills).
docs/BENCHMARKS.md "The particle-scale cap from six starts" uses it.

    python3 scripts/vehicle_starts.py SCENE [--offsets 0,0.4,0.8] [--granule-radius R]
                                     [--frame-budget MS|off] [--seconds T] [--sandpatch BIN]

--offsets: m added to the vehicle's start x, one run each; --granule-radius: the first
material's granule_radius instead of the scene's; --frame-budget and --seconds are passed to
`sandpatch run`. Runs with --threads 2 and writes under a temporary directory.
"""
import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile


def run_one(args, scene, offset, workdir):
    s = json.loads(json.dumps(scene))
    s["vehicles"][0]["position"][0] += offset
    if args.granule_radius is not None:
        s["materials"][0]["granule_radius"] = args.granule_radius
    tag = f"start{offset:+.2f}"
    path = os.path.join(workdir, tag + ".json")
    out = os.path.join(workdir, tag)
    with open(path, "w") as f:
        json.dump(s, f)
    cmd = [args.sandpatch, "run", "--quiet", "--threads", "2", "--out", out, path, "--csv", os.path.join(out, "bodies.csv")]
    if args.frame_budget:
        cmd += ["--frame-budget", args.frame_budget]
    if args.seconds:
        cmd += ["--seconds", str(args.seconds)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stdout}{r.stderr}")
    name = s["vehicles"][0]["name"]
    with open(os.path.join(out, "bodies.csv"), newline="") as f:
        rows = list(csv.DictReader(f))
    chassis = [x for x in rows if x["body"] == name + ".chassis"]
    if not chassis:
        sys.exit(f"{path}: no rows for {name}.chassis in the run's bodies CSV")
    sink = [float(x["sinkage"]) for x in rows
            if x["body"].startswith(name + ".wheel") and x["on_particles"] == "1" and float(x["t"]) > 1.0]
    with open(os.path.join(out, "report.json")) as f:
        rep = json.load(f)
    scales = sorted({p["particle_scale"] for p in rep.get("budget", {}).get("patches", [])})
    return {
        "start_x": s["vehicles"][0]["position"][0],
        "driven_m": float(chassis[-1]["x"]) - float(chassis[0]["x"]),
        "sink_mean_m": sum(sink) / len(sink) if sink else 0.0,
        "sink_max_m": max(sink) if sink else 0.0,
        "scales": scales,
        "frames_rtf": rep["frames_real_time_factor"],
        "max_over_budget": rep.get("frames", {}).get("max_over_budget", 0.0),
        "over_budget": rep.get("frames", {}).get("over_budget", 0),
        "frames": rep.get("frame_count", 0),
        "urgent_fills": rep.get("pool", {}).get("urgent_fills", 0),
    }


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scene")
    p.add_argument("--offsets", default="0,0.4,0.8")
    p.add_argument("--granule-radius", type=float)
    p.add_argument("--frame-budget")
    p.add_argument("--seconds", type=float)
    p.add_argument("--sandpatch", default=os.path.join(os.path.dirname(__file__), "..", "build", "sandpatch"))
    args = p.parse_args()
    try:
        with open(args.scene) as f:
            scene = json.load(f)
    except (OSError, ValueError) as e:
        sys.exit(f"{args.scene}: cannot read the scene: {e}")
    if not isinstance(scene, dict) or not scene.get("vehicles"):
        sys.exit(f"{args.scene}: field vehicles: the scene has no vehicle")
    try:
        offsets = [float(x) for x in args.offsets.split(",")]
    except ValueError:
        sys.exit(f"--offsets {args.offsets}: must be numbers (m) separated by commas, e.g. 0,0.4,0.8")
    if not offsets or len(offsets) > 100 or not all(abs(o) < 1e4 for o in offsets):
        sys.exit(f"--offsets {args.offsets}: 1 to 100 offsets, each within 10 km")
    if not os.path.exists(args.sandpatch):
        sys.exit(f"--sandpatch {args.sandpatch}: no such program (build it: cmake --build build)")
    with tempfile.TemporaryDirectory() as workdir:
        for o in offsets:
            r = run_one(args, scene, o, workdir)
            print(f"start x {r['start_x']:.2f} m: drove {r['driven_m']:.2f} m, wheel sinkage mean {r['sink_mean_m']:.3f} m, "
                  f"deepest {r['sink_max_m']:.3f} m, particle scales {r['scales']}, frames' real-time factor "
                  f"{r['frames_rtf']:.2f}, longest frame {r['max_over_budget']:.2f} x the budget, "
                  f"{r['over_budget']} of {r['frames']} frames over it, {r['urgent_fills']} fills at once", flush=True)


if __name__ == "__main__":
    main()
