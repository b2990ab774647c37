#!/usr/bin/env python3
"""Error against cost from `sandpatch bench tradeoff` (OUT/tradeoff.json): one panel per reference
case (poured pile, crater straight on the DEM, drop through the terrain manager), each setting a point at (wall seconds per simulated second, error
against the case's reference), the Pareto front joined and marked, the reference and the noise
floor (the same setting with another seed) drawn as such. Drop settings are labelled with
their substeps (sub), LOD (off, or the apron in m) and slot capacity; settings the manager refused
(slot too small) are listed under their panel.

    python3 scripts/plot_tradeoff.py OUT/tradeoff.json [OUT/tradeoff.png]

Needs python3 and matplotlib (Debian: python3-matplotlib, installed by scripts/install-deps.sh).
Exit codes: 0 written, 2 bad input (missing file, not a tradeoff.json), 3 matplotlib missing.
"""
import json
import os
import sys


def main(argv):
    if len(argv) < 2 or len(argv) > 3:
        print("usage: plot_tradeoff.py TRADEOFF_JSON [PNG]", file=sys.stderr)
        return 2
    src = argv[1]
    png = argv[2] if len(argv) == 3 else os.path.join(os.path.dirname(src) or ".", "tradeoff.png")
    try:
        with open(src) as f:
            data = json.load(f)
    except (OSError, ValueError) as e:
        print(f"plot_tradeoff: {src}: cannot read a JSON file: {e}", file=sys.stderr)
        return 2
    if not isinstance(data, dict) or data.get("bench") != "tradeoff" or not isinstance(data.get("settings"), list):
        print(f"plot_tradeoff: {src}: not a sandpatch bench tradeoff JSON (no 'settings')", file=sys.stderr)
        return 2
    rows = [s for s in data["settings"] if s.get("ran") and s.get("error") is not None]
    if not rows:
        print(f"plot_tradeoff: {src}: no setting with a cost and an error", file=sys.stderr)
        return 2
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("plot_tradeoff: matplotlib is not installed (Debian: apt-get install python3-matplotlib, "
              "or bash scripts/install-deps.sh); the data is in " + src, file=sys.stderr)
        return 3

    refused = [s for s in data["settings"] if s.get("outcome") == "refused"]
    cases = [c for c in ("pile", "crater", "drop") if any(r["case"] == c for r in rows)]
    fig, axes = plt.subplots(1, len(cases), figsize=(6.5 * len(cases), 5), dpi=100, squeeze=False)
    titles = {"pile": "angle of repose of a poured pile", "crater": "crater of a dropped sphere (DEM)",
              "drop": "sphere on a heightfield through the terrain manager"}
    for ax, case in zip(axes[0], cases):
        pts = [r for r in rows if r["case"] == case]
        top_slot = max((r.get("granules_per_slot") or 0) for r in pts)
        # errors past `cap` (%) are drawn at the cap with their value in the label (one far point
        # would squash the rest of the panel)
        errs = sorted(100.0 * r["error"] for r in pts)
        cap = max(120.0, errs[len(errs) // 2] * 3) if errs else 120.0
        for r in pts:
            x, y = r["wall_s_per_sim_s"], min(100.0 * r["error"], cap)
            if r.get("noise"):
                style = dict(marker="x", color="tab:gray", s=50)
            elif r.get("reference"):
                style = dict(marker="*", color="tab:green", s=160)
            elif r.get("backend") == "gl":
                style = dict(marker="s", color="tab:purple", s=45)
            else:
                style = dict(marker="o", color="tab:blue", s=35)
            ax.scatter([x], [y], zorder=3, **style)
            label = f"s{r['particle_scale']:g} N{r['steps_per_contact']}"
            if case == "crater":
                label += f" p{r['patch_radii']:g}" + (" gl" if r.get("backend") == "gl" else "")
            if case == "drop":
                lod = "LOD off" if r.get("lod") == "off" else f"LOD {r.get('lod_apron_m', 0):g} m"
                label += f" sub{r.get('substeps', 1)} {lod}"
                if r.get("granules_per_slot") != top_slot:
                    label += f" slot {r.get('granules_per_slot')}"
            if r.get("noise"):
                label += f" seed{r['seed']}"
            if 100.0 * r["error"] > cap:
                label += f" (error {100.0 * r['error']:.0f} %, off scale)"
            ax.annotate(label, (x, y), textcoords="offset points", xytext=(4, 4), fontsize=6.5)
        front = sorted((r for r in pts if r.get("pareto")), key=lambda r: r["wall_s_per_sim_s"])
        if front:
            ax.plot([r["wall_s_per_sim_s"] for r in front], [min(100.0 * r["error"], cap) for r in front],
                    color="tab:red", linewidth=1.2, zorder=2, label="Pareto front")
            ax.scatter([r["wall_s_per_sim_s"] for r in front], [min(100.0 * r["error"], cap) for r in front],
                       facecolors="none",
                       edgecolors="tab:red", s=140, linewidths=1.2, zorder=4)
        noise = [100.0 * r["seed_scatter"] for r in pts if r.get("noise") and r.get("seed_scatter") is not None]
        if noise:
            ax.axhline(max(noise), color="tab:gray", linestyle=":", linewidth=1,
                       label=f"noise floor (seed-to-seed, same knobs): {max(noise):.1f} %")
        ax.scatter([], [], marker="*", color="tab:green", s=100, label="reference (finest)")
        ax.scatter([], [], marker="o", color="tab:blue", label="cpu setting")
        if any(r.get("backend") == "gl" for r in pts):
            ax.scatter([], [], marker="s", color="tab:purple", label="gl setting")
        ax.set_xscale("log")
        ax.set_xlabel("cost: wall seconds per simulated second (log)")
        ax.set_ylabel("error against the reference (%)")
        ax.set_ylim(bottom=-1)
        ax.set_title(titles.get(case, case), fontsize=10)
        gone = [s for s in refused if s.get("case") == case]
        if gone:
            text = "refused (slot too small): " + ", ".join(
                f"{'LOD off' if s.get('lod') == 'off' else 'LOD on'} s{s['particle_scale']:g} slot {s.get('granules_per_slot')}"
                for s in gone)
            ax.text(0.01, 0.55, text, transform=ax.transAxes, fontsize=7, color="tab:red", va="center",
                    bbox=dict(facecolor="white", edgecolor="none", alpha=0.8))
        ax.legend(fontsize=7, loc="best")
        ax.grid(True, which="both", alpha=0.3)
    load = data.get("load_average", ["?", "?"])
    fig.suptitle(f"sandpatch bench tradeoff ({data.get('sweep', '?')} sweep, {data.get('threads', '?')} threads, "
                 f"load {load[0]:.1f}-{load[1]:.1f}); s = particle scale, N = t_c/dt, p = patch side / R, "
                 f"sub = Bullet substeps",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(png)
    print(f"plot_tradeoff: wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
