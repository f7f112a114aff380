#!/usr/bin/python3
"""The OptiOdom loops' models with group_variation added (issue 10): the model each loop built,
plus a systematic parameter drawn once per group (`group:` of the imported suite), fitted on the
training runs (the group's sd and the varied parameter), then compared on the training runs and
on the held-out runs. A held-out group is predicted with the between-group spread.

Usage: optiodom_group.py --odomcov BIN --suite GROUPED_SUITE.yaml --out DIR
           NAME:LOOP_DIR:PARAMETER:TRAIN_REGEX[:TEST_REGEX] ...   > group.md
(TRAIN_REGEX '.' and no TEST_REGEX: in-sample on every run.)
"""
import argparse
import json
import os
import sys

from diagnose_loop import compare, model_of, run, set_model, split_suite, type_table


def one(odomcov, suite, out, name, loop_dir, parameter, train, test):
    os.makedirs(out, exist_ok=True)
    source = os.path.join(loop_dir, "suite-fit.yaml")
    if not os.path.exists(source):
        source = os.path.join(loop_dir, "suite.yaml")
    model = model_of(source).rstrip("\n") + f"\n    - group_variation: {{parameter: {parameter}, sd: 0.002}}\n"
    files = {"train": os.path.join(out, f"{name}-train.yaml")}
    split_suite(suite, files["train"], train, True)
    if test:
        files["test"] = os.path.join(out, f"{name}-test.yaml")
        split_suite(suite, files["test"], test, True)
    set_model(files["train"], model)
    fit_json = os.path.join(out, f"{name}-fit.json")
    run([odomcov, "fit", files["train"], "--params", f"group_variation.sd,{parameter}",
         "--order", "1", "--json", fit_json])
    with open(fit_json) as f:
        fit = json.load(f)
    result = {"name": name, "parameter": parameter, "fit": {k: (v, fit["stderr"][k])
                                                            for k, v in fit["parameters"].items()}}
    for key, path in files.items():
        set_model(path, fit["yaml"])
        result[key] = compare(odomcov, path, os.path.join(out, f"{name}-compare-{key}.json"), 1)
    return result


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--odomcov", required=True)
    parser.add_argument("--suite", required=True)
    parser.add_argument("--out", required=True)
    parser.add_argument("runs", nargs="+")
    args = parser.parse_args()
    results = []
    for spec in args.runs:
        name, loop_dir, parameter, train, *test = spec.split(":")
        results.append(one(args.odomcov, args.suite, args.out, name, loop_dir, parameter, train,
                           test[0] if test else None))
    with open(os.path.join(args.out, "group.json"), "w") as f:
        json.dump(results, f, indent=1)
    for r in results:
        sizes = ", ".join(f"{k} = {v:.5g} ± " + (f"{se:.2g}" if se is not None else "(none)")
                          for k, (v, se) in r["fit"].items())
        print(f"### {r['name']}: group_variation of {r['parameter']}\n\nFitted on the training runs: "
              f"{sizes}.\n")
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
