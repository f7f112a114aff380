#!/usr/bin/python3
"""Find what your odometry model is missing, step by step: run `odomcov diagnose` on a suite,
add the effect it names to the model, and repeat until nothing more is found; then compare the
final model with the runs and fit all the effects found together.

    repeat: odomcov diagnose SUITE, and adopt its model (the named effect added and every
            effect refitted, each on the part of the likelihood it explains)
    until it names nothing (or --rounds rounds);
    then:   odomcov compare SUITE                        (the model the loop built)
            odomcov fit SUITE --params <all named>       (one joint fit on the full likelihood)
            odomcov compare SUITE-with-the-joint-fit

The two final models differ when a random effect, sized by the full likelihood, also absorbs
mean errors that vary from experiment to experiment; diagnose sizes it by the spread within
experiments only. A big difference means such variation is in the data and no catalogue effect
is its cause.

The suite is copied to OUT/suite.yaml (relative CSV paths made absolute) and edited there; the
original is not touched. Each round's `diagnose` JSON is kept (OUT/diagnose-N.json); the joint
fit's suite is OUT/suite-fit.yaml. The table of rounds goes to stdout as Markdown and everything
to OUT/loop.json.

With --holdout, a second suite of other runs (not used by the loop) is compared with the model
as it was, with the model the loop built and with the joint fit (OUT/holdout.yaml): does what
was learnt on some runs predict the others?

Usage:
  diagnose_loop.py --odomcov BIN SUITE.yaml --out DIR [--rounds N] [--holdout SUITE.yaml]
"""
import argparse
import json
import os
import re
import subprocess
import sys

NOISE_LEVEL = "wheel_noise_level"
# The parameters `fit` refines for each named effect. Bumps fit their rate only: sigma is fixed
# by the tails (the fourth cumulant) when diagnose names them.
FIT_PARAMS = {
    "wheel_diameter_ratio": ["wheel_diameter_ratio.Ed"],
    "wheelbase_error": ["wheelbase_error.Eb"],
    "scale_error": ["scale_error.Es"],
    "wheel_noise_correlation": ["wheel_noise_correlation.rho"],
    "turn_slip": ["turn_slip.k"],
    "per_run_radius": ["per_run_radius.sigma"],
    "bumps": ["bumps.rate"],
    NOISE_LEVEL: ["k_left", "k_right"],
}


def run(cmd):
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({done.returncode}): {done.stderr.strip()}")
    return done.stdout


def copy_suite(suite, to):
    """Copies a suite elsewhere, making its relative CSV paths absolute."""
    base = os.path.dirname(os.path.abspath(suite))
    with open(suite) as f:
        text = f.read()
    # plain or quoted (the suite writer quotes file names) relative paths
    text = re.sub(r"(?<=[\s\[,])([\"']?)(?!/)([^\s,\[\]{}'\"]+\.csv)\1(?=[\s,\]]|$)",
                  lambda m: m.group(1) + os.path.join(base, m.group(2)) + m.group(1), text)
    with open(to, "w") as f:
        f.write(text)


def _model_span(lines):
    """Indices of the robot line and of the model block [start, end) (None, None if absent)."""
    robot = next(i for i, line in enumerate(lines) if line.startswith("robot:"))
    start = next((i for i, line in enumerate(lines) if line.startswith("model:")), None)
    end = start
    if start is not None:
        end = start + 1
        while end < len(lines) and (lines[end].startswith(" ") or not lines[end].strip()):
            end += 1
    return robot, start, end


def model_of(suite):
    """The robot line and model block of a suite, as the YAML `diagnose` and `fit` write."""
    with open(suite) as f:
        lines = f.read().splitlines()
    robot, start, end = _model_span(lines)
    return "\n".join([lines[robot]] + (lines[start:end] if start is not None else [])) + "\n"


def set_model(suite, yaml_text):
    """Replaces the suite's robot line and model block with `yaml_text` (a robot line, then
    optionally a model block)."""
    with open(suite) as f:
        lines = f.read().splitlines()
    robot, start, end = _model_span(lines)
    if start is not None:
        del lines[start:end]
    new = yaml_text.rstrip("\n").splitlines()
    lines[robot] = new[0]
    at = next(i for i, line in enumerate(lines) if line.startswith("experiments:"))
    lines[at:at] = new[1:]
    with open(suite, "w") as f:
        f.write("\n".join(lines) + "\n")


def compare(odomcov, suite, report):
    """`odomcov compare` in brief: log-likelihood, pooled NEES, experiments consistent."""
    run([odomcov, "compare", suite, "--json", report])
    with open(report) as f:
        c = json.load(f)
    runs = sum(e["n"] for e in c["experiments"])
    return {"log_likelihood": c["log_likelihood"],
            "nees_mean": sum(e["nees_mean"] * e["n"] for e in c["experiments"]) / runs,
            "verdict": c["verdict"], "experiments": len(c["experiments"]),
            "consistent_experiments": sum(e["verdict"] == "consistent" for e in c["experiments"])}


def loop(odomcov, suite, out, rounds):
    """Runs the loop on a copy of `suite` in `out`. Returns a report: the rounds, `compare`
    before, with the loop's model and with the joint fit, and the fit itself."""
    os.makedirs(out, exist_ok=True)
    work = os.path.join(out, "suite.yaml")
    copy_suite(suite, work)
    report = {"suite": suite, "compare_before": compare(odomcov, work, os.path.join(out, "compare-before.json")),
              "rounds": [], "fit": None, "compare_fit": None,
              "compare_rounds": [os.path.join(out, "compare-before.json")]}
    named = []
    for round_ in range(rounds):
        path = os.path.join(out, f"diagnose-{round_}.json")
        progress(f"diagnose loop: round {round_ + 1} of at most {rounds} "
                 f"({len(named)} named so far{': ' + ', '.join(named) if named else ''})")
        run([odomcov, "diagnose", work, "--json", path])
        with open(path) as f:
            d = json.load(f)
        report["explained"] = d.get("explained")
        report["alpha"] = d.get("alpha", 0.01)
        report["odometry_correction"] = d.get("odometry_correction")
        report["residuals"] = d.get("residuals")
        if d["best"] is None:
            report["rounds"].append({"round": round_, "named": None, "before": d["before"],
                                     "explained": d.get("explained")})
            break
        best = d["best"]["effect"]
        candidate = next(c for c in d["candidates"] if c["effect"] == best)
        report["rounds"].append({
            "round": round_, "named": best, "parameters": d["best"]["parameters"],
            "stderr": candidate["stderr"], "p_value": candidate["p_value"],
            "delta_log_likelihood": candidate["delta_log_likelihood"],
            "likelihood": candidate["likelihood"], "before": d["before"], "after": d["after"],
            "explanation": candidate["explanation"], "explained": d.get("explained")})
        named.append(best)
        set_model(work, d["after"]["yaml"])
        # The compare of each round's model, for scripts/plot_loop.py.
        path = os.path.join(out, f"compare-round-{round_ + 1}.json")
        compare(odomcov, work, path)
        report["compare_rounds"].append(path)
    progress("diagnose loop: compare and the joint fit")
    report["compare_after"] = compare(odomcov, work, os.path.join(out, "compare-after.json"))
    if named:
        path = os.path.join(out, "fit.json")
        params = [p for n in named for p in FIT_PARAMS[n]]
        run([odomcov, "fit", work, "--params", ",".join(params), "--json", path])
        with open(path) as f:
            report["fit"] = json.load(f)
        fitted = os.path.join(out, "suite-fit.yaml")
        copy_suite(work, fitted)
        set_model(fitted, report["fit"]["yaml"])
        report["compare_fit"] = compare(odomcov, fitted, os.path.join(out, "compare-fit.json"))
    progress("")
    return report


def _yes_no(flag):
    return "" if flag is None else ("yes" if flag else "no")


def progress(text):
    """One line of per-round progress on stderr when it is a terminal."""
    if sys.stderr.isatty():
        print(f"\r\033[K{text}", end="", file=sys.stderr, flush=True)


def summary(c):
    return (f"log-likelihood {c['log_likelihood']:.1f}, NEES mean {c['nees_mean']:.2f}, "
            f"{c['consistent_experiments']} of {c['experiments']} experiments consistent, "
            f"{c['verdict']}")


def verdict_lines(report, top=3):
    """The loop's honest ending: explained or not, and what the misfit lines up with."""
    if report.get("explained") is None:
        return []
    if report["explained"]:
        return ["- Verdict: **explained**: the final model is consistent with the data."]
    lines = ["- Verdict: **not explained**: the final model is still inconsistent with the data."]
    testable = [r for r in report.get("residuals") or [] if r.get("p_value") is not None]
    alpha = report.get("alpha", 0.01)
    aligned = [r for r in testable if r["p_value"] < alpha][:top]
    if aligned:
        lines.append("  The remaining misfit lines up with (p family-wise over the features):")
    elif testable:
        lines.append("  The remaining misfit lines up with no path feature at alpha; the closest:")
        aligned = testable[:1]
    for r in aligned:
        lines.append(f"  - {r['feature']}: p = {r['p_value']:.2g}: {r['description']}")
    return lines


def correction_lines(report):
    """The odometry corrected by the named systematic effects, UMBmark-style."""
    c = report.get("odometry_correction")
    if not c:
        return []
    lines = [f"- Corrected odometry: wheelbase {c['wheelbase']:.6g} m, wheel scales left "
             f"{c['scale_left']:.6g}, right {c['scale_right']:.6g}. End-pose x-y error with the "
             "runs re-integrated, before → after:",
             "",
             "| kind | runs | mean \\|xy\\| [mm] | Emax,sys [mm] |",
             "|---|---|---|---|"]
    for k in c["by_kind"]:
        lines.append(f"| {k['kind']} | {k['runs']} | {1e3 * k['mean_xy_before']:.1f} → "
                     f"{1e3 * k['mean_xy_after']:.1f} | {1e3 * k['emax_sys_before']:.1f} → "
                     f"{1e3 * k['emax_sys_after']:.1f} |")
    return lines


def markdown(report):
    rows = ["| round | named | size (all effects refitted) | p-value | log-likelihood | NEES mean | verdict | explained |",
            "|---|---|---|---|---|---|---|---|"]
    first = report["compare_before"]
    rows.append(f"| 0 | (the suite's model) | | | {first['log_likelihood']:.1f} | "
                f"{first['nees_mean']:.2f} | {first['verdict']} | |")
    for s in report["rounds"]:
        if s["named"] is None:
            rows.append(f"| {s['round'] + 1} | nothing significant | | | | | | "
                        f"{_yes_no(s.get('explained'))} |")
            continue
        values = ", ".join(f"{k} = {v:.5g}" for k, v in s["parameters"].items())
        a = s["after"]
        rows.append(f"| {s['round'] + 1} | {s['named']} | {values} | {s['p_value']:.2g} | "
                    f"{a['log_likelihood']:.1f} | {a['nees_mean']:.2f} | {a['verdict']} | "
                    f"{_yes_no(s.get('explained'))} |")
    rows.append("")
    rows.append(f"- `compare` with the loop's model: {summary(report['compare_after'])}.")
    fit = report["fit"]
    if fit:
        values = ", ".join(f"{k} = {v:.6g} ± {fit['stderr'][k]:.2g}"
                           for k, v in fit["parameters"].items())
        rows.append(f"- Joint fit of everything named, full likelihood: {values}.")
        rows.append(f"- `compare` with the joint fit: {summary(report['compare_fit'])}.")
    rows.extend(verdict_lines(report))
    rows.extend(correction_lines(report))
    held = report.get("holdout")
    if held:
        rows.append(f"- Held-out runs ({held['suite']}) with the suite's original model: "
                    f"{summary(held['compare_before'])}.")
        rows.append(f"- Held-out runs with the loop's model: {summary(held['compare_after'])}.")
        if "compare_fit" in held:
            rows.append(f"- Held-out runs with the joint fit: {summary(held['compare_fit'])}.")
    return "\n".join(rows)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--odomcov", required=True, metavar="BIN",
                        help="the odomcov program, e.g. build/src/cli/odomcov")
    parser.add_argument("suite", help="measurement suite (suite.yaml); it is copied, never changed")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="folder for the edited suite, each round's diagnose JSON and loop.json")
    parser.add_argument("--rounds", type=int, default=8,
                        help="stop after adding this many effects (default: 8)")
    parser.add_argument("--holdout", metavar="SUITE",
                        help="a suite of other runs: compare it with the original model and "
                             "with the model the loop built")
    args = parser.parse_args()
    report = loop(args.odomcov, args.suite, args.out, args.rounds)
    if args.holdout:
        held = os.path.join(args.out, "holdout.yaml")
        copy_suite(args.holdout, held)
        report["holdout"] = {"suite": args.holdout, "compare_before": compare(
            args.odomcov, held, os.path.join(args.out, "holdout-before.json"))}
        for key, source in (("compare_after", "suite.yaml"), ("compare_fit", "suite-fit.yaml")):
            if os.path.exists(os.path.join(args.out, source)):
                set_model(held, model_of(os.path.join(args.out, source)))
                report["holdout"][key] = compare(args.odomcov, held,
                                                 os.path.join(args.out, f"holdout-{key}.json"))
    with open(os.path.join(args.out, "loop.json"), "w") as f:
        json.dump(report, f, indent=1)
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
