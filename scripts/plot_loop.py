#!/usr/bin/python3
"""Watch the error fall: the rounds of an `odomcov calibrate` run, from its --out directory.

Plots only what calibrate.json already holds (docs/json.md, "calibrate"):
  * the NEES mean per run of the training runs, per round (round 0 is the suite's own model,
    each later point the model after that round's adoption, the last the final model: the joint
    fit when calibrate took it); with a hold-out (--holdout or --train), the final model's NEES
    on the held-out runs, pooled and per kind of path (holdout.by_kind). 3 is right;
  * the corrected odometry's mean end-position error before and after, per kind of experiment
    (odometry_correction.by_kind), when the model corrects the odometry;
  * with a hold-out, each held-out kind's x-y end-point errors with the final model's predicted
    95% ellipse per experiment (holdout.compare).

The kind of a held-out experiment is the first group of --group-by (default: the name's prefix
before the first '-', as calibrate's default kind).

Usage: plot_loop.py CALIBRATE_DIR [--group-by REGEX] [--types N] --out FIG.png
"""
import argparse
import json
import math
import os
import re
import sys

try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse
except ImportError:
    print("plot_loop.py: needs matplotlib; install Debian's python3-matplotlib (scripts/setup.sh does) "
          "and run it with /usr/bin/python3", file=sys.stderr)
    sys.exit(2)

CHI2_2_95 = 5.991464547107979  # chi^2_2 95% point


def ellipse(ax, mean, cov, **style):
    a, b, c = cov[0][0], cov[0][1], cov[1][1]
    half = math.sqrt(max(((a - c) / 2) ** 2 + b * b, 0.0))
    l1, l2 = (a + c) / 2 + half, max((a + c) / 2 - half, 0.0)
    angle = math.degrees(0.5 * math.atan2(2 * b, a - c))
    ax.add_patch(Ellipse((mean[0], mean[1]), 2 * math.sqrt(CHI2_2_95 * l1),
                         2 * math.sqrt(CHI2_2_95 * l2), angle=angle, fill=False, **style))


def kind_of(name, pattern):
    m = re.search(pattern, name)
    return (m.group(1) if m and m.groups() else m.group(0)) if m else name


def rounds_nees(report):
    """(label, NEES mean) per step: the suite's model, each adoption, the final model."""
    rounds = report["rounds"]
    steps = [("start", rounds[0]["before"]["nees_mean"])] if rounds else []
    for r, d in enumerate(rounds, 1):
        if d.get("best"):
            steps.append((f"{r}: + {d['best']['effect']}", d["after"]["nees_mean"]))
    final = "joint fit" if report["model"].get("joint_fit_adopted") else "final (loop's model)"
    steps.append((final, report["after"]["nees_mean"]))
    return steps


def draw_rounds(ax, report):
    steps = rounds_nees(report)
    xs = range(len(steps))
    ax.plot(xs, [v for _, v in steps], "o-", color="tab:blue", label="training runs")
    held = report.get("holdout")
    if held:
        last = len(steps) - 1
        ax.plot([last], [held["nees_mean"]], "s", color="tab:red", ms=8, label="held out, pooled")
        for i, (kind, value) in enumerate(held["by_kind"].items()):
            ax.plot([last + 0.15 * (i + 1)], [value], "_", color="tab:red", ms=10, mew=2)
            ax.annotate(kind, (last + 0.15 * (i + 1), value), fontsize=6, xytext=(3, 0),
                        textcoords="offset points", va="center")
    ax.axhline(3, color="k", lw=0.8, ls=":")
    ax.set_xticks(list(xs))
    ax.set_xticklabels([label for label, _ in steps], rotation=35, ha="right", fontsize=6)
    ax.set_yscale("log")
    ax.set_ylabel("NEES mean per run (3 is right)", fontsize=7)
    ax.set_title(f"{report['suite']}: NEES per round", fontsize=8)
    ax.legend(fontsize=6)


def draw_correction(ax, report):
    correction = report.get("odometry_correction")
    if not correction:
        ax.axis("off")
        return
    kinds = correction["by_kind"]
    xs = range(len(kinds))
    ax.bar([x - 0.2 for x in xs], [1e3 * k["mean_xy_before"] for k in kinds], 0.4,
           label="nominal odometry", color="0.7")
    ax.bar([x + 0.2 for x in xs], [1e3 * k["mean_xy_after"] for k in kinds], 0.4,
           label="corrected", color="tab:blue")
    ax.set_xticks(list(xs))
    ax.set_xticklabels([k["kind"] for k in kinds], rotation=30, fontsize=7)
    ax.set_ylabel("mean |xy| end error [mm]", fontsize=7)
    ax.set_title("corrected odometry (training runs)", fontsize=8)
    ax.legend(fontsize=6)


def draw_held_out(axes, compare, kinds, pattern):
    for ax, k in zip(axes, kinds):
        for e in compare["experiments"]:
            if kind_of(e["name"], pattern) != k:
                continue
            ax.plot([p[0] for p in e["errors"]], [p[1] for p in e["errors"]], ".", ms=3, color="k")
            ellipse(ax, e["predicted"]["mean"], e["predicted"]["cov"], color="tab:red", lw=0.9)
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"held out, {k}: x-y error [m], final model's 95%", fontsize=8)
        ax.tick_params(labelsize=6)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("calibrate", help="the --out directory of odomcov calibrate")
    parser.add_argument("--group-by", default=r"^([^-]+)",
                        help="regex whose first group is a held-out experiment's kind (default: "
                             "the name's prefix before the first '-')")
    parser.add_argument("--types", type=int, default=4, help="at most this many held-out kinds drawn")
    parser.add_argument("--out", required=True, help="output image (PNG)")
    args = parser.parse_args()
    with open(os.path.join(args.calibrate, "calibrate.json")) as f:
        report = json.load(f)
    held = report.get("holdout")
    kinds = []
    for e in held["compare"]["experiments"] if held else []:
        k = kind_of(e["name"], args.group_by)
        if k not in kinds:
            kinds.append(k)
    kinds = kinds[:args.types]
    fig, axes = plt.subplots(1, 2 + len(kinds), figsize=(4.2 * (2 + len(kinds)), 4.0), squeeze=False)
    draw_rounds(axes[0][0], report)
    draw_correction(axes[0][1], report)
    if held:
        draw_held_out(axes[0][2:], held["compare"], kinds, args.group_by)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
