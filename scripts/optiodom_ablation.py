#!/usr/bin/python3
"""Does an effect the loop named help on the runs it never saw? (issue 10: keep a hypothesis
only when it is significant AND helps held out.) For a diagnose_loop.py run with a hold-out, the
joint fit's model without the given effects, every remaining parameter refitted on the training
runs (full likelihood), compared on the training and on the held-out runs, beside the joint fit
with them.

Usage: optiodom_ablation.py --odomcov BIN --out DIR [--order 1|2]
           NAME:LOOP_DIR[:EFFECT[+EFFECT...]] ...   > ablation.md
Without EFFECTs: the custom effects the loop named, all of them together and (when there are
several) each alone.
"""
import argparse
import json
import os
import sys

from diagnose_loop import compare, copy_suite, model_of, run, set_model, type_table


def _drops(line, effects):
    """Whether a model line is one of `effects` (catalogue `- name:` or `- custom: {name: X`)."""
    item = line.strip()
    return any(item.startswith(f"- {e}:") or f"name: {e}," in item for e in effects)


def named_custom(loop_dir):
    """The custom effects the loop named: all together, then each alone when there are several."""
    with open(os.path.join(loop_dir, "loop.json")) as f:
        report = json.load(f)
    model = model_of(os.path.join(loop_dir, "suite.yaml"))
    named = [s["named"] for s in report["rounds"] if s["named"] and f"name: {s['named']}," in model]
    return ([named] if named else []) + ([[n] for n in named] if len(named) > 1 else [])


def one(odomcov, out, name, loop_dir, effects, order):
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(loop_dir, "loop.json")) as f:
        report = json.load(f)
    params = [p for p in report["fit"]["parameters"] if p.split(".")[0] not in effects]
    train = os.path.join(out, f"{name}-train.yaml")
    copy_suite(os.path.join(loop_dir, "suite-fit.yaml"), train)
    set_model(train, "\n".join(line for line in model_of(train).splitlines()
                               if not _drops(line, effects)) + "\n")
    fit_json = os.path.join(out, f"{name}-fit.json")
    run([odomcov, "fit", train, "--params", ",".join(params), "--order", str(order),
         "--json", fit_json])
    with open(fit_json) as f:
        fit = json.load(f)
    set_model(train, fit["yaml"])
    test = os.path.join(out, f"{name}-test.yaml")
    copy_suite(os.path.join(loop_dir, "holdout.yaml"), test)
    set_model(test, fit["yaml"])
    return {"name": name, "without": effects, "log_likelihood_train": fit["log_likelihood_after"],
            "with": {"log_likelihood_train": report["fit"]["log_likelihood_after"],
                     "train": report["compare_fit"], "test": report["holdout"]["compare_fit"]},
            "train": compare(odomcov, train, os.path.join(out, f"{name}-compare-train.json"), order),
            "test": compare(odomcov, test, os.path.join(out, f"{name}-compare-test.json"), order)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--odomcov", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--order", type=int, choices=[1, 2], default=2)
    parser.add_argument("runs", nargs="+")
    args = parser.parse_args()
    results = []
    for spec in args.runs:
        name, loop_dir, *effects = spec.split(":")
        sets = [effects[0].split("+")] if effects else named_custom(loop_dir)
        if not sets:
            results.append({"name": name, "without": []})  # the loop named no custom effect
        for i, drop in enumerate(sets):
            results.append(one(args.odomcov, args.out, f"{name}-{i}", loop_dir, drop, args.order))
    with open(os.path.join(args.out, "ablation.json"), "w") as f:
        json.dump(results, f, indent=1)
    for r in results:
        if not r["without"]:
            print(f"### {r['name']}: the loop named no custom effect\n")
            continue
        removed = ", ".join(r["without"])
        print(f"### {r['name'].rsplit('-', 1)[0]}: the joint fit with and without {removed}\n\n"
              f"Training log-likelihood {r['with']['log_likelihood_train']:.1f} with, "
              f"{r['log_likelihood_train']:.1f} without (refitted).\n")
        for label, key in (("training runs", "train"), ("held-out runs", "test")):
            rows = [(f"{label}, with", r["with"][key]), (f"{label}, without", r[key])]
            print("\n".join(type_table(rows)))
            print()
            print("\n".join(type_table(rows, heading=True)))
            print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
