#!/usr/bin/python3
"""The OptiOdom loops' models with group_variation (issue 10): the model each loop built, its
group_variation (if any) replaced by one of PARAMETER drawn once per group (`group:` of the
given suite: the session, or the recording day with `import optiodom --group day`), fitted on
the training runs (the group's sd and the varied parameter), then compared on the training runs
and on the held-out runs. A held-out group is predicted with the between-group spread. The same
loop model with session and with day groups says which grouping the data support.

Usage: optiodom_group.py --odomcov BIN --out DIR [--order 1|2]
           NAME:GROUPED_SUITE.yaml:LOOP_DIR:PARAMETER:TRAIN_REGEX[:TEST_REGEX] ...   > group.md
(TRAIN_REGEX '.' and no TEST_REGEX: in-sample on every run.)
"""
import argparse
import json
import os
import sys

from diagnose_loop import compare, model_of, plus_minus, run, set_model, split_suite, type_table


def one(odomcov, suite, out, name, loop_dir, parameter, train, test, order):
    os.makedirs(out, exist_ok=True)
    source = os.path.join(loop_dir, "suite-fit.yaml")
    if not os.path.exists(source):
        source = os.path.join(loop_dir, "suite.yaml")
    kept = [line for line in model_of(source).rstrip("\n").splitlines()
            if not line.lstrip().startswith("- group_variation:")]  # one group_variation: ours
    model = "\n".join(kept) + f"\n    - group_variation: {{parameter: {parameter}, sd: 0.002}}\n"
    files = {"train": os.path.join(out, f"{name}-train.yaml")}
    split_suite(suite, files["train"], train, True)
    if test:
        files["test"] = os.path.join(out, f"{name}-test.yaml")
        split_suite(suite, files["test"], test, True)
    set_model(files["train"], model)
    fit_json = os.path.join(out, f"{name}-fit.json")
    run([odomcov, "fit", files["train"], "--params", f"group_variation.sd,{parameter}",
         "--order", str(order), "--json", fit_json])
    with open(fit_json) as f:
        fit = json.load(f)
    result = {"name": name, "suite": suite, "parameter": parameter, "fit": {k: (v, fit["stderr"][k])
                                                            for k, v in fit["parameters"].items()}}
    for key, path in files.items():
        set_model(path, fit["yaml"])
        result[key] = compare(odomcov, path, os.path.join(out, f"{name}-compare-{key}.json"), order)
    result["log_likelihood_train"] = fit["log_likelihood_after"]
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--odomcov", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("--order", type=int, choices=[1, 2], default=2)
    parser.add_argument("runs", nargs="+")
    args = parser.parse_args()
    results = []
    for spec in args.runs:
        name, suite, loop_dir, parameter, train, *test = spec.split(":")
        results.append(one(args.odomcov, suite, args.out, name, loop_dir, parameter, train,
                           test[0] if test else None, args.order))
    with open(os.path.join(args.out, "group.json"), "w") as f:
        json.dump(results, f, indent=1)
    for r in results:
        sizes = ", ".join(f"{k} = {plus_minus(v, se, 5)}" for k, (v, se) in r["fit"].items())
        print(f"### {r['name']}: group_variation of {r['parameter']}\n\nGroups from `{r['suite']}`. "
              f"Fitted on the training runs: {sizes}; log-likelihood "
              f"{r['log_likelihood_train']:.1f}.\n")
        rows = [("training runs", r["train"])] + ([("held-out runs", r["test"])] if "test" in r else [])
        print("\n".join(type_table(rows)))
        print()
        print("\n".join(type_table(rows, heading=True)))
        for label, c in rows:
            print(f"\n- {label}: NEES {c['nees_mean']:.2f}, {c['consistent_experiments']} of "
                  f"{c['experiments']} experiments consistent, {c['verdict']}")
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
