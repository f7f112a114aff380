#!/usr/bin/env bash
# synth and import csv whose second file cannot be written leave nothing behind (issue 14):
#  1. under a file-size limit (ulimit -f 4: 4 KB, SIGXFSZ ignored so the write fails with EFBIG)
#     the first file fits and the second does not: exit 2, one stderr line, no --out and no
#     staging directory left;
#  2. into an existing --out whose suite.yaml is a directory: exit 2 before any file is moved,
#     the directory holds only what it held.
#   stage_failure.sh ODOMCOV SOURCE_DIR WORK_DIR
set -u
bin=$1 src=$2 work=$3
data="$src/tests/data/staged"
rm -rf "$work" && mkdir -p "$work"
failures=0
check() {  # name, expected listing of $work/box after the run, command...
  local name=$1 listing=$2; shift 2
  local err="$work/$name.err"
  (trap '' XFSZ; "$@") >/dev/null 2>"$err"
  local code=$? lines got
  lines=$(wc -l <"$err")
  got=$(cd "$work/box" && find . -mindepth 1 | sort | tr '\n' ' ')
  if [ $code -ne 2 ] || [ "$lines" -ne 1 ] || [ "$got" != "$listing" ]; then
    failures=$((failures + 1))
    echo "FAIL $name: exit $code, $lines stderr lines, left: '$got' (want '$listing')"; cat "$err"
  fi
  rm -rf "$work/box"
}
limited() { (ulimit -f 4; "$@"); }

mkdir -p "$work/box"
check synth_second_csv_too_big "" limited "$bin" synth "$data/world.yaml" --out "$work/box/lab"
mkdir -p "$work/box"
check import_csv_second_log_too_big "" \
  limited "$bin" import csv "$data/logs" --wheelbase 0.3 --out "$work/box/lab"
mkdir -p "$work/box/lab/suite.yaml"
check synth_suite_yaml_is_a_directory "./lab ./lab/suite.yaml " \
  "$bin" synth "$data/world.yaml" --out "$work/box/lab"
mkdir -p "$work/box/lab/suite.yaml"
check import_csv_suite_yaml_is_a_directory "./lab ./lab/suite.yaml " \
  "$bin" import csv "$data/logs" --wheelbase 0.3 --out "$work/box/lab"
echo "4 cases, $failures failures"
[ $failures -eq 0 ]
