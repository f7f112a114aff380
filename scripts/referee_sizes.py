#!/usr/bin/env python3
"""Measured size and power of compare's simulation-calibrated verdict (the referee).

Each case is a world in the standard experiment set of configs/worlds/standard.yaml (9
experiments, 250 runs) with its own effects, and a model: the true one (the rejection rate is
then the test's size, which should be alpha) or a wrong one (the rate is its power). For each of
N worlds (seed = base + i), `odomcov synth` makes the lab's data and `odomcov compare` judges the
model at alpha with the referee (`--calibration simulation`, its seed distinct from the world's);
for the Gaussian world the Gaussian fast path's verdict is recorded too. The rejection counts
get exact (Clopper-Pearson) 95% intervals.

  referee_sizes.py --odomcov BIN --out DIR [--worlds N] [--alpha A] [--cases a,b] [--seed S]
                   [--report FILE.json] [--experiments K]
  referee_sizes.py --merge A.json B.json ... --report FILE.json

--experiments K keeps the first K experiments of the standard set (a smaller lab).
Prints one line per case and writes the JSON report (every world's p-value and verdict).
--merge joins the reports of runs made case by case (in parallel, say) into one, and prints
the same lines."""
import argparse
import json
import math
import os
import re
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STANDARD = os.path.join(ROOT, "configs", "worlds", "standard.yaml")

SYSTEMATIC = ["- wheel_diameter_ratio: {Ed: 1.003}", "- wheelbase_error: {Eb: 1.01}"]
PER_RUN = "- per_run_radius: {sigma: 0.003}"
BUMPS = "- bumps: {rate: 0.5, sigma: 0.005}"
# The same variance rate sigma^2 = 1.25e-5 per metre, other tails: only the shape tells them apart.
BUMPS_BIGGER = "- bumps: {rate: 0.125, sigma: 0.01}"
BUMPS_SMALLER = "- bumps: {rate: 2.0, sigma: 0.0025}"
# A random custom effect: a scale and a wheelbase drawn once per run (the effect language).
RANDOM_CUSTOM = ('- custom: {name: load, parameters: {e: 0.0, w: 0.0}, random: {e: 0.003, w: 0.004}, '
                 'scale: "1 + e", wheelbase_factor: "1 + w"}')
# Large heading noise: k = 3e-3 (three times the standard lab's), where the arc update bends the
# white wheel noise enough that compare's automatic choice simulates (docs/diagnose.md).
NOISY_ROBOT = "robot: {wheelbase: 0.4, k_left: 3.0e-3, k_right: 3.0e-3}"

# name: (world effects, model effects, what the model is, robot line or None for the standard's)
CASES = {
    "gaussian": (SYSTEMATIC, SYSTEMATIC, "correct", None),
    "per_run_radius": (SYSTEMATIC + [PER_RUN], SYSTEMATIC + [PER_RUN], "correct", None),
    "bumps": (SYSTEMATIC + [BUMPS], SYSTEMATIC + [BUMPS], "correct", None),
    "random_custom": (SYSTEMATIC + [RANDOM_CUSTOM], SYSTEMATIC + [RANDOM_CUSTOM], "correct", None),
    "heading_noise": (SYSTEMATIC, SYSTEMATIC, "correct", NOISY_ROBOT),
    "bumps_too_big": (SYSTEMATIC + [BUMPS], SYSTEMATIC + [BUMPS_BIGGER], "wrong", None),
    "bumps_too_small": (SYSTEMATIC + [BUMPS], SYSTEMATIC + [BUMPS_SMALLER], "wrong", None),
}


def clopper_pearson(k, n, level=0.95):
    """Exact binomial interval by bisection on the binomial tails (no SciPy needed)."""
    def cdf(k, n, p):  # P(X <= k)
        if p <= 0:
            return 1.0
        if p >= 1:
            return 0.0 if k < n else 1.0
        total, term = 0.0, (1 - p) ** n
        for i in range(k + 1):
            total += term
            term *= (n - i) / (i + 1) * p / (1 - p)
        return min(1.0, total)

    a = (1 - level) / 2

    def solve(f):
        lo, hi = 0.0, 1.0
        for _ in range(100):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if f(mid) else (lo, mid)
        return (lo + hi) / 2

    lower = 0.0 if k == 0 else solve(lambda p: 1 - cdf(k - 1, n, p) < a)
    upper = 1.0 if k == n else solve(lambda p: cdf(k, n, p) > a)
    return lower, upper


def world_text(effects, seed, experiments, robot=None):
    text = open(STANDARD).read()
    if robot:
        text = re.sub(r"^robot: .*$", robot, text, count=1, flags=re.M)
    text = re.sub(r"world:\n  effects:\n(    - .*\n)+", "world:\n  effects:\n" +
                  "".join(f"    {e}\n" for e in effects), text)
    text = re.sub(r"^seed: .*$", f"seed: {seed}", text, flags=re.M)
    if experiments:
        head, body = text.split("experiments:\n", 1)
        items = re.split(r"(?m)^(?=  - name:)", body)
        text = head + "experiments:\n" + "".join(items[1:experiments + 1])
    return text


def with_model(suite_file, model):
    text = open(suite_file).read()
    block = "model:\n  effects:\n" + "".join(f"    {e}\n" for e in model)
    text = re.sub(r"^experiments:", block + "experiments:", text, count=1, flags=re.M)
    with open(suite_file, "w") as f:
        f.write(text)


def compare(odomcov, suite, alpha, calibration, seed, out):
    subprocess.run([odomcov, "compare", suite, "--alpha", str(alpha), "--calibration", calibration,
                    "--seed", str(seed), "--json", out], check=True, stdout=subprocess.DEVNULL)
    with open(out) as f:
        d = json.load(f)
    return {"verdict": d["verdict"], "p_value": d["p_value"], "replicates": d["replicates"],
            "reference_replicates": d.get("reference_replicates"),
            "close_call": d["close_call"], "beyond": d["beyond_replicates"]}


def run_case(args, name):
    world_effects, model_effects, kind, robot = CASES[name]
    rows = []
    for i in range(args.worlds):
        seed = args.seed + i
        work = os.path.join(args.out, name, f"world-{i:04d}")
        os.makedirs(work, exist_ok=True)
        world = os.path.join(work, "world.yaml")
        with open(world, "w") as f:
            f.write(world_text(world_effects, seed, args.experiments, robot))
        lab = os.path.join(work, "lab")
        subprocess.run([args.odomcov, "synth", world, "--out", lab], check=True, stdout=subprocess.DEVNULL)
        suite = os.path.join(lab, "suite.yaml")
        with_model(suite, model_effects)
        # The referee's seed differs from the world's, so its replicates are not the lab's runs.
        row = {"seed": seed, "simulation": compare(args.odomcov, suite, args.alpha, "simulation",
                                                   seed + 1_000_003, os.path.join(work, "compare.json"))}
        if name == "gaussian":
            row["gaussian"] = compare(args.odomcov, suite, args.alpha, "gaussian", 1,
                                      os.path.join(work, "compare_gaussian.json"))
        rows.append(row)
    return {"kind": kind, "world": world_effects, "model": model_effects, "robot": robot, "worlds": rows}


def summarise(name, case, alpha, key):
    rows = [r[key] for r in case["worlds"] if key in r]
    k = sum(r["verdict"] == "inconsistent" for r in rows)
    n = len(rows)
    lo, hi = clopper_pearson(k, n)
    replicates = sorted(r["replicates"] or 0 for r in rows)
    return {"case": name, "calibration": key, "model": case["kind"], "worlds": n, "rejections": k,
            "rate": k / n if n else math.nan, "interval_95": [lo, hi], "alpha": alpha,
            "close_calls": sum(r["close_call"] for r in rows),
            "median_replicates": replicates[len(replicates) // 2] if replicates else 0}


def summary_line(name, key, s, seconds):
    return (f"{name:16s} {key:10s} {s['model']:7s}: {s['rejections']:4d} of {s['worlds']:4d} "
            f"rejected at alpha = {s['alpha']} ({100 * s['rate']:.2f}%, exact 95% interval "
            f"{100 * s['interval_95'][0]:.2f}-{100 * s['interval_95'][1]:.2f}%), "
            f"{s['close_calls']} close calls, median B {s['median_replicates']}, {seconds:.0f} s")


def add_case(report, name, case):
    report["cases"][name] = case
    for key in ("simulation", "gaussian"):
        if any(key in r for r in case["worlds"]):
            s = summarise(name, case, report["alpha"], key)
            report["summary"].append(s)
            print(summary_line(name, key, s, case["seconds"]), flush=True)


def merge(files, out):
    report = None
    for file in files:
        with open(file) as f:
            part = json.load(f)
        if report is None:
            report = {"alpha": part["alpha"], "seed": part["seed"], "cases": {}, "summary": []}
        if part["alpha"] != report["alpha"] or part["seed"] != report["seed"]:
            sys.exit(f"{file}: alpha or seed differs from {files[0]}'s")
        for name, case in part["cases"].items():
            add_case(report, name, case)
    if out:
        with open(out, "w") as f:
            json.dump(report, f, indent=1)
    return 0


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--merge", nargs="+")
    p.add_argument("--odomcov")
    p.add_argument("--out")
    p.add_argument("--worlds", type=int, default=200)
    p.add_argument("--alpha", type=float, default=0.01)
    p.add_argument("--seed", type=int, default=20261201)
    p.add_argument("--cases", default=",".join(CASES))
    p.add_argument("--experiments", type=int, default=0)
    p.add_argument("--report")
    args = p.parse_args()
    if args.merge:
        return merge(args.merge, args.report)
    if not args.odomcov or not args.out:
        p.error("--odomcov and --out are required (or --merge)")
    report = {"alpha": args.alpha, "seed": args.seed, "cases": {}, "summary": []}
    for name in args.cases.split(","):
        start = time.time()
        case = run_case(args, name)
        case["seconds"] = time.time() - start
        add_case(report, name, case)
    if args.report:
        with open(args.report, "w") as f:
            json.dump(report, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
