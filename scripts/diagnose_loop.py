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
was learnt on some runs predict the others? With --train REGEX (and optionally --test REGEX) one
suite is split instead: the loop runs on the experiments whose names match --train, and its
models are judged on those matching --test (default: every other experiment). E.g. the path-type
hold-out of OptiOdom is --train '^(square|ivanjko)-' --test '^(circular|free)-', a campaign
hold-out --train '^[a-z]+-2312' --test '^[a-z]+-(2306|2506)'.

Every compare is also summarised per path type, the experiment name's prefix before the first
'-' (square-..., circular-...): the pooled NEES per run (3 when the model is right), and the
within-experiment NEES, the scatter of the runs about their own experiment's mean against the
predicted covariance (3 when the predicted spread is right whatever the mean misfit; well below
3 means the model's random noise is larger than the runs' own scatter supports).

Usage:
  diagnose_loop.py --odomcov BIN SUITE.yaml --out DIR [--rounds N] [--order 1|2]
                   [--candidates FILE.yaml] [--holdout SUITE.yaml | --train REGEX [--test REGEX]]
  diagnose_loop.py --odomcov BIN SUITE.yaml --out DIR --render   (the report again, no odomcov run)
"""
import argparse
import json
import math
import os
import re
import shutil
import sys

import numpy

from suite_tools import _model_span, copy_suite, run  # noqa: F401 (re-exported to the study scripts)

NOISE_LEVEL = "wheel_noise_level"
# The parameters `fit` refines for an effect whose name does not prefix them (effect.param, the
# default for every other effect, the second catalogue's and custom ones included). Bumps fit
# their rate only: sigma is fixed by the tails (the fourth cumulant) when diagnose names them.
FIT_PARAMS = {
    "bumps": ["bumps.rate"],
    NOISE_LEVEL: ["k_left", "k_right"],
}


def fit_params(effect, parameters):
    """The `fit --params` names of a named effect with these parameters."""
    if effect.startswith("group_variation("):  # its sd, and the varied parameter when it was new
        return [p if "." in p else f"group_variation.{p}" for p in parameters]
    return FIT_PARAMS.get(effect, [f"{effect}.{p}" for p in parameters])


def path_type(name):
    """An experiment's path type: its name's prefix before the first '-'."""
    return name.split("-", 1)[0]


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


def _within(e):
    """(sum over runs of (e_i - mean)' P^-1 (e_i - mean), its degrees of freedom 3 (n - 1)):
    the runs' scatter about their own mean against the predicted covariance P."""
    errors = numpy.array(e["errors"], dtype=float)
    if len(errors) < 2:
        return 0.0, 0
    d = errors - errors.mean(axis=0)
    cov = numpy.array(e["predicted"]["cov"], dtype=float)
    try:
        q = numpy.linalg.solve(cov, d.T)
    except numpy.linalg.LinAlgError:
        return 0.0, 0
    return float((d.T * q).sum()), 3 * (len(errors) - 1)


def heading_z(e):
    """The experiment's heading-mean misfit in standard errors of its mean, (measured -
    predicted) / sqrt(P_theta,theta / n), and the turn sense its name ends with (+1 '-ccw',
    -1 '-cw', else 0)."""
    var = e["predicted"]["cov"][2][2] / e["n"]
    z = (e["measured"]["mean"][2] - e["predicted"]["mean"][2]) / math.sqrt(var) if var > 0 else 0.0
    sense = 1 if e["name"].endswith("-ccw") else -1 if e["name"].endswith("-cw") else 0
    return z, sense


def by_type(experiments):
    """Per path type: runs, experiments, consistent ones, the pooled NEES per run, the
    within-experiment NEES (3 when the predicted spread matches the runs' own scatter), and the
    heading-mean misfits in standard errors: their RMS (1 when the model is right) and their mean
    signed by the turn sense (0 when no heading bias is left)."""
    out = {}
    for e in experiments:
        t = out.setdefault(path_type(e["name"]), {"runs": 0, "experiments": 0, "consistent": 0,
                                                 "nees": 0.0, "_within": 0.0, "_dof": 0,
                                                 "_z": [], "_signed": []})
        t["runs"] += e["n"]
        t["experiments"] += 1
        t["consistent"] += e["verdict"] == "consistent"
        t["nees"] += e["nees_mean"] * e["n"]
        q, dof = _within(e)
        t["_within"] += q
        t["_dof"] += dof
        z, sense = heading_z(e)
        t["_z"].append(z)
        if sense:
            t["_signed"].append(z * sense)
    for t in out.values():
        t["nees"] /= t["runs"]
        t["nees_within"] = 3 * t.pop("_within") / t["_dof"] if t["_dof"] else None
        t.pop("_dof")
        z, signed = t.pop("_z"), t.pop("_signed")
        t["heading_z_rms"] = math.sqrt(sum(v * v for v in z) / len(z))
        t["heading_z_signed_mean"] = sum(signed) / len(signed) if signed else None
    return dict(sorted(out.items()))


def compare(odomcov, suite, report, order=None):
    """`odomcov compare` in brief (summarise)."""
    run([odomcov, "compare", suite, "--json", report] + order_args(order))
    return summarise(report)


def summarise(report):
    """A compare JSON in brief: log-likelihood, pooled NEES, experiments consistent, and the
    same per path type."""
    with open(report) as f:
        c = json.load(f)
    runs = sum(e["n"] for e in c["experiments"])
    within = [_within(e) for e in c["experiments"]]
    within_dof = sum(dof for _, dof in within)
    return {"log_likelihood": c["log_likelihood"],
            "nees_mean": sum(e["nees_mean"] * e["n"] for e in c["experiments"]) / runs,
            "nees_within": 3 * sum(q for q, _ in within) / within_dof if within_dof else None,
            "verdict": c["verdict"], "experiments": len(c["experiments"]),
            "consistent_experiments": sum(e["verdict"] == "consistent" for e in c["experiments"]),
            "by_type": by_type(c["experiments"])}


def _candidates(d):
    """Every candidate of a diagnose round in brief, best first."""
    return [{k: c.get(k) for k in ("effect", "parameters", "stderr", "delta_log_likelihood",
                                   "likelihood", "p_value")} for c in d["candidates"]]


def _round_of(round_, d):
    """One round's entry of the report from its diagnose JSON."""
    entry = _round_fields(round_, d)
    entry["candidates"] = _candidates(d)
    return entry


def _round_fields(round_, d):
    if d["best"] is None:
        return {"round": round_, "named": None, "before": d["before"], "explained": d.get("explained")}
    best = d["best"]["effect"]
    candidate = next(c for c in d["candidates"] if c["effect"] == best)
    return {"round": round_, "named": best, "parameters": d["best"]["parameters"],
            "stderr": candidate["stderr"], "p_value": candidate["p_value"],
            "delta_log_likelihood": candidate["delta_log_likelihood"],
            "likelihood": candidate.get("likelihood"), "before": d["before"], "after": d["after"],
            "explanation": candidate.get("explanation"), "explained": d.get("explained")}


def _verdict_of(report, d):
    report["explained"] = d.get("explained")
    report["alpha"] = d.get("alpha", 0.01)
    report["odometry_correction"] = d.get("odometry_correction")
    report["residuals"] = d.get("residuals")


def rebuild(out):
    """The report of a loop from the files it left in `out`, also of one that was stopped
    before it ended (its loop.json is written last): the rounds done so far."""
    report = {"suite": os.path.join(out, "suite.yaml"), "rounds": [], "fit": None,
              "compare_rounds": [os.path.join(out, "compare-before.json")], "partial": True}
    round_ = 0
    while os.path.exists(os.path.join(out, f"diagnose-{round_}.json")):
        with open(os.path.join(out, f"diagnose-{round_}.json")) as f:
            d = json.load(f)
        _verdict_of(report, d)
        report["rounds"].append(_round_of(round_, d))
        compared = os.path.join(out, f"compare-round-{round_ + 1}.json")
        if d["best"] is not None and os.path.exists(compared):
            report["compare_rounds"].append(compared)
        round_ += 1
    if os.path.exists(os.path.join(out, "fit.json")):
        with open(os.path.join(out, "fit.json")) as f:
            report["fit"] = json.load(f)
    if not os.path.exists(os.path.join(out, "compare-after.json")):
        shutil.copy(report["compare_rounds"][-1], os.path.join(out, "compare-after.json"))
    return report


def resummarise(report, out):
    """Re-reads every compare JSON a finished loop left in `out` (after this script's summary
    changed: no odomcov run)."""
    def again(name):
        path = os.path.join(out, name)
        return summarise(path) if os.path.exists(path) else None
    report["compare_before"] = again("compare-before.json")
    report["compare_after"] = again("compare-after.json")
    report["compare_fit"] = again("compare-fit.json")
    for s in report["rounds"]:
        if s["named"]:
            s["compare"] = again(f"compare-round-{s['round'] + 1}.json")
        path = os.path.join(out, f"diagnose-{s['round']}.json")
        if os.path.exists(path):
            with open(path) as f:
                s["candidates"] = _candidates(json.load(f))
    held = report.get("holdout")
    if held:
        for key in ("compare_after", "compare_fit"):
            if again(f"holdout-{key}.json"):
                held[key] = again(f"holdout-{key}.json")
        held["compare_before"] = again("holdout-before.json")
    return report


def order_args(order):
    return ["--order", str(order)] if order else []


def diagnose_args(candidates, order):
    """Extra `diagnose` options: --candidates FILE (user hypotheses ranked beside the catalogue)
    only when given, so the loop runs with any odomcov; and the model order."""
    return (["--candidates", candidates] if candidates else []) + order_args(order)


def loop(odomcov, suite, out, rounds, candidates=None, order=None):
    """Runs the loop on a copy of `suite` in `out`. Returns a report: the rounds, `compare`
    before, with the loop's model and with the joint fit, and the fit itself."""
    os.makedirs(out, exist_ok=True)
    work = os.path.join(out, "suite.yaml")
    copy_suite(suite, work)
    report = {"suite": suite, "order": order, "candidates": candidates,
              "compare_before": compare(odomcov, work, os.path.join(out, "compare-before.json"), order),
              "rounds": [], "fit": None, "compare_fit": None,
              "compare_rounds": [os.path.join(out, "compare-before.json")]}
    named = []
    for round_ in range(rounds):
        path = os.path.join(out, f"diagnose-{round_}.json")
        progress(f"diagnose loop: round {round_ + 1} of at most {rounds} "
                 f"({len(named)} named so far{': ' + ', '.join(n for n, _ in named) if named else ''})")
        run([odomcov, "diagnose", work, "--json", path] + diagnose_args(candidates, order))
        with open(path) as f:
            d = json.load(f)
        _verdict_of(report, d)
        report["rounds"].append(_round_of(round_, d))
        if d["best"] is None:
            break
        best = d["best"]["effect"]
        named.append((best, list(d["best"]["parameters"])))
        set_model(work, d["after"]["yaml"])
        # The compare of each round's model, for scripts/plot_loop.py.
        path = os.path.join(out, f"compare-round-{round_ + 1}.json")
        report["rounds"][-1]["compare"] = compare(odomcov, work, path, order)
        report["compare_rounds"].append(path)
    progress("diagnose loop: compare and the joint fit")
    report["compare_after"] = compare(odomcov, work, os.path.join(out, "compare-after.json"), order)
    if named:
        path = os.path.join(out, "fit.json")
        params = [p for effect, names in named for p in fit_params(effect, names)]
        try:
            run([odomcov, "fit", work, "--params", ",".join(params), "--json", path]
                + order_args(order))
        except RuntimeError as e:  # reported, not fatal: the loop's own model stands
            report["fit_error"] = str(e)
        else:
            with open(path) as f:
                report["fit"] = json.load(f)
            fitted = os.path.join(out, "suite-fit.yaml")
            copy_suite(work, fitted)
            set_model(fitted, report["fit"]["yaml"])
            report["compare_fit"] = compare(odomcov, fitted, os.path.join(out, "compare-fit.json"),
                                            order)
    progress("")
    return report


def plus_minus(value, stderr, digits=6):
    """value ± its standard error, or "(not identified)" when the fit has none (a singular
    information matrix: two effects the data cannot tell apart)."""
    return f"{value:.{digits}g} ± " + (f"{stderr:.2g}" if stderr is not None else "(not identified)")


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
        lines.append("  The remaining misfit lines up with (mean: the experiments' mean errors; scatter: "
                     "their spread; p family-wise over the features and parts):")
    elif testable:
        lines.append("  The remaining misfit lines up with no path feature at alpha; the closest:")
        aligned = testable[:1]
    for r in aligned:
        part = f", {r['part']}" if r.get("part") else ""
        lines.append(f"  - {r['feature']}{part}: p = {r['p_value']:.2g}: {r['description']}")
    return lines


def correction_lines(report):
    """The odometry corrected by the named systematic effects, UMBmark-style."""
    c = report.get("odometry_correction")
    if not c:
        return []
    varies = c.get("motion_dependent", False)
    head = ("- Corrected odometry: it depends on the motion, so each kind of path has its own "
            f"effective wheelbase and wheel scales (over all runs: wheelbase {c['wheelbase']:.6g} m"
            if varies else f"- Corrected odometry: wheelbase {c['wheelbase']:.6g} m")
    head += (f", wheel scales left {c['scale_left']:.6g}, right {c['scale_right']:.6g}"
             + (")" if varies else "") + ". End-pose x-y error with the runs re-integrated, "
             "before → after:")
    extra = " wheelbase [m] | scale left | scale right |" if varies else ""
    lines = [head, "",
             "| kind | runs | mean \\|xy\\| [mm] | Emax,sys [mm] |" + extra,
             "|---|---|---|---|" + ("---|---|---|" if varies else "")]
    for k in c["by_kind"]:
        row = (f"| {k['kind']} | {k['runs']} | {1e3 * k['mean_xy_before']:.1f} → "
               f"{1e3 * k['mean_xy_after']:.1f} | {1e3 * k['emax_sys_before']:.1f} → "
               f"{1e3 * k['emax_sys_after']:.1f} |")
        if varies:
            row += f" {k['wheelbase']:.6g} | {k['scale_left']:.6g} | {k['scale_right']:.6g} |"
        lines.append(row)
    return lines


def _nees_cell(t):
    if t is None:
        return ""
    within = "" if t.get("nees_within") is None else f" ({t['nees_within']:.2f})"
    return f"{t['nees']:.2f}{within}"


def _heading_cell(t):
    if t is None:
        return ""
    signed = t.get("heading_z_signed_mean")
    return ("" if signed is None else f"{signed:+.2f} ") + f"({t['heading_z_rms']:.2f})"


def type_table(rows_in, heading=False):
    """A Markdown table per path type: rows_in is [(label, compare summary)]. Each cell is the
    pooled NEES per run with the within-experiment NEES in brackets; with heading=True, the
    heading-mean misfit in standard errors, mean signed by the turn sense, RMS in brackets."""
    types = sorted({t for _, c in rows_in if c for t in c["by_type"]})
    rows = ["| model | " + " | ".join(types) + (" |" if heading else " | pooled |"),
            "|---|" + "---|" * (len(types) + (0 if heading else 1))]
    cell = _heading_cell if heading else _nees_cell
    for label, c in rows_in:
        if not c:
            continue
        pooled = "" if heading else \
            f" {_nees_cell({'nees': c['nees_mean'], 'nees_within': c.get('nees_within')})} |"
        rows.append(f"| {label} | " + " | ".join(cell(c["by_type"].get(t)) for t in types)
                    + " |" + pooled)
    return rows


HEADING_NOTE = ("Heading-mean misfit per path type, in standard errors of each experiment's mean: "
                "mean signed by the turn sense (0 when no heading bias is left), RMS in brackets "
                "(1 when the model is right):")


def _round_rows(report):
    rows = [("suite's model", report["compare_before"])]
    rows += [(f"round {s['round'] + 1}: + {s['named']}", s.get("compare"))
             for s in report["rounds"] if s["named"]]
    if report.get("compare_fit"):
        rows.append(("joint fit", report["compare_fit"]))
    return rows


def holdout_lines(held):
    rows = [f"- Held-out runs ({held['suite']}) with the suite's original model: "
            f"{summary(held['compare_before'])}.",
            f"- Held-out runs with the loop's model: {summary(held['compare_after'])}."]
    if "compare_fit" in held:
        rows.append(f"- Held-out runs with the joint fit: {summary(held['compare_fit'])}.")
    rows += ["", "NEES per run by path type on the held-out runs (within-experiment NEES in brackets):",
             ""]
    models = [("suite's model", held["compare_before"]), ("loop's model", held["compare_after"]),
              ("joint fit", held.get("compare_fit"))]
    rows += type_table(models)
    rows += ["", HEADING_NOTE, ""]
    rows += type_table(models, heading=True)
    return rows


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
        values = ", ".join(f"{k} = {plus_minus(v, fit['stderr'][k])}"
                           for k, v in fit["parameters"].items())
        rows.append(f"- Joint fit of everything named, full likelihood: {values}.")
        rows.extend(f"- The joint fit warns: {w}." for w in fit.get("warnings", []))
        rows.append(f"- `compare` with the joint fit: {summary(report['compare_fit'])}.")
    elif report.get("fit_error"):
        rows.append(f"- The joint fit failed: {report['fit_error']}")
    rows += ["", "NEES per run by path type, in-sample (within-experiment NEES in brackets; 3 is right):",
             ""]
    rows += type_table(_round_rows(report))
    rows += ["", HEADING_NOTE, ""]
    rows += type_table(_round_rows(report), heading=True)
    rows.append("")
    held = report.get("holdout")
    if held:
        rows.extend(holdout_lines(held))
        rows.append("")
    rows.extend(verdict_lines(report))
    rows.extend(correction_lines(report))
    if report.get("partial"):
        rows += ["", f"(Stopped before its end: the {len(report['rounds'])} rounds done; no joint "
                 "fit unless it was reached; held-out runs judged with the model as far as it got.)"]
    return "\n".join(rows)


def split_suite(suite, to, pattern, keep):
    """Copies the experiments of `suite` whose names match `pattern` (keep=True) or do not
    (keep=False) to `to`, with everything else in the suite; relative CSV paths made absolute.
    Returns how many experiments it kept."""
    copy_suite(suite, to)
    with open(to) as f:
        lines = f.read().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("experiments:")) + 1
    end = next((i for i in range(start, len(lines)) if lines[i] and not lines[i][0].isspace()),
               len(lines))
    items, head = [], lines[:start]
    for line in lines[start:end]:
        if line.lstrip().startswith("- ") and (not items or _indent(line) <= _indent(items[-1][0])):
            items.append([line])
        elif items:
            items[-1].append(line)
    regex = re.compile(pattern)
    kept = [item for item in items if bool(regex.search(_name(item))) == keep]
    with open(to, "w") as f:
        f.write("\n".join(head + [line for item in kept for line in item] + lines[end:]) + "\n")
    return len(kept)


def _indent(line):
    return len(line) - len(line.lstrip())


def _name(item):
    """The name of one experiment entry (its lines)."""
    for line in item:
        m = re.match(r"\s*(?:- )?name:\s*[\"']?([^\"'#]*?)[\"']?\s*(?:#.*)?$", line)
        if m:
            return m.group(1)
    return ""


def judge_holdout(odomcov, held, out, order):
    """The held-out suite `held` (already in `out`) against the suite's model, the loop's and the
    joint fit's."""
    report = {"suite": held, "compare_before": compare(
        odomcov, held, os.path.join(out, "holdout-before.json"), order)}
    for key, source in (("compare_after", "suite.yaml"), ("compare_fit", "suite-fit.yaml")):
        if os.path.exists(os.path.join(out, source)):
            set_model(held, model_of(os.path.join(out, source)))
            report[key] = compare(odomcov, held, os.path.join(out, f"holdout-{key}.json"), order)
    return report


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--odomcov", required=True, metavar="BIN",
                        help="the odomcov program, e.g. build/src/cli/odomcov")
    parser.add_argument("suite", help="measurement suite (suite.yaml); it is copied, never changed")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="folder for the edited suite, each round's diagnose JSON and loop.json")
    parser.add_argument("--rounds", type=int, default=8,
                        help="stop after adding this many effects (default: 8)")
    parser.add_argument("--order", type=int, choices=[1, 2],
                        help="model order for diagnose, compare and fit (default: odomcov's)")
    parser.add_argument("--candidates", metavar="FILE",
                        help="custom hypotheses (YAML) that diagnose ranks beside the catalogue")
    held = parser.add_mutually_exclusive_group()
    held.add_argument("--holdout", metavar="SUITE",
                      help="a suite of other runs: compare it with the original model and "
                           "with the model the loop built")
    held.add_argument("--train", metavar="REGEX",
                      help="split SUITE: the loop runs on the experiments whose names match")
    parser.add_argument("--render", action="store_true",
                        help="re-read the compare JSONs of a loop in --out, rewrite its loop.json "
                             "and print its report again (no odomcov run for a finished loop; for "
                             "one stopped early, the rounds done and the held-out compares)")
    parser.add_argument("--test", metavar="REGEX",
                        help="with --train: judge on the experiments whose names match "
                             "(default: every experiment --train leaves out)")
    args = parser.parse_args()
    if args.test and not args.train:
        parser.error("--test needs --train")
    return args


def main():
    args = parse_args()
    if args.render:
        path = os.path.join(args.out, "loop.json")
        if os.path.exists(path):
            with open(path) as f:
                report = json.load(f)
        else:
            report = rebuild(args.out)
            held = os.path.join(args.out, "holdout.yaml")
            if os.path.exists(held):  # judged with the model as far as the loop got
                report["holdout"] = judge_holdout(args.odomcov, held, args.out, args.order)
                report["holdout"]["suite"] = held
        report = resummarise(report, args.out)
        with open(os.path.join(args.out, "loop.json"), "w") as f:
            json.dump(report, f, indent=1)
        print(markdown(report))
        return 0
    os.makedirs(args.out, exist_ok=True)
    suite, held = args.suite, None
    if args.train:
        suite = os.path.join(args.out, "train-source.yaml")
        held = os.path.join(args.out, "holdout.yaml")
        if split_suite(args.suite, suite, args.train, True) == 0:
            sys.exit(f"diagnose_loop.py: --train {args.train!r} matches no experiment of {args.suite}")
        test = (split_suite(args.suite, held, args.test, True) if args.test
                else split_suite(args.suite, held, args.train, False))
        if test == 0:
            sys.exit(f"diagnose_loop.py: no experiment of {args.suite} is left to test on")
    elif args.holdout:
        held = os.path.join(args.out, "holdout.yaml")
        copy_suite(args.holdout, held)
    report = loop(args.odomcov, suite, args.out, args.rounds, args.candidates, args.order)
    if args.train:
        report["split"] = {"suite": args.suite, "train": args.train, "test": args.test}
    if held:
        report["holdout"] = judge_holdout(args.odomcov, held, args.out, args.order)
        report["holdout"]["suite"] = args.holdout or f"{args.suite} ({args.test or 'not ' + args.train})"
    with open(os.path.join(args.out, "loop.json"), "w") as f:
        json.dump(report, f, indent=1)
    print(markdown(report))
    return 0


if __name__ == "__main__":
    sys.exit(main())
