#!/usr/bin/python3
"""One table across several scripts/diagnose_loop.py runs (e.g. the OptiOdom splits): per run,
the effects named with the joint fit's sizes and standard errors, the NEES per path type
in-sample and on the held-out runs, the heading bias per path type, and the verdict.

Usage: loop_summary.py NAME=LOOP.json [NAME=LOOP.json ...] > summary.md
"""
import json
import sys

from diagnose_loop import plus_minus


def model(report):
    """The final model's compare summary: the joint fit's, else the loop's."""
    return report.get("compare_fit") or report["compare_after"]


def held_model(report):
    held = report.get("holdout")
    return (held.get("compare_fit") or held.get("compare_after")) if held else None


def sizes(report):
    fit = report.get("fit")
    identified = fit and any(se is not None for se in fit["stderr"].values())
    if not identified:  # no joint fit, or one the data cannot pin down: as diagnose sized each
        if not any(s["named"] for s in report["rounds"]):
            return "nothing"
        why = "no joint fit" if not fit else "the joint fit is not identified (" + \
            "; ".join(fit.get("warnings", [])) + ")"
        return "; ".join(", ".join(f"{s['named']}.{k} = {plus_minus(v, s['stderr'][k], 5)}"
                                   for k, v in s["parameters"].items())
                         for s in report["rounds"] if s["named"]) + f" ({why}: as diagnose named them)"
    return ", ".join(f"{k} = {plus_minus(v, fit['stderr'][k], 5)}" for k, v in fit["parameters"].items())


def cells(summary, types, field):
    out = []
    for t in types:
        v = summary["by_type"].get(t) if summary else None
        if v is None:
            out.append("")
        elif field == "nees":
            out.append(f"{v['nees']:.2f}")
        else:
            signed = v.get("heading_z_signed_mean")
            out.append(("" if signed is None else f"{signed:+.1f} ") + f"({v['heading_z_rms']:.1f})")
    return out


def main():
    runs = []
    for arg in sys.argv[1:]:
        name, _, path = arg.partition("=")
        with open(path) as f:
            runs.append((name, json.load(f)))
    types = sorted({t for _, r in runs for c in (model(r), held_model(r)) if c for t in c["by_type"]})
    print("## Effects named (joint fit of everything named, full likelihood, ± standard error)\n")
    print("| split | named, in order | sizes |")
    print("|---|---|---|")
    for name, r in runs:
        named = " → ".join(s["named"] for s in r["rounds"] if s["named"]) or "nothing"
        print(f"| {name} | {named} | {sizes(r)} |")
    for title, field in (("NEES per run by path type, final model (3 is right)", "nees"),
                         ("Heading-mean misfit by path type, final model, in standard errors: "
                          "mean signed by the turn sense (RMS)", "heading")):
        print(f"\n## {title}\n")
        print("| split | runs | " + " | ".join(types) + (" | pooled | experiments consistent |"
                                                         if field == "nees" else " |"))
        print("|---|---|" + "---|" * (len(types) + (2 if field == "nees" else 0)))
        for name, r in runs:
            for label, c in (("in-sample", model(r)), ("held-out", held_model(r))):
                if not c:
                    continue
                extra = (f" | {c['nees_mean']:.2f} | {c['consistent_experiments']} of "
                         f"{c['experiments']}" if field == "nees" else "")
                print(f"| {name} | {label} | " + " | ".join(cells(c, types, field)) + extra + " |")
    print("\n## Verdict of the last diagnose round (in-sample)\n")
    for name, r in runs:
        top = [f"{x['feature']}{', ' + x['part'] if x.get('part') else ''} (p = {x['p_value']:.2g})" for x in r.get("residuals") or []
               if x.get("p_value") is not None and x["p_value"] < r.get("alpha", 0.01)][:3]
        verdict = "explained" if r.get("explained") else "not explained"
        print(f"- {name}: {verdict}" + (f"; the misfit lines up with {', '.join(top)}" if top else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
