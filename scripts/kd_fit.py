#!/usr/bin/env python3
"""The soil's force on a dropped ball against Katsuragi & Durian's force law (docs/validation.md
"The stopping force against Katsuragi and Durian").

Reads the JSON lines of `sandpatch_impact ... --trace` runs (one file per drop, any names) from a
folder and fits, by least squares over the frames of the stop (from the first frame whose soil
force passes a tenth of the ball's weight until the ball goes down slower than 1 % of its impact
speed; each frame's mean force against the state at the frame's middle), the soil's upward
force F (N) to

    F = m v^2 / d1 + k z            (H. Katsuragi and D. J. Durian, Nature Physics 3, 420, 2007)

with m the ball's mass (kg), v its downward speed (m/s) and z how far its lowest point has gone
down since the stop began (m). Prints d1 (m), k (N/m) and R^2 per drop, per ball density
(every drop of that density together) and, from the force's largest value on, the same fit
again; then the exponents of d1 and k against the ball's density, which Katsuragi and Durian
(Phys. Rev. E 87, 052208, 2013) found to be 1 (inertial drag as in a fluid, m v^2/d1 ~ rho_g A v^2)
and 1/2 (the frictional term grows as the square root of the ball's and the medium's densities).

    python3 scripts/kd_fit.py DIR
"""
import glob
import json
import math
import os
import sys


def fit(rows):
    """Least squares F = a x1 + b x2 (no constant); returns a, b, R^2."""
    s11 = sum(x1 * x1 for x1, _, _ in rows)
    s12 = sum(x1 * x2 for x1, x2, _ in rows)
    s22 = sum(x2 * x2 for _, x2, _ in rows)
    t1 = sum(x1 * f for x1, _, f in rows)
    t2 = sum(x2 * f for _, x2, f in rows)
    det = s11 * s22 - s12 * s12
    if len(rows) < 3 or det <= 0:
        return float("nan"), float("nan"), float("nan")
    a = (t1 * s22 - t2 * s12) / det
    b = (s11 * t2 - s12 * t1) / det
    mean = sum(f for _, _, f in rows) / len(rows)
    ss = sum((f - a * x1 - b * x2) ** 2 for x1, x2, f in rows)
    st = sum((f - mean) ** 2 for _, _, f in rows)
    return a, b, 1.0 - ss / st if st > 0 else float("nan")


def inv(a):
    return 1.0 / a if a and a == a else float("nan")


def slope(xs, ys):
    """Exponent of y ~ x^p by least squares in logs (points with y > 0)."""
    pts = [(math.log(x), math.log(y)) for x, y in zip(xs, ys) if x > 0 and y > 0]
    if len(pts) < 2:
        return float("nan")
    mx = sum(p[0] for p in pts) / len(pts)
    my = sum(p[1] for p in pts) / len(pts)
    den = sum((p[0] - mx) ** 2 for p in pts)
    return sum((p[0] - mx) * (p[1] - my) for p in pts) / den if den > 0 else float("nan")


def stop_frames(run):
    """(m v^2, z, F) of the stop's frames, and the index of the largest force among them."""
    r = run["radius"]
    m = run["density"] * 4.0 / 3.0 * math.pi * r ** 3
    weight = m * 9.81
    v0 = run["impact_speed"]
    frames = run.get("frames") or []
    first = next((i for i, fr in enumerate(frames) if fr[3] > 0.1 * weight), None)
    rows = []
    if first is None:
        return m, rows, 0
    # the force is the frame's mean, the state the frame's end: the regressors at the frame's
    # middle (the mean of its start and end)
    # z from where the stop began (the ball's lowest point at the start of its first frame): the
    # ball meets the top granules up to a granule above the heightfield's surface
    top = frames[first - 1][1] if first > 0 else 0.0

    def state(i):
        _, bottom, vy, _ = frames[i]
        return m * vy * vy, max(0.0, top - bottom)
    for i in range(first, len(frames)):
        if -frames[i][2] <= 0.01 * v0:
            break
        a, b = state(i)
        if i > 0:
            a0, b0 = state(i - 1)
            a, b = 0.5 * (a + a0), 0.5 * (b + b0)
        rows.append((a, b, frames[i][3]))
    peak = max(range(len(rows)), key=lambda i: rows[i][2]) if rows else 0
    return m, rows, peak


def main():
    if len(sys.argv) != 2 or not os.path.isdir(sys.argv[1]):
        sys.exit("usage: kd_fit.py DIR (DIR holds the JSON output of sandpatch_impact --trace, one drop a file)")
    by_density = {}
    paths = sorted(glob.glob(os.path.join(sys.argv[1], "*")))
    if not paths:
        sys.exit(f"{sys.argv[1]}: no files (one sandpatch_impact --trace output a file)")
    for path in paths:
        try:
            with open(path) as f:
                run = json.loads(f.read().strip().splitlines()[-1])
        except (OSError, ValueError, IndexError) as e:
            sys.exit(f"{path}: not the JSON line of sandpatch_impact --trace ({e})")
        if not isinstance(run, dict) or not run.get("frames"):
            sys.exit(f"{path}: no frames (run sandpatch_impact with --trace)")
        for key in ("radius", "density", "height", "impact_speed"):
            if not isinstance(run.get(key), (int, float)) or not run[key] > 0:
                sys.exit(f"{path}: {key} = {run.get(key)!r}: must be a positive number (sandpatch_impact's JSON line)")
        if not all(isinstance(fr, list) and len(fr) == 4 and all(isinstance(x, (int, float)) for x in fr)
                   for fr in run["frames"]):
            sys.exit(f"{path}: frames must be [t, bottom, vy, fy] numbers (sandpatch_impact --trace)")
        m, rows, peak = stop_frames(run)
        a, k, r2 = fit(rows)
        a2, k2, r22 = fit(rows[peak:])
        by_density.setdefault(run["density"], ([], []))
        by_density[run["density"]][0].extend(rows)
        by_density[run["density"]][1].extend(rows[peak:])
        print(f"{os.path.basename(path)}: rho {run['density']:.0f} kg/m3, h {run['height']:.2f} m, m {m:.1f} kg, "
              f"v0 {run['impact_speed']:.2f} m/s, {len(rows)} frames: d1 {inv(a):.3f} m, k {k:.0f} N/m, R2 {r2:.2f}; "
              f"from the largest force on: d1 {inv(a2):.3f} m, k {k2:.0f} N/m, R2 {r22:.2f}")
    print("per density, every drop together (whole stop | from the largest force on):")
    dens, d1s, ks, d1p, kp = [], [], [], [], []
    for rho, (rows, after) in sorted(by_density.items()):
        a, k, r2 = fit(rows)
        a2, k2, r22 = fit(after)
        dens.append(rho)
        d1s.append(inv(a))
        ks.append(k)
        d1p.append(inv(a2))
        kp.append(k2)
        print(f"  rho {rho:6.0f}: d1 {inv(a):.3f} m, k {k:.0f} N/m, R2 {r2:.2f} | d1 {inv(a2):.3f} m, k {k2:.0f} N/m, "
              f"R2 {r22:.2f}")
    if len(dens) >= 2:
        print(f"exponents against the ball's density (Katsuragi & Durian 2013: d1 1, k 1/2): whole stop d1 "
              f"{slope(dens, d1s):.2f}, k {slope(dens, ks):.2f}; from the largest force on d1 {slope(dens, d1p):.2f}, "
              f"k {slope(dens, kp):.2f}")


if __name__ == "__main__":
    main()
