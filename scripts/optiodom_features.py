#!/usr/bin/python3
"""Two path features of the imported OptiOdom runs, per path type and campaign, from the logged
wheel travel of each run (the imported CSVs, columns t,left,right in metres):

  spin fraction r, weighted by the rotation: sum(|dR - dL| r) / sum(|dR - dL|) with the
      per-sample r = |dR - dL| / (|dL| + |dR|) (0 on a line, 1 on the spot): how tightly the run
      turns where it turns;
  speed, weighted by the distance: sum(d v) / sum(d) with d = (|dL| + |dR|)/2, v = d/dt.

The campaign is the session's month: 2312 December 2020, 2306/2506 June 2020, else January 2021.

Usage: optiodom_features.py SUITE_DIR > features.md
"""
import csv
import glob
import os
import sys

CAMPAIGNS = {"2312": "December 2020", "2306": "June 2020", "2506": "June 2020"}


def features(path):
    with open(path) as f:
        rows = [(float(r["t"]), float(r["left"]), float(r["right"])) for r in csv.DictReader(f)]
    turn = spin = dist = speed = 0.0
    for (t0, l0, r0), (t1, l1, r1) in zip(rows, rows[1:]):
        dl, dr, dt = l1 - l0, r1 - r0, t1 - t0
        both = abs(dl) + abs(dr)
        if both == 0 or dt <= 0:
            continue
        w = abs(dr - dl)
        turn += w
        spin += w * w / both
        d = both / 2
        dist += d
        speed += d * d / dt
    return (spin / turn if turn else None), (speed / dist if dist else None)


def main():
    root = sys.argv[1]
    table = {}
    for path in sorted(glob.glob(os.path.join(root, "*", "*", "run-*.csv"))):
        kind, session = path.split(os.sep)[-3:-1]
        key = (kind, CAMPAIGNS.get(session[:4], "January 2021"))
        table.setdefault(key, []).append(features(path))
    print("| path type | campaign | runs | spin fraction r (rotation-weighted): mean [min, max] "
          "| speed [m/s] (distance-weighted): mean [min, max] |")
    print("|---|---|---|---|---|")
    for (kind, campaign), values in sorted(table.items()):
        cells = []
        for i in (0, 1):
            xs = [v[i] for v in values if v[i] is not None]
            cells.append(f"{sum(xs) / len(xs):.3f} [{min(xs):.3f}, {max(xs):.3f}]")
        print(f"| {kind} | {campaign} | {len(values)} | {cells[0]} | {cells[1]} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
