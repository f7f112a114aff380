#!/usr/bin/python3
"""The NumPy simulator a user would write: the speed baseline of docs/performance.md.

Same model as odomcov's simulator on the [Kleeman95] Table III config (configs/kleeman95/
table3.yaml: wheelbase 0.5 m, kL = kR = 1e-3, the Fig. 7 keyframes at 200 Hz, 1000 samples per
run): per sample, each wheel's true travel is the encoder increment plus N(0, k^2 |increment|), and
the pose follows the exact constant-curvature (arc) update. Vectorised over runs the way NumPy
is meant to be used: one array per state variable, one array operation per formula, a Python loop
over the samples only.

Prints the wheel-sample steps per second (best of --repeats) on one line:
    numpy_baseline: 21.3 M steps/s (8192 runs x 1000 samples, best of 3)
Threads: NumPy's element-wise operations and its random generator run on one core; the script
sets the BLAS thread count to 1 so nothing else does either.
"""
import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

WHEELBASE = 0.5
K_LEFT = K_RIGHT = 1.0e-3
RATE_HZ = 200.0
# (t, left, right): the Fig. 7 keyframes of table3.yaml, wheel travel in metres.
KEYFRAMES = [(0, 0, 0), (2, 2, 2), (3, 1.6073, 2.3927), (4, 3.5708, 3.5708),
             (5, 3.37445, 4.15985)]


def encoder_increments():
    """Per-sample encoder increments (dL, dR): each keyframe interval split evenly."""
    dl, dr = [], []
    for (t0, l0, r0), (t1, l1, r1) in zip(KEYFRAMES, KEYFRAMES[1:]):
        n = int(round((t1 - t0) * RATE_HZ))
        dl += [(l1 - l0) / n] * n
        dr += [(r1 - r0) / n] * n
    return np.array(dl), np.array(dr)


def simulate(runs, rng, dl, dr):
    """End poses (x, y, theta) of `runs` noisy robots, vectorised over runs."""
    x = np.zeros(runs)
    y = np.zeros(runs)
    theta = np.zeros(runs)
    sd_l = K_LEFT * np.sqrt(np.abs(dl))
    sd_r = K_RIGHT * np.sqrt(np.abs(dr))
    for i in range(len(dl)):
        left = dl[i] + sd_l[i] * rng.standard_normal(runs)
        right = dr[i] + sd_r[i] * rng.standard_normal(runs)
        ds = 0.5 * (left + right)
        dtheta = (right - left) / WHEELBASE
        # exact arc: chord ds sinc(dtheta/2) at the mid heading (np.sinc(x) = sin(pi x)/(pi x))
        chord = ds * np.sinc(dtheta / (2 * np.pi))
        mid = theta + 0.5 * dtheta
        x += chord * np.cos(mid)
        y += chord * np.sin(mid)
        theta += dtheta
    return x, y, theta


def best_rate(runs, repeats, dl, dr, clock=time.perf_counter):
    """Steps per second, the best of `repeats` simulations of `runs` runs, by `clock`
    (time.process_time: the CPU time, which a loaded machine's preemption does not inflate)."""
    rng = np.random.default_rng(1)
    simulate(64, rng, dl, dr)  # warm-up
    best = float("inf")
    for _ in range(repeats):
        t0 = clock()
        x, _, _ = simulate(runs, rng, dl, dr)
        best = min(best, clock() - t0)
        assert np.isfinite(x).all()
    return runs * len(dl) / best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8192)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    dl, dr = encoder_increments()
    rate = best_rate(args.runs, args.repeats, dl, dr)
    print(f"numpy_baseline: {rate / 1e6:.1f} M steps/s "
          f"({args.runs} runs x {len(dl)} samples, best of {args.repeats})")


if __name__ == "__main__":
    main()
