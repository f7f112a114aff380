#!/usr/bin/python3
"""[Chong97] Fig. 4 for every experiment of a suite: the measured end-point errors with the
predicted 95% ellipse (model) and the 95% ellipse of the data.

Reads the JSON of `odomcov compare SUITE.yaml --json FILE`. One panel per experiment shows the
x-y errors; with --pairs all, three panels per experiment show (x, y), (x, theta) and
(y, theta), as in the paper. Panel titles carry the verdict.

Usage: plot_compare.py COMPARE.json [--pairs xy|all] [--experiments NAME,...] [--match TEXT]
                       --out FIG.png
"""
import argparse
import os
import sys
import json
import math

try:
    import matplotlib
except ImportError:
    print("%s: needs matplotlib; install Debian's python3-matplotlib (scripts/setup.sh does) "
          "and run it with /usr/bin/python3" % os.path.basename(sys.argv[0]), file=sys.stderr)
    sys.exit(2)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Ellipse  # noqa: E402

CHI2_2_95 = 5.991464547107979  # chi^2 with 2 dof, 95% point: the 95% ellipse of a 2-D marginal
LABELS = ["x error [m]", "y error [m]", "theta error [rad]"]


def add_ellipse(ax, mean, cov, i, j, **style):
    sub = np.array([[cov[i][i], cov[i][j]], [cov[j][i], cov[j][j]]])
    values, vectors = np.linalg.eigh(sub)
    values = np.clip(values, 0.0, None)
    angle = math.degrees(math.atan2(vectors[1, 1], vectors[0, 1]))
    r = math.sqrt(CHI2_2_95)
    ax.add_patch(Ellipse((mean[i], mean[j]), 2 * r * math.sqrt(values[1]),
                         2 * r * math.sqrt(values[0]), angle=angle, fill=False, **style))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("compare", help="JSON of odomcov compare")
    parser.add_argument("--pairs", choices=["xy", "all"], default="xy")
    parser.add_argument("--experiments", help="comma-separated names (default: all)")
    parser.add_argument("--match", help="only experiments whose name contains this")
    parser.add_argument("--title", help="figure title (default: the suite and its verdict)")
    parser.add_argument("--out", required=True, help="output image")
    args = parser.parse_args()

    with open(args.compare) as f:
        data = json.load(f)
    experiments = data["experiments"]
    if args.experiments:
        wanted = args.experiments.split(",")
        experiments = [e for e in experiments if e["name"] in wanted]
    if args.match:
        experiments = [e for e in experiments if args.match in e["name"]]
    if not experiments:
        parser.error("no experiment to plot")
    pairs = [(0, 1)] if args.pairs == "xy" else [(0, 1), (0, 2), (1, 2)]
    cols = 3 if args.pairs == "xy" else 3
    per_row = cols // len(pairs) if args.pairs == "xy" else 1
    rows = math.ceil(len(experiments) / per_row)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.8 * rows), squeeze=False)
    for k, e in enumerate(experiments):
        errors = np.asarray(e["errors"])
        for p, (i, j) in enumerate(pairs):
            index = k * len(pairs) + p
            ax = axes[index // cols][index % cols]
            ax.scatter(errors[:, i], errors[:, j], s=12, color="tab:blue", zorder=3,
                       label=f"measured runs (n = {e['n']})")
            add_ellipse(ax, e["predicted"]["mean"], e["predicted"]["cov"], i, j,
                        color="tab:red", lw=1.6, label="model, 95%")
            if e["n"] > 2:
                add_ellipse(ax, e["measured"]["mean"], e["measured"]["cov"], i, j,
                            color="tab:blue", ls="--", lw=1.2, label="data, 95%")
            ax.plot(*e["predicted"]["mean"][i:j + 1:j - i], "r+", ms=10)
            ax.set_xlabel(LABELS[i])
            ax.set_ylabel(LABELS[j])
            ax.grid(alpha=0.3)
            ax.locator_params(nbins=5)
            ax.ticklabel_format(style="sci", scilimits=(-2, 3))
            ax.autoscale_view()
            ax.margins(0.2)
            verdict = e["verdict"]
            ax.set_title(f"{e['name']}: {verdict}", fontsize=9,
                         color="tab:red" if verdict == "inconsistent" else "black")
            if index == 0:
                ax.legend(fontsize=7, loc="best")
    for index in range(len(experiments) * len(pairs), rows * cols):
        axes[index // cols][index % cols].axis("off")
    fig.suptitle(args.title or f"{data.get('suite', '')}: model against measurements "
                 f"(verdict {data['verdict']})", fontsize=11)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / (3.8 * rows)))
    fig.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
