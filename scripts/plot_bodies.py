#!/usr/bin/env python3
"""Plot a run's body time series (`sandpatch run --csv FILE`, or a scene's outputs.csv):
the vertical granular and heightfield forces on each body against time, and its sinkage
below the original surface against time, in two panels; a third shows the vertical granular
force against sinkage (a pressure-sinkage curve for a plate pressed into sand).

    python3 scripts/plot_bodies.py out/plate_press/plate.csv [--out plot.png] [--body NAME]

Columns read (docs/cli.md "CSV"): t, body, granular_fy, heightfield_fy, sinkage.
"""
import argparse
import csv
import sys
from collections import defaultdict


def read(path, only):
    series = defaultdict(lambda: defaultdict(list))
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if only and row["body"] != only:
                continue
            s = series[row["body"]]
            for key in ("t", "granular_fy", "heightfield_fy", "sinkage"):
                s[key].append(float(row[key]))
    return series


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("csv", help="the body CSV of a run")
    ap.add_argument("--out", help="image to write (default: the CSV's name with .png)")
    ap.add_argument("--body", help="only this body")
    a = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("plot_bodies.py needs matplotlib (apt-get install python3-matplotlib)")
    series = read(a.csv, a.body)
    if not series:
        sys.exit(f"{a.csv}: no rows" + (f" for body '{a.body}'" if a.body else ""))
    fig, (ax_f, ax_s, ax_p) = plt.subplots(1, 3, figsize=(15, 4.5))
    for name, s in series.items():
        ax_f.plot(s["t"], s["granular_fy"], label=f"{name}: granular")
        if any(v != 0.0 for v in s["heightfield_fy"]):
            ax_f.plot(s["t"], s["heightfield_fy"], "--", label=f"{name}: heightfield")
        ax_s.plot(s["t"], [1000.0 * v for v in s["sinkage"]], label=name)
        ax_p.plot([1000.0 * v for v in s["sinkage"]], s["granular_fy"], label=name)
    ax_f.set(xlabel="t (s)", ylabel="vertical force on the body (N)", title="force")
    ax_s.set(xlabel="t (s)", ylabel="sinkage below the original surface (mm)", title="sinkage")
    ax_p.set(xlabel="sinkage (mm)", ylabel="vertical granular force (N)", title="force against sinkage")
    for ax in (ax_f, ax_s, ax_p):
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out = a.out or (a.csv[:-4] if a.csv.endswith(".csv") else a.csv) + ".png"
    fig.savefig(out, dpi=100)
    print(out)


if __name__ == "__main__":
    main()
