#!/usr/bin/python3
"""Covariance ellipses along a path with the odomcov Python module.

A robot with wheelbase 0.4 m and kL = kR = 2e-3 m^(1/2) drives a 2 m line, a left arc of radius
1 m through 180 deg and a 1 m line back, its encoders sampled at 50 Hz. odomcov.predict gives the
pose and the first-order covariance of the odometry error at every sample; the script draws the
1-sigma x-y ellipse (magnified) every half metre.

    scripts/build.sh
    PYTHONPATH=build/python /usr/bin/python3 examples/python/ellipses_along_path.py --out path.png
"""
import argparse
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "build", "python"))
import numpy as np  # noqa: E402

import odomcov  # noqa: E402

B, K, RATE, SPEED = 0.4, 2e-3, 50.0, 0.4


def wheel_travel():
    """Cumulative (left, right) per sample: line, arc, line; the faster wheel at SPEED."""
    pieces = [(2.0, 2.0), (math.pi * (1 - B / 2), math.pi * (1 + B / 2)), (1.0, 1.0)]
    left, right = [0.0], [0.0]
    for dl, dr in pieces:
        n = int(round(max(abs(dl), abs(dr)) / SPEED * RATE))
        for k in range(1, n + 1):
            left.append(left[-1] + dl / n)
            right.append(right[-1] + dr / n)
    return np.array(left), np.array(right)


def main():
    parser = argparse.ArgumentParser(description="Covariance ellipses along a path (odomcov.predict)")
    parser.add_argument("--out", required=True, help="output image")
    parser.add_argument("--magnify", type=float, default=20.0)
    args = parser.parse_args()
    try:
        import matplotlib
    except ImportError:
        print("needs matplotlib: install python3-matplotlib", file=sys.stderr)
        sys.exit(2)
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    left, right = wheel_travel()
    out = odomcov.predict(left, right, B, K, K)
    pose, cov = out["pose"], out["cov"]
    travel = np.concatenate([[0.0], np.cumsum(np.abs(np.diff((left + right) / 2)))])
    marks = [int(np.searchsorted(travel, s)) for s in np.arange(0.5, travel[-1], 0.5)] + [len(travel) - 1]
    fig, ax = plt.subplots(figsize=(7, 6))
    ax.plot(pose[:, 0], pose[:, 1], "k-", lw=1)
    for i in marks:
        values, vectors = np.linalg.eigh(cov[i][:2, :2])
        a, b = np.sqrt(np.clip(values[::-1], 0, None))
        angle = math.degrees(math.atan2(vectors[1, 1], vectors[0, 1]))
        ax.add_patch(Ellipse(pose[i, :2], 2 * a * args.magnify, 2 * b * args.magnify, angle=angle,
                             fill=False, color="C0"))
    ax.set_aspect("equal")
    ax.set_title(f"1-sigma ellipses x {args.magnify:g}, every 0.5 m (B = {B} m, k = {K})")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    fig.savefig(args.out, dpi=120)
    end = cov[-1]
    print(f"end pose {pose[-1].round(4)}, sd x, y, theta = {np.sqrt(np.diag(end)).round(5)}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
