#!/usr/bin/env bash
# The plotting scripts run on the tool's own JSON/CSV and write an image.
#   plot_smoke.sh ODOMCOV SOURCE_DIR WORKDIR
set -euo pipefail
odomcov=$1 src=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
"$odomcov" theory "$src/configs/kleeman95/fig9.yaml" --json "$work/theory.json" > /dev/null
"$odomcov" run "$src/configs/kleeman95/table4.yaml" --runs 500 --samples 200 --json "$work/run.json" > /dev/null
/usr/bin/python3 "$src/scripts/plot_ellipses.py" "$work/theory.json" --run "$work/run.json" --out "$work/fig.png"
"$odomcov" sweep "$src/tests/data/sweep/small.yaml" --out "$work/sweep.csv" --json "$work/sweep.json" > /dev/null
/usr/bin/python3 "$src/scripts/plot_sweep.py" "$work/sweep.csv" --json "$work/sweep.json" --x path.sample_rate --out "$work/sweep.png"
mkdir -p "$work/lab"
"$odomcov" synth "$src/configs/worlds/standard.yaml" --out "$work/lab" > /dev/null
# calibrate on the lab, in-sample and with the spins held out; the plot of each, and the table
# across the two.
"$odomcov" calibrate "$work/lab/suite.yaml" --out "$work/loop" --rounds 2 > /dev/null
"$odomcov" calibrate "$work/lab/suite.yaml" --out "$work/held" --rounds 2 --train '^(line|arc|forward|umbmark)' > /dev/null
/usr/bin/python3 "$src/scripts/plot_loop.py" "$work/loop" --out "$work/loop.png"
/usr/bin/python3 "$src/scripts/plot_loop.py" "$work/held" --group-by '^([a-z]+)' --out "$work/loop_held.png"
/usr/bin/python3 "$src/scripts/loop_summary.py" "all=$work/loop" "held=$work/held/calibrate.json" > "$work/summary.md"
grep -q '^| held | ' "$work/summary.md" || { echo "FAIL: loop_summary.py has no row for the held-out run"; exit 1; }
"$odomcov" predict "$src/tests/data/import_csv/mm/run-01.csv" --wheelbase 0.3 --k-left 1e-3 --k-right 1e-3 \
  --left-scale 0.001 --right-scale 0.001 --every 5 --json "$work/predict.json" > /dev/null
/usr/bin/python3 "$src/scripts/plot_ellipses.py" "$work/predict.json" --out "$work/log.png" > /dev/null
/usr/bin/python3 "$src/examples/python/ellipses_along_path.py" --out "$work/example.png" > /dev/null
# Without matplotlib (-S hides the system site-packages), a one-line hint and exit code 2.
for script in plot_ellipses.py plot_compare.py plot_sweep.py plot_loop.py; do
  code=0
  hint=$(/usr/bin/python3 -S "$src/scripts/$script" x --out "$work/none.png" 2>&1) || code=$?
  [ "$code" -eq 2 ] && [[ $hint == *"needs matplotlib"* ]] || { echo "FAIL: $script without matplotlib: $code $hint"; exit 1; }
done
for f in fig.png sweep.png loop.png loop_held.png log.png example.png; do
  [ "$(head -c 8 "$work/$f" | od -An -tx1 | tr -d ' \n')" = "89504e470d0a1a0a" ] || { echo "FAIL: $f is not a PNG"; exit 1; }
done
echo ok
