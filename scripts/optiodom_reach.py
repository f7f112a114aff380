#!/usr/bin/python3
"""How near 3 the model family gets on a set of runs when it has seen them: the bound a hold-out
figure on those runs can be read against.

For each subset of the imported OptiOdom suite (by experiment name), three in-sample figures:
  * the NEES mean of the model calibrate built on all the runs (MODEL, calibrate's model.yaml),
    by `odomcov compare` on the subset with that model pasted in;
  * the same after `odomcov fit` refits that model's parameters on the subset (the all-runs
    effects at the sizes these runs want; the parameters are the joint fit's, CALIBRATE_JSON);
  * the NEES mean of the model calibrate builds on the subset alone (`odomcov calibrate` on it,
    the loop's own best fit of those runs), and the effects it adopts.
A held-out prediction of a subset is not expected to come nearer 3 than these.

Usage: optiodom_reach.py ODOMCOV SUITE_DIR MODEL CALIBRATE_JSON WORK_DIR > reach.md
"""
import json
import os
import re
import shutil
import sys

from suite_tools import model_of, run, select_experiments, set_model

SUBSETS = [
    ("Ivanjko paths", r"^ivanjko-"),
    ("Ivanjko paths, December 2020", r"^ivanjko-2312"),
    ("Ivanjko paths, June 2020", r"^ivanjko-(2306|2506)"),
    ("December 2020", r"^[a-z]+-2312"),
    ("December 2020 squares", r"^square-2312"),
    ("June 2020", r"^[a-z]+-(2306|2506)"),
]


def nees(odomcov, suite, out):
    """compare's NEES mean over the suite's runs, and its verdict (alpha 0.01)."""
    run([odomcov, "compare", suite, "--alpha", "0.01", "--json", out])
    with open(out) as f:
        c = json.load(f)
    n = sum(e["n"] for e in c["experiments"])
    return f"{sum(e['nees_mean'] * e['n'] for e in c['experiments']) / n:.2f} ({c['verdict']})"


def main():
    odomcov, suite_dir, model, calibrated, work = sys.argv[1:6]
    with open(calibrated) as f:
        params = sorted(json.load(f)["joint_fit"]["parameters"])
    os.makedirs(work, exist_ok=True)
    suite = os.path.join(suite_dir, "suite.yaml")
    rows = []
    for label, pattern in SUBSETS:
        name = re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")
        alone = os.path.join(work, name + ".yaml")
        runs = select_experiments(suite, pattern, alone)
        with_model = os.path.join(work, name + "_all_model.yaml")
        shutil.copyfile(alone, with_model)
        set_model(with_model, model_of(model))
        nees_all = nees(odomcov, with_model, os.path.join(work, name + "_compare.json"))
        refit_json = os.path.join(work, name + "_refit.json")
        run([odomcov, "fit", with_model, "--params", *params, "--json", refit_json])
        with open(refit_json) as f:
            set_model(with_model, json.load(f)["yaml"])
        nees_refit = nees(odomcov, with_model, os.path.join(work, name + "_refit_compare.json"))
        out = os.path.join(work, name + "_calibrate")
        run([odomcov, "calibrate", alone, "--out", out])
        with open(os.path.join(out, "calibrate.json")) as f:
            k = json.load(f)
        named = ", ".join(k["named"]) or "none"
        rows.append(f"| {label} | `{pattern}` | {runs} | {nees_all} | {nees_refit} | "
                    f"{k['after']['nees_mean']:.2f} ({k['after']['verdict']}) | {named} |")
    print("# In-sample reach: the model family on runs it has seen\n")
    print("Made by `scripts/optiodom_reach.py` (scripts/reproduce.sh optiodom). Each figure is the")
    print("NEES mean of the subset's runs (3 when the model is right), in-sample: the all-runs model")
    print("(`model_all.yaml`) by `odomcov compare`; the same effects refitted on the subset by")
    print("`odomcov fit`; and the model `odomcov calibrate` builds on the subset alone; verdicts at")
    print("alpha 0.01. A held-out prediction of a subset is not expected to come nearer 3 than")
    print("these.\n")
    print("| subset | names | runs | all-runs model | its effects refitted on the subset | "
          "calibrated on the subset alone | adopted on the subset alone |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(rows))


if __name__ == "__main__":
    main()
