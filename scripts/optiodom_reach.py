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

Then, for the two hold-outs that miss their floors (the Ivanjko paths; June → December), what
their training runs say about a parameter they need and cannot size: the all-runs model with that
parameter fixed at each of several values, every other parameter of its joint fit refitted on
the training runs alone (`odomcov fit`; those listed as held stay at their all-runs values), its
training log-likelihood, and `odomcov compare` of it on the held-out runs. The training runs'
own optimum (the parameter fitted too) is a row of its own.

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


# (label, training runs, held-out runs, profiled parameter, its values besides the all-runs one
# and the training optimum, parameters held at their all-runs values)
PROFILES = [
    ("Ivanjko paths held out, the marker offset at its all-runs value", r"^(circular|free|square)-",
     r"^ivanjko-", "scale_error.Es", [1.0, 0.997, 0.995], ["reference_offset.dx", "reference_offset.dy"]),
    ("Ivanjko paths held out, the marker offset fitted on the training runs", r"^(circular|free|square)-",
     r"^ivanjko-", "scale_error.Es", [1.0], []),
    ("June → December", r"^[a-z]+-(2306|2506)", r"^[a-z]+-2312", "group_variation.sd",
     [0.001, 0.003, 0.005], []),
]


def compare(odomcov, suite, out):
    """compare's NEES mean over the suite's runs, its verdict (alpha 0.01) and log-likelihood."""
    run([odomcov, "compare", suite, "--alpha", "0.01", "--json", out])
    with open(out) as f:
        c = json.load(f)
    n = sum(e["n"] for e in c["experiments"])
    return sum(e["nees_mean"] * e["n"] for e in c["experiments"]) / n, c["verdict"], c["log_likelihood"]


def nees(odomcov, suite, out):
    """compare's NEES mean over the suite's runs, and its verdict (alpha 0.01)."""
    mean, verdict, _ = compare(odomcov, suite, out)
    return f"{mean:.2f} ({verdict})"


def set_parameter(model_text, name, value):
    """The model text with the effect parameter `name` ("scale_error.Es") set to `value`."""
    effect, parameter = name.split(".")
    lines = model_text.splitlines()
    at = next(i for i, line in enumerate(lines) if re.match(rf"\s*- {effect}:", line))
    lines[at], count = re.subn(rf"\b{parameter}: [^,}}]+", f"{parameter}: {value!r}", lines[at])
    if count != 1:
        raise RuntimeError(f"{name} not found once in: {lines[at]}")
    return "\n".join(lines) + "\n"


def profile(odomcov, suite, model, params, spec, work, all_runs):
    """One table of the profile study (module docstring) as markdown lines."""
    label, train, test, parameter, values, held = spec
    name = re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")
    train_suite = os.path.join(work, name + "_train.yaml")
    test_suite = os.path.join(work, name + "_test.yaml")
    select_experiments(suite, train, train_suite)
    select_experiments(suite, test, test_suite)
    refitted = [p for p in params if p != parameter and p not in held]
    rows = []
    for value in [None, all_runs[parameter]] + values:
        set_model(train_suite, model if value is None else set_parameter(model, parameter, value))
        fit_json = os.path.join(work, name + "_fit.json")
        run([odomcov, "fit", train_suite, "--params", *(refitted + ([parameter] if value is None else [])),
             "--json", fit_json])
        with open(fit_json) as f:
            fitted = json.load(f)
        set_model(test_suite, fitted["yaml"])
        mean, verdict, log_likelihood = compare(odomcov, test_suite, os.path.join(work, name + "_compare.json"))
        shown = fitted["parameters"][parameter] if value is None else value
        what = ("the training runs' optimum" if value is None else
                "the all-runs value" if value == all_runs[parameter] else "")
        rows.append((shown, what, fitted["log_likelihood_after"], mean, verdict, log_likelihood))
    best = rows[0][2]
    out = [f"### {label}\n", f"Training runs `{train}`, held out `{test}`; {parameter} fixed, "
           f"refitted on the training runs: {', '.join(refitted)}"
           + (f"; held at the all-runs values: {', '.join(held)}" if held else "") + ".\n",
           f"| {parameter} | | training log-likelihood (below the optimum) | held-out NEES | "
           "held-out verdict | held-out log-likelihood |", "|---|---|---|---|---|---|"]
    for shown, what, ll, mean, verdict, held_ll in sorted(rows, key=lambda r: r[0]):
        out.append(f"| {shown:.6g} | {what} | {ll:.1f} ({ll - best:+.1f}) | {mean:.2f} | {verdict} | {held_ll:.1f} |")
    return out


def main():
    odomcov, suite_dir, model, calibrated, work = sys.argv[1:6]
    with open(calibrated) as f:
        all_runs = json.load(f)["joint_fit"]["parameters"]
    params = sorted(all_runs)
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
    print("\n## What the training runs of the two failing hold-outs say\n")
    print("The all-runs model with one parameter fixed, every other parameter of its joint fit")
    print("refitted on the training runs alone (`odomcov fit`) except those held at their all-runs")
    print("values, judged by `odomcov compare` on the held-out runs. The training log-likelihood")
    print("says which value those runs prefer; the held-out NEES, what that value predicts.\n")
    for spec in PROFILES:
        print("\n".join(profile(odomcov, suite, model_of(model), params, spec, work, all_runs)))
        print()


if __name__ == "__main__":
    main()
