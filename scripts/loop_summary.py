#!/usr/bin/python3
"""One Markdown table across several `odomcov calibrate` runs (e.g. the OptiOdom splits), from
their calibrate.json files (docs/json.md, "calibrate"): per run, the effects adopted in order,
the final model's sizes ± standard errors, the NEES and log-likelihood on the training runs
(and their NEES per kind of path), the NEES on the held-out runs (pooled, per kind of path,
the model's effects refitted on them, the marginal NEES of the model, of the training
posterior of what it sized and of everything, experiments consistent, experiments outside the training
domain; and per group of held-out experiments, the kind of path with the last word of the name,
OptiOdom's direction cw, ccw or straight), the candidates the cross-validation stopped, and the
verdict. Every figure is
calibrate's; this script only lays them side by side.

Usage: loop_summary.py NAME=CALIBRATE_DIR_OR_JSON [NAME=... ...] > summary.md
"""
import json
import os
import sys


def plus_minus(value, stderr, digits=5):
    """value ± its standard error, or "(no standard error)" when the fit has none."""
    return f"{value:.{digits}g} ± " + (f"{stderr:.2g}" if stderr is not None else "(no standard error)")


def load(path):
    if os.path.isdir(path):
        path = os.path.join(path, "calibrate.json")
    with open(path) as f:
        return json.load(f)


def sizes(report):
    """The final model's fitted parameters: the joint fit's when calibrate took it, else the
    last adopting round's (as diagnose sized them)."""
    model = report["model"]
    fit = report.get("joint_fit")
    if fit and model.get("joint_fit_adopted"):
        return ", ".join(f"{k} = {plus_minus(v, fit['stderr'].get(k))}" for k, v in fit["parameters"].items())
    adopted = [d["best"]["effect"] for d in report["rounds"] if d.get("best")]
    if not adopted:
        return "nothing fitted"
    return f"the loop's model ({model.get('joint_fit_note', 'no joint fit')})"


def held_out_cells(held, kinds):
    if not held:
        return [""] * (len(kinds) + 7)
    by_kind = [f"{held['by_kind'][k]:.2f}" if k in held["by_kind"] else "" for k in kinds]
    # holdout.extrapolation has one entry per experiment and feature, "name: feature ...".
    outside = len({x.split(": ", 1)[0] for x in held["extrapolation"]})
    refitted = held.get("refitted")
    predictive = held.get("predictive")
    return by_kind + [f"**{held['nees_mean']:.2f}**", f"{refitted['nees_mean']:.2f}" if refitted else "",
                      f"{predictive['plugin_nees_mean']:.2f}" if predictive else "",
                      f"{predictive['sized_nees_mean']:.2f}" if predictive else "",
                      f"{predictive['nees_mean']:.2f}" if predictive else "",
                      f"{held['consistent_experiments']} of {held['experiments']}", str(outside)]


def held_out_groups(held):
    """The held-out NEES per run by experiment group: the kind (the name's first part) with the
    name's last part when that is a word (OptiOdom's cw, ccw, straight; not a session's
    number), weighted by runs: {group: (NEES mean, runs)}."""
    sums = {}
    for e in held["compare"]["experiments"]:
        parts = e["name"].split("-")
        group = parts[0] + (" " + parts[-1] if len(parts) > 1 and parts[-1].isalpha() else "")
        total, runs = sums.get(group, (0.0, 0))
        sums[group] = (total + e["nees_mean"] * e["n"], runs + e["n"])
    return {g: (total / runs, runs) for g, (total, runs) in sums.items()}


def stopped(report):
    """Significant candidates the guards stopped, with the rule (mimics first)."""
    out = []
    for c in report["candidates_cv"]:
        if c["verdict"] in ("mimic", "stopped"):
            gain = "" if c["gain_held_out"] is None else f", held out {c['gain_held_out']:+.1f}"
            entry = f"{c['effect']} (round {c['round']}: {c['rule']}{gain})"
            if entry not in out:
                out.append(entry)
    return out


def main():
    runs = []
    for arg in sys.argv[1:]:
        name, _, path = arg.partition("=")
        runs.append((name, load(path)))
    kinds = sorted({k for _, r in runs if r.get("holdout") for k in r["holdout"]["by_kind"]})
    print("## Effects adopted (in order) and the final model's sizes (± standard error)\n")
    print("| split | adopted, in order | sizes |")
    print("|---|---|---|")
    for name, r in runs:
        print(f"| {name} | {', '.join(r['named']) or 'nothing'} | {sizes(r)} |")
    held = any(r.get("holdout") for _, r in runs)
    columns = ["split", "training runs", "training verdict", "training log-likelihood"] + (
        [f"held out: {k}" for k in kinds]
        + ["held out, pooled", "the effects refitted on the held-out runs",
           "held out, marginal (no run conditioned on another)",
           "held out, marginal, with the training posterior of what it sized",
           "held out, marginal, with the priors of what it did not size besides", "held-out experiments consistent",
           "held-out experiments outside the domain"]
        if held else [])
    print("\n## NEES per run (3 is right)\n")
    print("| " + " | ".join(columns) + " |")
    print("|" + "---|" * len(columns))
    for name, r in runs:
        after = r["after"]
        cells = [name, f"{after['nees_mean']:.2f}", after["verdict"], f"{after['log_likelihood']:.1f}"]
        cells += held_out_cells(r.get("holdout"), kinds) if held else []
        print("| " + " | ".join(cells) + " |")
    groups = {name: held_out_groups(r["holdout"]) for name, r in runs if r.get("holdout")}
    columns = sorted({g for by_group in groups.values() for g in by_group})
    if columns:
        print("\n## Held-out NEES per run by experiment group (kind of path and the name's last word; runs)\n")
        print("| split | " + " | ".join(columns) + " |")
        print("|---|" + "---|" * len(columns))
        for name, by_group in groups.items():
            print(f"| {name} | " + " | ".join(f"{by_group[g][0]:.2f} ({by_group[g][1]})" if g in by_group else ""
                                              for g in columns) + " |")
    trained = sorted({k for _, r in runs for k in r["after"].get("by_kind", {})})
    if trained:
        print("\n## NEES per run on the training runs, by kind of path (in-sample)\n")
        print("| split | " + " | ".join(trained) + " |")
        print("|---|" + "---|" * len(trained))
        for name, r in runs:
            by_kind = r["after"].get("by_kind", {})
            print(f"| {name} | " + " | ".join(f"{by_kind[k]:.2f}" if k in by_kind else "" for k in trained) + " |")
    print("\n## Significant candidates the guards stopped (docs/calibrate.md, \"Guards\")\n")
    for name, r in runs:
        print(f"- {name}: " + ("; ".join(stopped(r)) or "none"))
    print("\n## Verdict on the training runs\n")
    for name, r in runs:
        top = [f"{x['feature']}{', ' + x['part'] if x.get('part') else ''} (p = {x['p_value']:.2g})"
               for x in r.get("residuals") or []
               if x.get("p_value") is not None and x["p_value"] < r["alpha"]][:3]
        verdict = "explained" if r["explained"] else "not explained"
        print(f"- {name}: {verdict}" + (f"; the misfit lines up with {', '.join(top)}" if top else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
