#!/usr/bin/env python3
"""Plot `sandpatch bench terra --out DIR` (docs/validation.md "Terramechanics"): four panels,
the plates' pressure against sinkage with the fitted Bekker law, the shear plate's shear stress
against shear displacement with the fitted Janosi-Hanamoto law, and the wheel's drawbar pull
and sinkage against slip beside the rigid-wheel model (matplotlib only).

    python3 scripts/plot_terra.py DIR [--out docs/images/terra.png]

Reads DIR/terra.json and the series DIR/plate_*.csv (t, z, p), DIR/shear_*.csv (t, j, tau)
and DIR/wheel_*.csv (t, x, dp, sinkage).
"""
import argparse
import csv
import glob
import json
import math
import os
import sys


def read_csv(path):
    cols = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            for k, v in row.items():
                cols.setdefault(k, []).append(float(v))
    return cols


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir")
    ap.add_argument("--out", default=None, help="PNG (default DIR/terra.png)")
    a = ap.parse_args()
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        sys.exit("plot_terra.py: matplotlib is missing (scripts/install-deps.sh installs it)")
    with open(os.path.join(a.dir, "terra.json")) as f:
        js = json.load(f)
    bk, jh = js["bekker"], js["janosi_hanamoto"]
    fig, ax = plt.subplots(2, 2, figsize=(11, 8))

    # plates
    p0 = ax[0][0]
    for path in sorted(glob.glob(os.path.join(a.dir, "plate_*.csv"))):
        d = read_csv(path)
        b = int(os.path.basename(path)[6:9]) / 1000.0
        p0.plot([z * 100 for z in d["z"]], [p / 1000 for p in d["p"]], lw=0.8, label="DEM, b = %.2f m" % b)
        k = bk["k_c_kN"] / b + bk["k_phi_kN"]  # kPa / m^n
        zs = [0.005 * i for i in range(1, 29)]
        p0.plot([z * 100 for z in zs], [k * z ** bk["n"] for z in zs], "k--", lw=0.8)
    p0.set_xlabel("sinkage z (cm)")
    p0.set_ylabel("pressure p (kPa)")
    p0.set_title("plates: p = (k_c/b + k_phi) z^n, n = %.2f (dashed)" % bk["n"], fontsize=9)
    p0.legend(fontsize=8)

    # shear
    p1 = ax[0][1]
    for path, s in zip(sorted(glob.glob(os.path.join(a.dir, "shear_*.csv"))), js["shear"]):
        d = read_csv(path)
        line, = p1.plot([j * 100 for j in d["j"]], [t / 1000 for t in d["tau"]], lw=0.8,
                        label="DEM, sigma = %.1f kPa" % (s["sigma"] / 1000))
        js_ = [0.005 * i for i in range(0, 80)]
        tmax = jh["c_kPa"] + s["sigma"] / 1000 * math.tan(math.radians(jh["phi_deg"]))
        p1.plot([j * 100 for j in js_], [tmax * (1 - math.exp(-j / jh["K_m"])) for j in js_], "--",
                color=line.get_color(), lw=0.8)
    p1.set_xlabel("shear displacement j (cm)")
    p1.set_ylabel("shear stress tau (kPa)")
    p1.set_title("grousered plate: Janosi-Hanamoto fit (dashed), phi = %.1f deg, K = %.1f cm"
                 % (jh["phi_deg"], 100 * jh["K_m"]), fontsize=9)
    p1.legend(fontsize=8)

    # wheel
    w = js["wheel"]
    mc = js.get("model_curve", [])
    p2, p3 = ax[1][0], ax[1][1]
    p2.errorbar([x["slip"] for x in w], [x["drawbar_pull"] for x in w], yerr=[x["drawbar_pull_sd"] for x in w],
                fmt="o", capsize=3, label="DEM wheel (sd over the window)")
    p3.errorbar([x["slip"] for x in w], [100 * x["sinkage"] for x in w], yerr=[100 * x["sinkage_sd"] for x in w],
                fmt="o", capsize=3, label="DEM wheel")
    p2.plot([x["slip"] for x in w], [x["model_at_sinkage_drawbar_pull"] for x in w], "kx",
            label="model at the DEM wheel's sinkage")
    if mc:
        p2.plot([m["slip"] for m in mc], [m["drawbar_pull"] for m in mc], "k-", lw=1, label="Bekker-Wong model (carries the load)")
        p3.plot([m["slip"] for m in mc], [100 * m["sinkage"] for m in mc], "k-", lw=1, label="Bekker-Wong model")
    p2.axhline(0, color="0.6", lw=0.5)
    p2.set_xlabel("slip")
    p2.set_ylabel("drawbar pull (N)")
    p2.set_title("wheel r = %.3f m, b = %.2f m, load %.0f N" % (js["wheel_geometry"]["radius"],
                 js["wheel_geometry"]["width"], w[0]["load"]), fontsize=9)
    p2.legend(fontsize=8)
    p3.set_xlabel("slip")
    p3.set_ylabel("sinkage (cm)")
    p3.legend(fontsize=8)
    fig.tight_layout()
    out = a.out or os.path.join(a.dir, "terra.png")
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
