#!/usr/bin/env bash
# Regenerates everything in results/ (see results/README.md). Deterministic: fixed seeds, and
# the statistics do not depend on the thread count.
#   scripts/reproduce.sh            # all
#   scripts/reproduce.sh kleeman95  # one part: kleeman95, sweeps, optiodom
set -euo pipefail
shopt -s failglob  # a pattern that matches nothing is an error, never a literal argument
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
odomcov="$root/build/src/cli/odomcov"
python=/usr/bin/python3  # Debian's, which has matplotlib
results="$root/results"
parts=("${@:-all}")
want() { [[ " ${parts[*]} " == *" all "* || " ${parts[*]} " == *" $1 "* ]]; }
# save FILE CMD...: runs CMD with stdout into a temporary file beside FILE, and moves it over
# FILE only when CMD succeeds, so a failure never empties a committed result.
save() {
  local dest=$1 tmp
  shift
  tmp=$(mktemp "$dest.XXXXXX")
  if "$@" > "$tmp"; then
    chmod 644 "$tmp"
    mv -f "$tmp" "$dest"
  else
    local code=$?
    rm -f "$tmp"
    echo "reproduce.sh: '$*' failed (exit $code); $dest left as it was" >&2
    return "$code"
  fi
}

if want kleeman95; then
  out="$results/kleeman95"
  mkdir -p "$out"
  # Tables I and II: the closed form along the Fig. 7 path.
  save "$out/table1.txt" "$odomcov" theory "$root/configs/kleeman95/fig7.yaml" --json "$out/table1.json"
  save "$out/table2.txt" "$odomcov" theory "$root/configs/kleeman95/fig9.yaml" --json "$out/table2.json"
  # Tables III-V: 10 000 Monte-Carlo runs against theory (2000 end points kept for the plots).
  for t in 3 4 5; do
    save "$out/table$t.txt" "$odomcov" run "$root/configs/kleeman95/table$t.yaml" --samples 2000 \
      --json "$out/table$t.json"
  done
  # Figures 8 and 9, with the Table III and IV end points.
  "$python" "$root/scripts/plot_ellipses.py" "$out/table1.json" --run "$out/table3.json" --out "$out/fig8.png"
  "$python" "$root/scripts/plot_ellipses.py" "$out/table2.json" --run "$out/table4.json" --out "$out/fig9.png"
fi

if want sweeps; then
  out="$results/sweeps"
  mkdir -p "$out"
  "$odomcov" sweep "$root/configs/sweeps/noise_breakdown.yaml" --out "$out/noise_breakdown.csv" \
    --json "$out/noise_breakdown.json"
  "$python" "$root/scripts/plot_sweep.py" "$out/noise_breakdown.csv" --json "$out/noise_breakdown.json" \
    --x-factor 1e-3 --x-label "kL = kR [m^1/2]" \
    --title "Order 1 (and order 2 overlaid) against wheel noise: Fig. 7 path, 10 000 runs per point" \
    --out "$out/noise_breakdown.png"
  "$odomcov" sweep "$root/configs/sweeps/noise_breakdown.yaml" --order 2 \
    --out "$out/noise_breakdown_order2.csv" --json "$out/noise_breakdown_order2.json"
  "$python" "$root/scripts/plot_sweep.py" "$out/noise_breakdown_order2.csv" \
    --json "$out/noise_breakdown_order2.json" --x-factor 1e-3 --x-label "kL = kR [m^1/2]" \
    --title "Order 2 (and order 1 overlaid) against wheel noise: Fig. 7 path, 10 000 runs per point" \
    --out "$out/noise_breakdown_order2.png"
  "$odomcov" sweep "$root/configs/sweeps/sample_rate.yaml" --out "$out/sample_rate.csv" \
    --json "$out/sample_rate.json"
  "$python" "$root/scripts/plot_sweep.py" "$out/sample_rate.csv" --json "$out/sample_rate.json" \
    --x path.sample_rate --x-label "sample rate [Hz]" \
    --title "First-order theory against sample rate: Fig. 7 path, kL = kR = 1e-3 x noise_scale" \
    --out "$out/sample_rate.png"
fi
if want optiodom; then
  cd "$root"  # paths in the reports are relative to the checkout
  out=results/optiodom
  data=data/optiodom/data/diff  # the OptiOdom recordings [Sousa22], shipped in the repository
  if [[ ! -d $data/square ]]; then
    echo "reproduce.sh: $root/$data: no OptiOdom recordings (they ship in data/optiodom/)" >&2
    exit 2
  fi
  suite=build/optiodom  # imported suites are regenerated, not committed
  mkdir -p "$out"
  # One nominal robot for every session: B = 0.2 m, D = 0.084 m. Some sessions' metadata say
  # 0.205/0.085, but their raw ticks behave exactly like the others' (results/optiodom/README.md).
  import_sessions() {  # DIR SESSION...
    local dir=$1
    shift
    "$odomcov" import optiodom "$@" --wheelbase 0.2 --diameters 0.084,0.084 --out "$dir"
  }
  save "$out/import.txt" import_sessions "$suite" "$data"/square/* "$data"/ivanjko/* "$data"/circular/* "$data"/free/*
  save "$out/compare_nominal.txt" "$odomcov" compare "$suite/suite.yaml" --json "$out/compare_nominal.json"
  cw=$(grep -o 'square-[0-9]*-cw' "$suite/suite.yaml" | sort -u | paste -sd,)
  ccw=$(grep -o 'square-[0-9]*-ccw' "$suite/suite.yaml" | sort -u | paste -sd,)
  save "$out/umbmark.txt" "$odomcov" umbmark "$suite/suite.yaml" --cw "$cw" --ccw "$ccw" --side 0.75 \
    --json "$out/umbmark.json"
  for type in square ivanjko circular free; do
    "$python" scripts/plot_compare.py "$out/compare_nominal.json" --match "$type-" \
      --title "OptiOdom $type runs against the nominal model (B = 0.2 m, kL = kR = 1e-3)" \
      --out "$out/compare_nominal_$type.png"
  done
  # Where each path type turns (spin fraction) and how fast it drives, per campaign.
  save "$out/features.md" "$python" scripts/optiodom_features.py "$suite"
  # calibrate (docs/calibrate.md): diagnose, adopt the candidate that predicts its held-out folds
  # better, repeat, fit jointly; with --train/--test the final model is judged on the held-out
  # runs. In-sample on all the runs; each path type held out in turn; the campaigns (December
  # 2020 -> June 2020 and the reverse; the January 2021 free paths are in neither). group: is the
  # session, so group_variation is among the candidates. Order 2, alpha 0.01, seed 1 (defaults).
  splits=(
    "all"
    "hold_circular --train ^(free|ivanjko|square)- --test ^circular-"
    "hold_free --train ^(circular|ivanjko|square)- --test ^free-"
    "hold_ivanjko --train ^(circular|free|square)- --test ^ivanjko-"
    "hold_square --train ^(circular|free|ivanjko)- --test ^square-"
    "dec_to_jun --train ^[a-z]+-2312 --test ^[a-z]+-(2306|2506)"
    "jun_to_dec --train ^[a-z]+-(2306|2506) --test ^[a-z]+-2312"
  )
  # calib NAME SUITE_DIR [calibrate options]: the report calibrate_NAME.txt; for the study's own
  # splits (not the _custom, _spins and _day variants, whose figures custom.md, spins.md and
  # group.md tabulate)
  # also calibrate_NAME.json and the plot calibrate_NAME.png.
  calib() {
    local name=$1 from=$2 dir="$suite-calibrate-$1"
    shift 2
    save "$out/calibrate_$name.txt" "$odomcov" calibrate "$from/suite.yaml" --out "$dir" "$@"
    [[ $name == *_custom || $name == *_spins || $name == *_day ]] && return
    cp "$dir/calibrate.json" "$out/calibrate_$name.json"
    "$python" scripts/plot_loop.py "$dir" --out "$out/calibrate_$name.png"
  }
  # The same recordings grouped by recording day instead of by session (below).
  import_sessions "$suite-day" --group day "$data"/square/* "$data"/ivanjko/* "$data"/circular/* \
    "$data"/free/* > /dev/null
  set -f  # the regexes are arguments, never globs
  for split in "${splits[@]}"; do
    read -r -a args <<<"$split"
    calib "${args[0]}" "$suite" "${args[@]:1}"
  done
  # The robot and model calibrate built on all the runs, to paste into a suite, and its ROS 2
  # parameters.
  cp "$suite-calibrate-all/model.yaml" "$out/model_all.yaml"
  cp "$suite-calibrate-all/diff_drive.yaml" "$out/diff_drive_all.yaml"
  # The custom hypotheses of candidates.yaml (written from the residual alignment: speed, spin
  # fraction, turn direction) ranked beside the catalogue: calibrate adopts one only when it
  # predicts its held-out folds better, and each split's hold-out says whether the model then
  # predicts the held-out runs better.
  for split in "${splits[@]}"; do
    read -r -a args <<<"$split"
    calib "${args[0]}_custom" "$suite" "${args[@]:1}" --candidates "$out/candidates.yaml"
  done
  # Physics for the Ivanjko turns on the spot (candidates_spins.yaml: noise growing with the
  # acceleration, the spin fraction or the turn rate; a wheelbase growing with the turn rate;
  # each wheel's scale backwards; a wheelbase that differs between left and right turns on the
  # spot), on all the runs and on the two splits that miss the floor.
  for split in "${splits[@]}"; do
    read -r -a args <<<"$split"
    [[ ${args[0]} == all || ${args[0]} == hold_ivanjko || ${args[0]} == jun_to_dec ]] || continue
    calib "${args[0]}_spins" "$suite" "${args[@]:1}" --candidates "$out/candidates_spins.yaml"
  done
  # Groups by recording day (import --group day, above) instead of by session, on all the runs.
  calib all_day "$suite-day"
  set +f
  # Tables across the runs: the catalogue splits; each with and without the custom hypotheses;
  # session against day groups. Every figure is calibrate's.
  names=() custom=()
  for split in "${splits[@]}"; do
    n=${split%% *}
    names+=("$n=$out/calibrate_$n.json")
    custom+=("$n=$out/calibrate_$n.json" "${n}_custom=$suite-calibrate-${n}_custom")
  done
  save "$out/summary.md" "$python" scripts/loop_summary.py "${names[@]}"
  save "$out/custom.md" "$python" scripts/loop_summary.py "${custom[@]}"
  spins=()
  for n in all hold_ivanjko jun_to_dec; do
    spins+=("$n=$out/calibrate_$n.json" "${n}_spins=$suite-calibrate-${n}_spins")
  done
  save "$out/spins.md" "$python" scripts/loop_summary.py "${spins[@]}"
  save "$out/group.md" "$python" scripts/loop_summary.py "all (session groups)=$out/calibrate_all.json" \
    "all (day groups)=$suite-calibrate-all_day"
  # In-sample reach: how near 3 the model family gets on the runs a hold-out judges (the Ivanjko
  # paths, each campaign) when it has seen them: the all-runs model, its effects refitted on them,
  # and calibrate on them alone; then what the training runs of the two hold-outs that miss their
  # floors say about the parameter they need (a profile of the all-runs model on them).
  save "$out/reach.md" "$python" scripts/optiodom_reach.py "$odomcov" "$suite" "$out/model_all.yaml" \
    "$out/calibrate_all.json" "$suite-reach"
fi
echo "results regenerated in $results" >&2
