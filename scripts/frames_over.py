#!/usr/bin/env python3
"""Frames of a run's frame file (`sandpatch run --csv DIR/t.csv` writes DIR/t_frames.csv) that
took more than FACTOR times their budget, and what ran in them: a conversion part (activation
or demotion stage above 0.5 ms), a take-over (`ready`), or the DEM alone.

    python3 scripts/frames_over.py DIR/t_frames.csv [--factor 1.5]
"""
import argparse
import csv
import signal
import statistics


def main():
    signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # (quiet when piped into head)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames")
    ap.add_argument("--factor", type=float, default=1.5)
    a = ap.parse_args()
    rows = list(csv.DictReader(open(a.frames)))
    if not rows:
        print("no frames")
        return
    ms = [float(r["frame_ms"]) for r in rows]
    budget = [float(r["budget_ms"]) for r in rows]
    over = [r for r, m, b in zip(rows, ms, budget) if b > 0 and m > a.factor * b]
    kinds = {"conversion part > 0.5 ms": 0, "take-over": 0, "DEM alone": 0}
    for r in over:
        if float(r["activation_ms"]) > 0.5 or float(r["demotion_ms"]) > 0.5:
            kinds["conversion part > 0.5 ms"] += 1
        elif int(r["ready"]) > 0:
            kinds["take-over"] += 1
        else:
            kinds["DEM alone"] += 1
    print(f"{len(rows)} frames, median {statistics.median(ms):.2f} ms, longest {max(ms):.2f} ms; "
          f"{len(over)} over {a.factor} x the budget: " + ", ".join(f"{k} {v}" for k, v in kinds.items()))
    acts = [float(r["activation_ms"]) for r in rows]
    dems = [float(r["demotion_ms"]) for r in rows]
    print(f"activation stage: longest {max(acts):.2f} ms, frames above 1 ms {sum(x > 1 for x in acts)}; "
          f"demotion stage: longest {max(dems):.2f} ms, frames above 1 ms {sum(x > 1 for x in dems)}")


if __name__ == "__main__":
    main()
