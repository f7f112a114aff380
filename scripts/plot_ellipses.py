#!/usr/bin/python3
"""Figures 8 and 9 of [Kleeman95]: the path with the error ellipses at each keyframe.

Reads the JSON of `odomcov theory CONFIG --json FILE`. At every keyframe it draws the x-y error
ellipse of the accumulated covariance (solid) and of the preceding segment's own contribution
(dashed). Both are magnified by the same factor, which is printed on the plot. With --run (the
JSON of `odomcov run CONFIG --json FILE --samples N`) it overlays the Monte-Carlo end points,
magnified about the odometry end pose by the same factor.

It also draws ellipses along an encoder log: given the JSON of `odomcov predict LOG.csv --json
FILE` (pose and covariance per sample), it draws the path and --count ellipses evenly spaced
along it.

Usage: plot_ellipses.py THEORY.json [--run RUN.json] [--sigma N] [--magnify M] --out FIG.png
       plot_ellipses.py PREDICT.json [--count N] [--sigma N] [--magnify M] --out FIG.png
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


def ellipse_axes(cov, sigma):
    """Semi-axes (a >= b) and angle [deg] of the n-sigma ellipse of a 3x3 world covariance."""
    p = np.asarray(cov)[:2, :2]
    values, vectors = np.linalg.eigh(p)
    values = np.clip(values, 0.0, None)
    a, b = sigma * math.sqrt(values[1]), sigma * math.sqrt(values[0])
    angle = math.degrees(math.atan2(vectors[1, 1], vectors[0, 1]))
    return a, b, angle


def nice_magnification(target):
    """The largest 1, 2 or 5 times a power of ten not above target (at least 1)."""
    if target <= 1:
        return 1.0
    exponent = math.floor(math.log10(target))
    for mantissa in (5, 2, 1):
        m = mantissa * 10**exponent
        if m <= target:
            return float(m)
    return float(10**exponent)


def plot_log(data, args):
    """Ellipses along a log: the JSON of `odomcov predict`."""
    samples = data["samples"]
    pose = np.array([s["pose"] for s in samples])
    extent = max(np.ptp(pose[:, 0]), np.ptp(pose[:, 1]), 1e-9)
    picks = sorted(set(np.linspace(0, len(samples) - 1, max(args.count, 2)).round().astype(int)))
    largest = max(ellipse_axes(samples[i]["cov"], args.sigma)[0] for i in picks)
    magnify = args.magnify or nice_magnification(0.08 * extent / max(largest, 1e-300))
    fig, ax = plt.subplots(figsize=(8, 7))
    ax.plot(pose[:, 0], pose[:, 1], "k-", lw=1.2, label="odometry path")
    for n, i in enumerate(picks):
        a, b, angle = ellipse_axes(samples[i]["cov"], args.sigma)
        ax.add_patch(Ellipse(pose[i, :2], 2 * a * magnify, 2 * b * magnify, angle=angle, fill=False,
                             color="C0", lw=1.2, label=None if n else
                             f"{args.sigma:g}-sigma ellipse x {magnify:g}"))
    ax.set_aspect("equal")
    ax.set_xlabel("x [m] (start frame)")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{data.get('log', 'log')}: covariance along the path")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(args.out, dpi=150)
    print(f"wrote {args.out} ({len(picks)} ellipses, magnified {magnify:g}x)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0].replace("\n", " "))
    parser.add_argument("theory", help="JSON of odomcov theory, or of odomcov predict")
    parser.add_argument("--count", type=int, default=12, help="predict JSON: ellipses along the log")
    parser.add_argument("--run", help="JSON of odomcov run with --samples, for the scatter")
    parser.add_argument("--sigma", type=float, default=1.0, help="ellipse level in sigmas")
    parser.add_argument("--magnify", type=float, help="ellipse magnification (default: auto)")
    parser.add_argument("--out", required=True, help="output image (PNG, PDF, SVG)")
    args = parser.parse_args()

    with open(args.theory) as f:
        theory = json.load(f)
    if "samples" in theory:
        return plot_log(theory, args)
    keyframes = theory["keyframes"]
    trace = theory["trace"]
    center = np.asarray(trace["center"])
    extent = max(np.ptp(center[:, 0]), np.ptp(center[:, 1]), 1e-9)

    largest = max(ellipse_axes(k["cov"], args.sigma)[0] for k in keyframes)
    magnify = args.magnify or nice_magnification(0.12 * extent / max(largest, 1e-300))

    fig, ax = plt.subplots(figsize=(8, 7))
    ax.plot(center[:, 0], center[:, 1], "k-", lw=1.2, label="path (axle centre)")
    for side in ("left", "right"):
        track = np.asarray(trace[side])
        ax.plot(track[:, 0], track[:, 1], ":", color="0.5", lw=0.9)
    ax.plot([], [], ":", color="0.5", label="wheel tracks")

    # Keyframes at the same point (a turn on the spot) share one label, e.g. "B, C".
    labels = {}
    for i, k in enumerate(keyframes):
        spot = (round(k["pose"][0] / extent, 6), round(k["pose"][1] / extent, 6))
        name = chr(ord("A") + i) if i < 26 else f"#{i}"
        labels.setdefault(spot, (k["pose"][0], k["pose"][1], []))[2].append(name)
    for x, y, names in labels.values():
        ax.annotate(", ".join(names), (x, y), xytext=(6, 6), textcoords="offset points",
                    fontsize=12, weight="bold", zorder=5)
        ax.plot(x, y, "ko", ms=3, zorder=5)

    for i, k in enumerate(keyframes):
        x, y = k["pose"][0], k["pose"][1]
        if i == 0:
            continue
        for cov, style, color in ((k["cov"], "-", "tab:blue"),
                                  (k["segment_cov"], "--", "tab:red")):
            a, b, angle = ellipse_axes(cov, args.sigma)
            ax.add_patch(Ellipse((x, y), 2 * magnify * a, 2 * magnify * b, angle=angle,
                                 fill=False, ls=style, lw=1.4, color=color, zorder=4))
    ax.plot([], [], "-", color="tab:blue", label="accumulated covariance")
    ax.plot([], [], "--", color="tab:red", label="segment's own contribution")

    if args.run:
        with open(args.run) as f:
            run = json.load(f)
        if "samples" not in run:
            parser.error("--run needs the JSON of `odomcov run ... --samples N`")
        end = np.asarray(run["odometry_end_pose"])
        errors = np.asarray(run["samples"])
        ax.scatter(end[0] + magnify * errors[:, 0], end[1] + magnify * errors[:, 1], s=2,
                   color="tab:green", alpha=0.35, lw=0, zorder=1,
                   label=f"Monte-Carlo end points ({len(errors)} of {run['runs']} runs)")

    robot = theory.get("robot", {})
    title = theory.get("name", "")
    if robot:
        title += (f"\nB = {robot['wheelbase']} m, kL = {robot['k_left']:g}, "
                  f"kR = {robot['k_right']:g} m$^{{1/2}}$")
    ax.set_title(title)
    ax.text(0.02, 0.02, f"{args.sigma:g}-sigma ellipses and errors magnified x{magnify:g}",
            transform=ax.transAxes, fontsize=10,
            bbox=dict(facecolor="white", edgecolor="0.7"))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    ax.margins(0.15)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=130)


if __name__ == "__main__":
    main()
