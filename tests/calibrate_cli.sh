#!/usr/bin/env bash
# odomcov calibrate end to end on the standard synthetic lab (a wheel diameter ratio and a
# wheelbase error hidden), as a user runs it:
#  1. calibrate on every experiment but the arcs, judged on the arcs (--train/--test): exit 0;
#     the three files in DIR; the report names both effects; calibrate.json has the keys of
#     docs/json.md ("calibrate") and the held-out block; model.yaml's model block has its
#     domain; diff_drive.yaml has the five diff_drive_controller parameters;
#  2. model.yaml pasted over the suite's robot line and model block: compare reads it and flags
#     exactly the held-out arcs as outside the training domain (their mean wheel speed, 0.25
#     m/s, is below the 0.3 m/s of every training run), as calibrate's holdout block does;
#  3. a second calibrate into the same DIR whose holdout is malformed: exit 2, DIR unchanged.
#   calibrate_cli.sh ODOMCOV SUITE_DIR WORK_DIR
set -u
bin=$1 lab=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
fail() { echo "FAIL: $*"; exit 1; }
"$bin" calibrate "$lab/suite.yaml" --out "$work/cal" --train '^(line|forward|spin|umbmark)-' --test '^arc-' \
  >"$work/report.txt" 2>"$work/err.txt" || fail "calibrate exited $? ($(cat "$work/err.txt"))"
for f in model.yaml calibrate.json diff_drive.yaml; do [ -s "$work/cal/$f" ] || fail "no $f"; done
grep -q "wheel_diameter_ratio" "$work/report.txt" || fail "report does not name wheel_diameter_ratio"
grep -q "wheelbase_error" "$work/report.txt" || fail "report does not name wheelbase_error"
grep -q "each run's marginal NEES (no run conditioned on another)" "$work/report.txt" || fail "report has no posterior prediction"
/usr/bin/python3 - "$work/cal" <<'PY' || fail "calibrate.json or diff_drive.yaml"
import json, sys
d = json.load(open(sys.argv[1] + "/calibrate.json"))
for key in ("rounds", "named", "explained", "candidates_cv", "confounded", "next_experiments", "holdout",
            "model", "diff_drive", "after", "joint_fit"):
    assert key in d, key
assert sorted(d["named"]) == ["wheel_diameter_ratio", "wheelbase_error"], d["named"]
assert d["explained"] is True, d["after"]
for c in d["candidates_cv"]:
    assert set(c) >= {"effect", "gain_in_sample", "gain_held_out", "verdict"}, c
assert set(d["holdout"]) >= {"nees_mean", "verdict", "by_kind", "extrapolation"}, d["holdout"]
assert list(d["holdout"]["by_kind"]) == ["arc"], d["holdout"]["by_kind"]
refit = d["holdout"]["refitted"]
assert list(refit["by_kind"]) == ["arc"] and refit["log_likelihood_after"] >= d["holdout"]["log_likelihood"] - 1e-6, refit
assert sorted(d["after"]["by_kind"]) == ["forward", "line", "spin", "umbmark"], d["after"]["by_kind"]
pred = d["holdout"]["predictive"]
for key in ("plugin_nees_mean", "plugin_by_kind", "sized_nees_mean", "sized_by_kind", "nees_mean", "by_kind"):
    assert key in pred, key
assert list(pred["sized_by_kind"]) == ["arc"], pred["sized_by_kind"]
for q in pred["parameters"]:
    assert set(q) == {"name", "prior_sd", "posterior_sd", "shift", "sized", "spread"} and q["spread"] >= 0.1, q
for n in d["next_experiments"]:
    assert set(n) >= {"name", "path", "runs", "expected_stderr"}, n
text = open(sys.argv[1] + "/diff_drive.yaml").read()
for key in ("wheel_separation_multiplier", "left_wheel_radius_multiplier", "right_wheel_radius_multiplier",
            "pose_covariance_diagonal", "twist_covariance_diagonal"):
    assert key + ":" in text, key
PY
grep -q "^  domain: {speed: \[" "$work/cal/model.yaml" || fail "model.yaml has no domain"
# 2. The calibrated model over the suite's own.
cp "$lab"/*.csv "$work/"
{ grep -v '^#' "$work/cal/model.yaml"; sed -n '/^measurement_noise:/p; /^experiments:/,$p' "$lab/suite.yaml"; } >"$work/calibrated.yaml"
grep -q '^name:' "$work/calibrated.yaml" || sed -i '1i name: calibrated' "$work/calibrated.yaml"
"$bin" compare "$work/calibrated.yaml" --json "$work/compare.json" >"$work/compare.txt" 2>"$work/err.txt"
code=$?
[ $code -eq 0 ] || fail "compare with model.yaml exited $code ($(cat "$work/err.txt"))"
/usr/bin/python3 -c "
import json, sys
d = json.load(open('$work/compare.json'))
c = json.load(open('$work/cal/calibrate.json'))
flagged = [e['name'] for e in d['experiments'] if e.get('extrapolation')]
assert flagged == ['arc-left', 'arc-right'], flagged
assert [x.split(':')[0] for x in c['holdout']['extrapolation']] == flagged, c['holdout']['extrapolation']
assert all('speed' in x for e in d['experiments'] for x in e['extrapolation']), d" || fail "extrapolation"
# 3. A malformed holdout: nothing written, DIR as it was.
before=$(cd "$work/cal" && md5sum * | sort)
echo "name: [" >"$work/bad.yaml"
"$bin" calibrate "$lab/suite.yaml" --out "$work/cal" --holdout "$work/bad.yaml" >/dev/null 2>"$work/err.txt"
code=$?
[ $code -eq 2 ] || fail "malformed holdout: exit $code"
[ "$(wc -l <"$work/err.txt")" -eq 1 ] || fail "malformed holdout: not one stderr line"
[ "$(cd "$work/cal" && md5sum * | sort)" = "$before" ] || fail "DIR changed by a failed calibrate"
echo ok
