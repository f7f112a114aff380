#!/usr/bin/python3
"""Breakdown curves of a sweep: where first-order theory stops matching the simulation.

Reads the CSV of `odomcov sweep` (and optionally its --json, which adds the tests against the
noise-induced mean and against the per-sample first-order covariance, [Wang88], and the other
model order's tests: the CSV follows the sweep's --order, and the JSON has both orders, so the
first panel overlays both orders' breakdown curves). The
first grid axis, or --x, is the horizontal axis on a log scale; each combination of the other
axes is one line. Three panels:
  1. the p-values of the mean and covariance tests, with the alpha line; filled markers are
     points whose verdict is inconsistent, a vertical line marks where each test's verdict
     flips, and the title says where each test rejects;
  2. |bias| of each component in standard errors, with the two-sided alpha quantile, and (with
     --json) the joint bias sqrt(chi^2) that the mean test sees, with its alpha quantile;
  3. |std-dev relative error| of each component and the largest correlation difference, with
     the two-sided alpha band of the sampling error of a standard deviation, z/sqrt(2(n-1)).

Usage: plot_sweep.py SWEEP.csv [--json SWEEP.json] [--x AXIS] [--x-factor F] [--x-label TEXT]
                     [--alpha A] --out FIG.png
"""
import argparse
import os
import sys
import csv
import itertools
import json
import math
from statistics import NormalDist

try:
    import matplotlib
except ImportError:
    print("%s: needs matplotlib; install Debian's python3-matplotlib (scripts/setup.sh does) "
          "and run it with /usr/bin/python3" % os.path.basename(sys.argv[0]), file=sys.stderr)
    sys.exit(2)

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

METRICS = ["runs", "seed", "std_rel_err_x", "std_rel_err_y", "std_rel_err_theta",
           "max_corr_diff", "bias_x_se", "bias_y_se", "bias_theta_se", "p_mean", "p_cov",
           "nees_mean", "verdict"]
P_FLOOR = 1e-20  # p-values below this are drawn at it (the panel says so)


def read_rows(path):
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        axes = [c for c in reader.fieldnames if c not in METRICS]
        rows = list(reader)
    for r in rows:
        for k in r:
            if k != "verdict":
                r[k] = float(r[k])
    return axes, rows


def chi2_3_sf(x):
    """Survival function of chi^2 with 3 dof: erfc(sqrt(x/2)) + sqrt(2x/pi) exp(-x/2)."""
    return math.erfc(math.sqrt(x / 2)) + math.sqrt(2 * x / math.pi) * math.exp(-x / 2)


def chi2_3_quantile(alpha):
    """x with chi2_3_sf(x) = alpha, by bisection (the sf is decreasing)."""
    lo, hi = 0.0, 1000.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_3_sf(mid) > alpha else (lo, mid)
    return 0.5 * (lo + hi)


def rejection_note(xs, ps, alpha, x_label):
    """Where a test rejects, in words: from some x upward, up to some x, or a list."""
    bad = [p < alpha for p in ps]
    if not any(bad):
        return None, None
    first = bad.index(True)
    last = len(bad) - 1 - bad[::-1].index(True)
    count = f"({sum(bad)} of {len(bad)} points)"
    if all(bad):
        return xs[0], f"rejects at every point {count}"
    if all(bad[first:]) and first > 0:
        return xs[first], f"rejects from {x_label} = {xs[first]:.3g} upward {count}"
    if all(bad[:last + 1]) and last < len(bad) - 1:
        return xs[last], f"rejects up to {x_label} = {xs[last]:.3g} {count}"
    listed = ", ".join(f"{x:.3g}" for x, b in zip(xs, bad) if b)
    return xs[first], f"rejects at {x_label} = {listed} {count}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("csv", help="CSV of odomcov sweep")
    parser.add_argument("--json", help="JSON of the same sweep (adds the noise-induced mean)")
    parser.add_argument("--x", help="axis for the horizontal axis (default: the first)")
    parser.add_argument("--x-factor", type=float, default=1.0, help="multiply x values by this")
    parser.add_argument("--x-label", help="label of the horizontal axis")
    parser.add_argument("--alpha", type=float, default=1e-3, help="level of the tests")
    parser.add_argument("--title", default="", help="plot title")
    parser.add_argument("--out", required=True, help="output image")
    args = parser.parse_args()

    axes, rows = read_rows(args.csv)
    x_axis = args.x or axes[0]
    if x_axis not in axes:
        parser.error(f"--x {x_axis} is not a grid axis ({', '.join(axes)})")
    others = [a for a in axes if a != x_axis]
    induced, joint, sampled, other = {}, {}, {}, {}
    order, other_order = 1, None
    if args.json:
        with open(args.json) as f:
            doc = json.load(f)
        order = doc.get("order", 1)
        for r in doc["rows"]:
            key = tuple(r["axes"][a] for a in axes)
            induced[key] = r["noise_induced_mean"]["test"]["p_value"]
            joint[key] = math.sqrt(r["tests"]["mean"]["statistic"] or 0.0)
            sampled[key] = r["sampled_theory"]["test"]["p_value"]
            for name in r:
                if name.startswith("order_"):
                    other_order = int(name[len("order_"):])
                    t = r[name]["tests"]
                    other[key] = (t["mean"]["p_value"], t["covariance"]["p_value"])

    groups = {}
    for r in rows:
        groups.setdefault(tuple(r[a] for a in others), []).append(r)
    z_single = NormalDist().inv_cdf(1 - args.alpha / 2)

    fig, (ax_p, ax_b, ax_s) = plt.subplots(3, 1, figsize=(8.5, 11), sharex=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    notes = []
    for (key, members), color in zip(sorted(groups.items()), itertools.cycle(colors)):
        members.sort(key=lambda r: r[x_axis])
        xs = [r[x_axis] * args.x_factor for r in members]
        name = ", ".join(f"{a} = {v:g}" for a, v in zip(others, key))
        suffix = f" ({name})" if name else ""
        bad = [r["verdict"] == "inconsistent" for r in members]
        cov_name = "covariance test (ADF)" if order == 2 else "covariance test (LRT)"
        for metric, marker, label in (("p_mean", "o", f"order {order}: mean test"),
                                      ("p_cov", "s", f"order {order}: {cov_name}")):
            ps = [max(r[metric], P_FLOOR) for r in members]
            ax_p.plot(xs, ps, "-" if metric == "p_mean" else "--", color=color, lw=1,
                      label=label + suffix)
            ax_p.scatter(xs, ps, marker=marker, s=30, color=color,
                         facecolors=[color if b else "white" for b in bad], zorder=3)
            flip, note = rejection_note(xs, [r[metric] for r in members], args.alpha,
                                        args.x_label or x_axis)
            if note:
                ax_p.axvline(flip, color=color, ls=":" if metric == "p_mean" else "-.", lw=1)
                notes.append(f"{label}{suffix}: {note}")
        if other:
            other_cov = "covariance test (ADF)" if other_order == 2 else "covariance test (LRT)"
            for index, marker, label in ((0, "D", f"order {other_order}: mean test"),
                                         (1, "P", f"order {other_order}: {other_cov}")):
                raw = [other.get(tuple(r[a] for a in axes), (float("nan"),) * 2)[index]
                       for r in members]
                ps = [max(p if p is not None else P_FLOOR, P_FLOOR) for p in raw]
                ax_p.plot(xs, ps, "-" if index == 0 else "--", marker=marker, ms=5, lw=2,
                          alpha=0.6, color=color, label=label + suffix)
                flip, note = rejection_note(xs, [p if p is not None else 0.0 for p in raw],
                                            args.alpha, args.x_label or x_axis)
                if note:
                    notes.append(f"{label}{suffix}: {note}")
        if induced and order == 1:
            ps = [max(induced.get(tuple(r[a] for a in axes), float("nan")) or P_FLOOR, P_FLOOR)
                  for r in members]
            ax_p.plot(xs, ps, ":", marker="^", color=color, ms=4, lw=1,
                      label="mean test vs noise-induced mean" + suffix)
            ps = [max(sampled.get(tuple(r[a] for a in axes), float("nan")) or P_FLOOR, P_FLOOR)
                  for r in members]
            ax_p.plot(xs, ps, ":", marker="v", color=color, ms=4, lw=1,
                      label="covariance test vs per-sample theory" + suffix)
        for comp, style in (("x", "-"), ("y", "--"), ("theta", ":")):
            ax_b.plot(xs, [abs(r[f"bias_{comp}_se"]) for r in members], style, marker=".",
                      color=color, label=f"|bias {comp}|{suffix}")
            ax_s.plot(xs, [abs(r[f"std_rel_err_{comp}"]) for r in members], style, marker=".",
                      color=color, label=f"|std rel. err. {comp}|{suffix}")
        if joint:
            ax_b.plot(xs, [joint[tuple(r[a] for a in axes)] for r in members], "-", lw=2.5,
                      alpha=0.5, color=color, label=f"joint sqrt(chi^2){suffix}")
        ax_s.plot(xs, [r["max_corr_diff"] for r in members], "-.", marker="x", color=color,
                  label=f"max |corr diff|{suffix}")
        n = members[0]["runs"]
        band = z_single / math.sqrt(2 * (n - 1))
        ax_s.axhline(band, color=color, lw=0.8, alpha=0.6)
        ax_s.text(0.01, band, f" sampling band of a std-dev at alpha (n = {n:g})",
                  transform=ax_s.get_yaxis_transform(), va="bottom", fontsize=8)

    ax_p.axhline(args.alpha, color="k", lw=1)
    ax_p.text(0.01, args.alpha, f" alpha = {args.alpha:g}", transform=ax_p.get_yaxis_transform(),
              va="bottom")
    ax_p.set_yscale("log")
    ax_p.set_ylim(bottom=P_FLOOR / 3, top=3)
    ax_p.set_ylabel(f"p-value (filled: inconsistent;\nbelow {P_FLOOR:g} drawn at {P_FLOOR:g})")
    ax_b.axhline(z_single, color="k", lw=1)
    ax_b.text(0.99, z_single, f"per component: two-sided alpha quantile {z_single:.2f} ",
              transform=ax_b.get_yaxis_transform(), va="top", ha="right")
    if joint:
        z_joint = math.sqrt(chi2_3_quantile(args.alpha))
        ax_b.axhline(z_joint, color="k", lw=1, ls="--")
        ax_b.text(0.01, z_joint, f" joint: sqrt(chi2_3 alpha quantile) {z_joint:.2f}",
                  transform=ax_b.get_yaxis_transform(), va="bottom")
    ax_b.set_yscale("log")
    ax_b.set_ylabel("|simulated - theory mean| [standard errors]")
    ax_s.set_yscale("log")
    ax_s.set_ylabel("|std-dev relative error|, |corr diff|")
    ax_s.set_xlabel(args.x_label or x_axis)
    for a in (ax_p, ax_b, ax_s):
        a.set_xscale("log")
        a.grid(alpha=0.3, which="both")
        a.legend(fontsize=7, ncol=2)
    fig.suptitle("\n".join([args.title] + notes), fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)


if __name__ == "__main__":
    main()
