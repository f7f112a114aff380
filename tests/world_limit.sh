#!/usr/bin/env bash
# synth at the world limit (1e6 runs, a 72 MB measurement CSV) writes a suite that compare loads
# (the CSV limit holds it): both exit 0. About 25 s, so not among the 20 s hostile cases.
#   world_limit.sh ODOMCOV SOURCE_DIR WORK_DIR
set -eu
bin=$1 src=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
"$bin" synth "$src/tests/data/staged/world_limit.yaml" --out "$work/lab" >/dev/null
"$bin" compare "$work/lab/suite.yaml" --json "$work/compare.json" >/dev/null
rm -rf "$work"
echo "synth at the world limit loads back"
