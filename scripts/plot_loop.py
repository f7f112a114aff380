#!/usr/bin/python3
"""Watch the error fall: one row per round of a scripts/diagnose_loop.py run.

Each row sets the model before the round against the model after it (the effect named that
round added). Its first panel is the mean NEES per path type, before and after (3 is right).
Then, for each path type, the x-y end-point errors of its runs with every experiment's
predicted 95% ellipse before (dashed) and after (solid), on the same axes.

The path type is the experiment name's prefix before the first '-' (square-..., circular-...),
or the first group of --group-by REGEX.

With --holdout (a loop run with --holdout or --train), a last row sets the held-out runs with
the suite's model against the joint fit learnt on the other runs.

Usage: plot_loop.py LOOP_DIR [--group-by REGEX] [--types N] [--holdout] --out FIG.png
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
    sys.exit("plot_loop.py needs matplotlib: apt-get install python3-matplotlib, "
             "and run it with /usr/bin/python3")

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


def nees_by_kind(compare, pattern):
    sums = {}
    for e in compare["experiments"]:
        k = kind_of(e["name"], pattern)
        s = sums.setdefault(k, [0.0, 0])
        s[0] += e["nees_mean"] * e["n"]
        s[1] += e["n"]
    return {k: v[0] / v[1] for k, v in sums.items()}


def draw_row(axes, before, after, label, kinds, pattern):
    """One row: the NEES by path type before and after, then each path type's x-y errors with
    the predicted 95% ellipses before (dashed) and after (solid)."""
    ax = axes[0]
    nb, na = nees_by_kind(before, pattern), nees_by_kind(after, pattern)
    xs = range(len(nb))
    ax.bar([x - 0.2 for x in xs], list(nb.values()), 0.4, label="before", color="0.7")
    ax.bar([x + 0.2 for x in xs], [na.get(k, float("nan")) for k in nb], 0.4, label="after",
           color="tab:blue")
    ax.axhline(3, color="k", lw=0.8, ls=":")
    ax.set_xticks(list(xs))
    ax.set_xticklabels(list(nb), rotation=30, fontsize=7)
    ax.set_yscale("log")
    ax.set_title(f"{label}\nNEES mean by path type", fontsize=8)
    ax.legend(fontsize=7)
    by_name = {e["name"]: e for e in after["experiments"]}
    for ax, k in zip(axes[1:], kinds):
        drawn = 0
        for e in before["experiments"]:
            if kind_of(e["name"], pattern) != k or e["name"] not in by_name:
                continue
            drawn += 1
            a = by_name[e["name"]]
            ax.plot([p[0] for p in a["errors"]], [p[1] for p in a["errors"]], ".", ms=3, color="k")
            ellipse(ax, e["predicted"]["mean"], e["predicted"]["cov"], color="0.5", ls="--", lw=0.8)
            ellipse(ax, a["predicted"]["mean"], a["predicted"]["cov"], color="tab:blue", lw=0.9)
        if not drawn:  # a path type of the other side of a hold-out
            ax.axis("off")
            continue
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"{k}: x-y error [m], 95% before (dashed) / after", fontsize=8)
        ax.tick_params(labelsize=6)
    for ax in axes[1 + len(kinds):]:
        ax.axis("off")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("loop", help="the --out directory of scripts/diagnose_loop.py")
    parser.add_argument("--group-by", default=r"^([^-]+)",
                        help="regex whose first group is the path type (default: the name's "
                             "prefix before the first '-')")
    parser.add_argument("--types", type=int, default=4, help="at most this many path types drawn")
    parser.add_argument("--holdout", action="store_true",
                        help="add a last row: the held-out runs with the suite's model against "
                             "the joint fit (or the loop's model) learnt on the others")
    parser.add_argument("--out", required=True, help="output image (PNG)")
    args = parser.parse_args()
    with open(os.path.join(args.loop, "loop.json")) as f:
        report = json.load(f)
    files = report.get("compare_rounds") or []
    if len(files) < 2:
        files = [os.path.join(args.loop, "compare-before.json"),
                 os.path.join(args.loop, "compare-after.json")]
    compares = []
    for path in files:
        with open(path) as f:
            compares.append(json.load(f))
    named = [s["named"] for s in report["rounds"] if s.get("named")]
    pairs = [(compares[r], compares[r + 1],
              f"round {r + 1}: + {named[r] if r < len(named) else 'nothing named'}")
             for r in range(len(compares) - 1)]
    held = report.get("holdout")
    if args.holdout and held:
        after = "compare_fit" if "compare_fit" in held else "compare_after"
        with open(os.path.join(args.loop, "holdout-before.json")) as f:
            first = json.load(f)
        with open(os.path.join(args.loop, f"holdout-{after}.json")) as f:
            last = json.load(f)
        pairs.append((first, last, "held-out runs: the suite's model → "
                      + ("the joint fit" if after == "compare_fit" else "the loop's model")))
    kinds = []
    for before, _, _ in pairs:
        for e in before["experiments"]:
            k = kind_of(e["name"], args.group_by)
            if k not in kinds:
                kinds.append(k)
    kinds = kinds[:args.types]
    fig, axes = plt.subplots(len(pairs), 1 + len(kinds),
                             figsize=(3.6 * (1 + len(kinds)), 3.4 * len(pairs)), squeeze=False)
    for row, (before, after, label) in zip(axes, pairs):
        draw_row(row, before, after, label, kinds, args.group_by)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
