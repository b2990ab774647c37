#!/usr/bin/env python3
"""Each body's landing in a run's body time series (`sandpatch run --csv FILE`): its impact
speed (the fastest it fell), its rebound (the fastest it then rose, as a fraction of the impact
speed; 0 when it never rose), the deepest its lowest point went after the impact, the highest
it came back up after that, and its final sinkage below the original surface (the CSV's
`sinkage` column, m; negative: above it). One line per body; docs/calibration.md "Normal law"
and docs/BENCHMARKS.md use it.

    python3 scripts/landings.py out/bodies.csv
"""
import csv
import sys


def landings(path):
    series = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            series.setdefault(row["body"], []).append(row)
    out = []
    for body, rows in series.items():
        vy = [float(r["vy"]) for r in rows]
        i = min(range(len(vy)), key=lambda k: vy[k])
        impact = -vy[i]
        rise = max([0.0] + vy[i:])
        sink = [float(r["sinkage"]) for r in rows]
        d = max(range(i, len(sink)), key=lambda k: sink[k])
        out.append((body, impact, rise / impact if impact > 0 else 0.0, sink[-1], float(rows[i]["t"]), sink[d],
                    min(sink[d:])))
    return out


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: landings.py BODIES.csv")
    for body, impact, rebound, sink, t, deepest, back_up in landings(sys.argv[1]):
        print(f"{body}: impact {impact:.2f} m/s at {t:.2f} s, rebound {rebound:.3f} of it, deepest {deepest:.3f} m, "
              f"then up to {back_up:.3f} m, final sinkage {sink:.3f} m")


if __name__ == "__main__":
    main()
