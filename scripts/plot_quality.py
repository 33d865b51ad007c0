#!/usr/bin/python3
"""Plots for the sampling-quality reports; reads only the CSV/PNG files the C++ tools write.

  plot_quality.py analysis DIR   (from `hpds analyze`)  -> levels.png, compare.png, compare_curves.png
  plot_quality.py normals DIR    (from bench/normal_accuracy) -> normal_error_cdf.png, normal_error_bars.png
  plot_quality.py features DIR   (from bench/feature_sensitivity) -> feature_levels.png, feature_sculpture.png

Needs Debian's python3-matplotlib (scripts/debian-packages.txt). Headless: the Agg backend, no display.
"""
import csv
import os
import sys
from collections import defaultdict

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402

METHOD_LABELS = {
    "hpds": "hpds (Poisson disk)",
    "grid_random": "grid random",
    "grid_closest": "grid closest-to-centre",
    "voxel_centroid": "voxel centroid",
    "random": "random subsampling",
}
METHOD_ORDER = ["hpds", "grid_random", "grid_closest", "voxel_centroid", "random"]


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def as_float(v):
    return float("nan") if v in ("", "null", None) else float(v)


def curves(rows, xkey, ykey):
    """{(method, level): (xs, ys)} in file order."""
    out = defaultdict(lambda: ([], []))
    for r in rows:
        xs, ys = out[(r["method"], int(r["level"]))]
        xs.append(as_float(r[xkey]))
        ys.append(as_float(r[ykey]))
    return out


def plot_analysis(d):
    rdf = curves(read_csv(os.path.join(d, "rdf.csv")), "r_over_rD", "g")
    spec = curves(read_csv(os.path.join(d, "spectrum.csv")), "f_times_rD", "power")

    # Per level: the hierarchy's levels share one scale once distances are in units of r_D.
    levels = sorted(l for (m, l) in rdf if m == "hpds")
    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    cmap = plt.get_cmap("viridis")
    for i, l in enumerate(levels):
        c = cmap(i / max(1, len(levels) - 1))
        ax[0].plot(*rdf[("hpds", l)], color=c, label=f"levels 0..{l}")
        ax[1].plot(*spec[("hpds", l)], color=c, label=f"levels 0..{l}")
    ax[0].axvline(1.0, color="grey", lw=0.8, ls="--")
    ax[0].set(xlabel="r / r_D", ylabel="g(r)", title="Radial distribution function (hpds, per level)")
    ax[1].axhline(1.0, color="grey", lw=0.8, ls="--")
    ax[1].set(xlabel="f * r_D", ylabel="radially averaged power", title="Power spectrum (hpds, per level)")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "levels.png"), dpi=110)
    plt.close(fig)

    methods = [m for m in METHOD_ORDER if any(k[0] == m for k in rdf if m != "hpds")]
    if not methods:
        return
    level = max(l for (m, l) in rdf if m != "hpds")
    methods = ["hpds"] + methods

    # Figure 5 of the paper: point set, periodogram, RDF and radial spectrum per method at equal count.
    fig, ax = plt.subplots(len(methods), 4, figsize=(15, 3.3 * len(methods)))
    for row, m in enumerate(methods):
        for col, kind in enumerate(("points", "periodogram")):
            path = os.path.join(d, f"{kind}_{m}_L{level}.png")
            a = ax[row][col]
            if os.path.exists(path):
                a.imshow(mpimg.imread(path), cmap="gray" if kind == "periodogram" else None)
            a.set_xticks([])
            a.set_yticks([])
            if row == 0:
                a.set_title("points (patch)" if kind == "points" else "periodogram (DC centred)")
        ax[row][0].set_ylabel(METHOD_LABELS.get(m, m), fontsize=11)
        ax[row][2].plot(*rdf[(m, level)], color="C0")
        ax[row][2].axvline(1.0, color="grey", lw=0.8, ls="--")
        ax[row][2].set(xlabel="r / r_D", ylabel="g(r)", ylim=(0, 3.5))
        ax[row][3].plot(*spec[(m, level)], color="C1")
        ax[row][3].axhline(1.0, color="grey", lw=0.8, ls="--")
        ax[row][3].set(xlabel="f * r_D", ylabel="power", ylim=(0, 4))
        if row == 0:
            ax[row][2].set_title("radial distribution function")
            ax[row][3].set_title("radially averaged power spectrum")
    fig.suptitle(f"Equal-count comparison at level {level} (as in the paper's figure 5)")
    fig.tight_layout(rect=(0, 0, 1, 0.975))
    fig.savefig(os.path.join(d, "compare.png"), dpi=90)
    plt.close(fig)

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.5))
    for m in methods:
        ax[0].plot(*rdf[(m, level)], label=METHOD_LABELS.get(m, m))
        ax[1].plot(*spec[(m, level)], label=METHOD_LABELS.get(m, m))
    ax[0].set(xlabel="r / r_D", ylabel="g(r)", title=f"RDF at equal count (level {level})", ylim=(0, 4))
    ax[1].set(xlabel="f * r_D", ylabel="radially averaged power", title="Power spectrum at equal count", yscale="log")
    for a in ax:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "compare_curves.png"), dpi=110)
    plt.close(fig)


def plot_normals(d):
    rows = read_csv(os.path.join(d, "normal_errors.csv"))
    # {scene: {(method, neighbourhood): [(quantile, error)]}}
    errs = defaultdict(lambda: defaultdict(list))
    for r in rows:
        errs[r["scene"]][(r["method"], r["neighborhood"])].append((as_float(r["quantile"]), as_float(r["error_deg"])))
    scenes = list(errs)
    fig, ax = plt.subplots(2, len(scenes), figsize=(4.6 * len(scenes), 8), squeeze=False)
    for col, s in enumerate(scenes):
        for row, nb in enumerate(("knn", "radius")):
            a = ax[row][col]
            for (m, n), qe in sorted(errs[s].items()):
                if n != nb or m.startswith("ablation_"):
                    continue
                qe = sorted(qe)
                a.plot([e for _, e in qe], [q for q, _ in qe], label=m, lw=2.2 if m.startswith("hpds") else 1.2)
            a.axvline(10.0, color="grey", lw=0.8, ls="--")
            a.set(xscale="log", xlim=(0.05, 90), ylim=(0, 1), xlabel="angular error [deg]", ylabel="fraction of samples",
                  title=f"{s} ({nb})")
            a.grid(alpha=0.3)
            a.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "normal_error_cdf.png"), dpi=100)
    plt.close(fig)

    summary = read_csv(os.path.join(d, "normal_accuracy.csv"))
    fig, ax = plt.subplots(1, 2, figsize=(14, 5))
    for i, nb in enumerate(("knn", "radius")):
        sel = [r for r in summary if r["neighborhood"] == nb and not r["method"].startswith("ablation_")]
        methods = list(dict.fromkeys(r["method"] for r in sel))
        width = 0.8 / max(1, len(methods))
        for j, m in enumerate(methods):
            vals = [as_float(next((r["p90_deg"] for r in sel if r["scene"] == s and r["method"] == m), "nan"))
                    for s in scenes]
            ax[i].bar([k + j * width for k in range(len(scenes))], vals, width, label=m)
        ax[i].set_xticks([k + 0.4 - width / 2 for k in range(len(scenes))])
        ax[i].set_xticklabels(scenes, fontsize=8)
        ax[i].set(ylabel="p90 angular error [deg]", title=f"90th-percentile normal error ({nb})", yscale="log")
        ax[i].legend(fontsize=7)
        ax[i].grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "normal_error_bars.png"), dpi=100)
    plt.close(fig)


def plot_features(d):
    rows = read_csv(os.path.join(d, "feature_levels.csv"))
    feats = [f for f in dict.fromkeys(r["feature"] for r in rows)]
    fig, ax = plt.subplots(1, len(feats), figsize=(5 * len(feats), 4.5), squeeze=False)
    for i, f in enumerate(feats):
        a = ax[0][i]
        base = f.replace("_sculpture", "")
        for o in ("random", base):
            sel = [r for r in rows if r["feature"] == f and r["order"] == o]
            a.plot([int(r["level"]) for r in sel], [100 * as_float(r["high_share"]) for r in sel], marker="o",
                   label=f"{o} order")
        a.axhline(10.0, color="grey", lw=0.8, ls="--", label="share in the input (top 10 %)")
        where = "sculpture samples" if f.endswith("_sculpture") else "all samples"
        a.set(xlabel="levels 0..D", ylabel="high-feature samples [%]", title=f"{base}: {where}")
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(d, "feature_levels.png"), dpi=100)
    plt.close(fig)

    pics = os.path.join(d, "pictures")
    orders = ["random", "sphericity", "surface_variation"]
    levels = sorted({int(n.split("_L")[1].split(".")[0]) for n in os.listdir(pics) if n.startswith("sculpture_")})
    if not levels:
        return
    fig, ax = plt.subplots(len(levels), len(orders), figsize=(4.2 * len(orders), 4.2 * len(levels)), squeeze=False)
    for r, lv in enumerate(levels):
        for c, o in enumerate(orders):
            a = ax[r][c]
            path = os.path.join(pics, f"sculpture_{o}_L{lv}.png")
            if os.path.exists(path):
                a.imshow(mpimg.imread(path))
            a.set_xticks([])
            a.set_yticks([])
            if r == 0:
                a.set_title(f"{o} order")
            if c == 0:
                a.set_ylabel(f"levels 0..{lv}")
    fig.suptitle("Sculpture, samples coloured by sphericity (dark = flat, yellow = high); grey = input")
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    fig.savefig(os.path.join(d, "feature_sculpture.png"), dpi=90)
    plt.close(fig)


def main():
    if len(sys.argv) != 3 or sys.argv[1] not in ("analysis", "normals", "features"):
        sys.exit(__doc__)
    {"analysis": plot_analysis, "normals": plot_normals, "features": plot_features}[sys.argv[1]](sys.argv[2])


if __name__ == "__main__":
    main()
