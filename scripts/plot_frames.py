#!/usr/bin/env python3
"""Frame time against simulated time from `sandpatch stress` (OUT/stress.json), in the manner of
Leach & Marais' figures 10, 12 and 14: frame time (ms) on the left axis, the live simulations and
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
    windows = data.get("windows") if isinstance(data, dict) else None
    if not windows:
        print(f"plot_frames: {src}: no 'windows' array: not a sandpatch stress.json", file=sys.stderr)
        return 2
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot_frames: matplotlib is not installed (Debian: apt-get install python3-matplotlib, "
              "or bash scripts/install-deps.sh); the data is in " + src, file=sys.stderr)
        return 3

    # Each window is a step: its mean frame time holds from t0 to t1.
    t, ms, cpu, live, arrived = [], [], [], [], []
    for w in windows:
        t += [w["t0_s"], w["t1_s"]]
        ms += [w["frame_ms_mean"]] * 2
        cpu += [w.get("frame_cpu_ms_mean", float("nan"))] * 2
        live += [w["simulations_live"]] * 2
        arrived += [w["bodies_arrived"]] * 2
    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=100)
    ax.plot(t, ms, color="tab:blue", label="frame time, wall (window mean)")
    if any(c == c for c in cpu):
        ax.plot(t, cpu, color="tab:purple", linewidth=1, label="frame time, CPU of all threads (window mean)")
    dt_ms = 1000.0 * data.get("dt_s", 0.0)
    if dt_ms > 0:
        ax.axhline(dt_ms, color="tab:green", linestyle="--", linewidth=1, label=f"real time ({dt_ms:.1f} ms)")
    ax.set_xlabel("simulated time (s)")
    ax.set_ylabel("frame time (ms)")
    ax.set_ylim(bottom=0)
    ax2 = ax.twinx()
    ax2.plot(t, live, color="tab:red", linewidth=1, label="live simulations")
    ax2.plot(t, arrived, color="tab:gray", linewidth=1, linestyle=":", label="bodies arrived")
    ax2.set_ylabel("simulations")
    ax2.set_ylim(bottom=0, top=max(arrived + live + [1]) + 1)
    lines = ax.get_legend_handles_labels()
    lines2 = ax2.get_legend_handles_labels()
    ax.legend(lines[0] + lines2[0], lines[1] + lines2[1], loc="upper left", fontsize=8)
    scene = data.get("scene", {}).get("name", "")
    ax.set_title(f"{scene}: {data.get('sims', '?')} simulations, {data.get('threads', '?')} threads "
                 f"({len(windows)} windows)", fontsize=10)
    fig.tight_layout()
    fig.savefig(png)
    print(f"plot_frames: wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
