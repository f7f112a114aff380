#!/usr/bin/env bash
# Replays hostile inputs through the CLI (tests/hostile/README in docs/bad-input.md):
#   run.sh ODOMCOV SOURCE_DIR WORK_DIR cases      every line of cases.txt
#   run.sh ODOMCOV SOURCE_DIR WORK_DIR corpora    every committed fuzz corpus input
# Each must exit with an allowed code (never 3, never a signal, within 20 s), print at most one
# stderr line (exactly one on exit 2) of at most 1000 bytes (long input is quoted cut) and, on
# exit 2, leave no output behind. A case with a fourth field runs that command after an exit 0
# (e.g. compare on the suite an import wrote: it must load), which must exit 0 too.
set -u
bin=$1 src=$2 work=$3 mode=$4
here="$src/tests/hostile"
rm -rf "$work" && mkdir -p "$work"
failures=0 count=0
check() {  # name, allowed codes, args...
  local name=$1 allowed=$2; shift 2
  local out="$work/out.$name" err="$work/err.$name"
  count=$((count + 1))
  timeout 20 "$bin" "$@" >/dev/null 2>"$err"
  local code=$? lines bytes
  lines=$(wc -l <"$err") bytes=$(wc -c <"$err")
  local why=""
  if [ $code -eq 124 ]; then why="timed out"
  elif [ $code -gt 128 ]; then why="killed by signal $((code - 128))"
  elif ! grep -qw -- "$code" <<<"$allowed"; then why="exit $code, allowed: $allowed"
  elif [ $code -eq 2 ] && [ "$lines" -ne 1 ]; then why="exit 2 with $lines stderr lines"
  elif [ "$lines" -gt 1 ]; then why="$lines stderr lines"
  elif [ "$bytes" -gt 1000 ]; then why="a stderr line of $bytes bytes"
  elif [ $code -eq 2 ] && compgen -G "$out*" >/dev/null; then why="partial output left: $(ls -d "$out"*)"
  elif grep -q "internal error" "$err"; then why="internal error"
  elif [ $code -eq 0 ] && [ ${#after[@]} -gt 0 ] && ! timeout 20 "$bin" "${after[@]}" >/dev/null 2>"$err.after"; then
    why="afterwards, ${after[*]} failed: $(head -c 300 "$err.after")"
  fi
  if [ -n "$why" ]; then
    failures=$((failures + 1))
    echo "FAIL $name: $why"; head -c 400 "$err"; echo
  fi
  rm -rf "$out" "$out".*  # outputs can be large (synth at the world limit)
}
if [ "$mode" = cases ]; then
  while IFS='|' read -r name codes args then; do
    name=$(echo $name); [ -z "$name" ] || [ "${name#\#}" != "$name" ] && continue
    subst() { local a=${1//@C/$here/cases}; a=${a//@S/$src}; echo "${a//@O/$work/out.$name}"; }
    eval "after=($(subst "${then:-}"))"
    eval "set -- $(subst "$args")"
    check "$name" "$(echo $codes)" "$@"
  done <"$here/cases.txt"
else
  after=()
  # fuzz_calibrate's arguments (one per line) for the CLI: the files they name in DIR, --out and
  # --json under OUT (the fuzzer ignores both). Prints them one per line.
  calibrate_args() {  # ARGS_FILE DIR OUT
    local -a a
    mapfile -t a <"$1"
    local i
    for ((i = 0; i < ${#a[@]}; i++)); do
      case ${a[i]} in
        --out) echo --out; echo "$3"; i=$((i + 1)) ;;
        --json) echo --json; echo "$3.json"; i=$((i + 1)) ;;
        -*) echo "${a[i]}" ;;
        *) if [ -n "${a[i]}" ] && [ -e "$2/$(basename -- "${a[i]}")" ]; then echo "$2/$(basename -- "${a[i]}")"; else echo "${a[i]}"; fi ;;
      esac
    done
  }
  # Fuzz corpus inputs: unpack the sections (tests/fuzz/fuzz_util.hpp) and run the command that
  # reads that kind of file.
  for input in "$src"/tests/fuzz/corpus/*/*; do
    target=$(basename "$(dirname "$input")")
    dir="$work/in.$count"; mkdir -p "$dir"
    case $target in
      path_config) main=config.yaml ;; sweep) main=sweep.yaml ;; world|roundtrip) main=world.yaml ;;
      suite) main=suite.yaml ;; custom) main=effects.yaml ;; optiodom) main=notes.txt; dir="$dir/square/20000101"; mkdir -p "$dir" ;;
      csv_import) main=run-01.csv ;; calibrate) main=args ;;
    esac
    awk -v dir="$dir" -v main="$main" '
      BEGIN { f = dir "/" main }
      /^#@ / { name = substr($0, 4); f = (name ~ /^[A-Za-z0-9_-][A-Za-z0-9_.-]*$/) ? dir "/" name : "/dev/null"; next }
      { print > f }' "$input"
    name="$target.$(basename "$input")"
    case $target in
      path_config) check "$name" "0 2" theory "$dir/$main" --json "$work/out.$name" ;;
      sweep) check "$name" "0 2" sweep "$dir/$main" --shard 1/1000 --out "$work/out.$name" ;;
      world|roundtrip) check "$name" "0 2" synth "$dir/$main" --out "$work/out.$name" ;;
      suite) check "$name" "0 2" compare "$dir/$main" --json "$work/out.$name" ;;
      optiodom) check "$name" "0 2" import optiodom "$dir" --out "$work/out.$name" ;;
      custom) check "$name" "0 2" diagnose "$src/tests/data/suites/good_logs.yaml" --effects wheelbase_error \
                --candidates "$dir/$main" --json "$work/out.$name" ;;
      csv_import) check "$name" "0 2" import csv "$dir" --wheelbase 0.3 --out "$work/out.$name" ;;
      calibrate) mapfile -t cargs < <(calibrate_args "$dir/$main" "$dir" "$work/out.$name")
                 check "$name" "0 2" calibrate "${cargs[@]}" ;;
    esac
  done
fi
echo "$count inputs, $failures failures"
[ $failures -eq 0 ]
