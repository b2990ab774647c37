#!/usr/bin/env python3
"""Frame time against simulated time from `sandpatch stress` (OUT/stress.json and the per-frame
OUT/stress.csv it names), in the manner of Leach & Marais' figures 10, 12 and 14: every frame's
time and its DEM stage time (ms) on the left axis, the active / asleep / filling simulations and
the bodies that have arrived on the right axis.

    python3 scripts/plot_frames.py OUT/stress.json [OUT/frame_time.png]

Needs python3 and matplotlib (Debian: python3-matplotlib, installed by scripts/install-deps.sh).
Exit codes: 0 written, 2 bad input (missing file, not a stress.json), 3 matplotlib missing.
"""
import json
import os
import sys


def main(argv):
    if len(argv) < 2 or len(argv) > 3:
        print("usage: plot_frames.py STRESS_JSON [PNG]", file=sys.stderr)
        return 2
    src = argv[1]
    png = argv[2] if len(argv) == 3 else os.path.join(os.path.dirname(src) or ".", "frame_time.png")
    try:
        with open(src) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        print(f"plot_frames: {src}: cannot read a JSON file: {e}", file=sys.stderr)
        return 2
    csv_name = data.get("csv") if isinstance(data, dict) else None
    if not isinstance(csv_name, str):
        print(f"plot_frames: {src}: no 'csv' entry: not a sandpatch stress.json", file=sys.stderr)
        return 2
    csv_path = os.path.join(os.path.dirname(src) or ".", csv_name)
    try:
        import csv

        with open(csv_path, newline="") as f:
            rows = list(csv.DictReader(f))
        t = [float(r["time_s"]) for r in rows]
        ms = [float(r["frame_ms"]) for r in rows]
        dem = [float(r["dem_ms"]) for r in rows]
        active = [int(r["active"]) for r in rows]
        asleep = [int(r["asleep"]) for r in rows]
        filling = [int(r["filling"]) for r in rows]
        arrived = [int(r["arrived"]) for r in rows]
    except (OSError, ValueError, KeyError) as e:
        print(f"plot_frames: {csv_path}: cannot read the per-frame CSV: {e}", file=sys.stderr)
        return 2
    if not rows:
        print(f"plot_frames: {csv_path}: no frames", file=sys.stderr)
        return 2
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot_frames: matplotlib is not installed (Debian: apt-get install python3-matplotlib, "
              "or bash scripts/install-deps.sh); the data is in " + src, file=sys.stderr)
        return 3

    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    ax.plot(t, ms, color="tab:blue", linewidth=0.6, label="frame time, wall (each frame)")
    ax.plot(t, dem, color="tab:purple", linewidth=0.6, label="DEM stage (each frame)")
    dt_ms = 1000.0 * data.get("dt_s", 0.0)
    if dt_ms > 0:
        ax.axhline(dt_ms, color="tab:green", linestyle="--", linewidth=1, label=f"real time ({dt_ms:.1f} ms)")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("frame time (ms)")
    ax.set_ylim(bottom=0)
    ax2 = ax.twinx()
    ax2.step(t, active, where="post", color="tab:red", linewidth=1, label="active simulations")
    ax2.step(t, asleep, where="post", color="tab:orange", linewidth=1, label="asleep simulations")
    if any(filling):
        ax2.step(t, filling, where="post", color="tab:olive", linewidth=1, label="filling")
    ax2.step(t, arrived, where="post", color="tab:gray", linewidth=1, linestyle=":", label="bodies arrived")
    ax2.set_ylabel("simulations")
    ax2.set_ylim(bottom=0, top=max(arrived + active + asleep + [1]) + 1)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="upper left", fontsize=8)
    scene = data.get("scene", {}).get("name", "")
    ax.set_title(f"{scene}: {data.get('sims', '?')} simulations, {data.get('threads', '?')} threads "
                 f"({len(rows)} frames)", fontsize=10)
    fig.tight_layout()
    fig.savefig(png)
    print(f"plot_frames: wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
