#!/usr/bin/env bash
# Benchmark of `odomcov diagnose` on blind worlds (issue 7): the identification rate over a mixed
# batch of 110 worlds (each effect alone, a wrong noise level, pairs of effects, nothing hidden)
# and the false-alarm rate over 200 worlds with nothing hidden. Seeds are fixed, so the figures
# in results/diagnose/ are reproducible; a few minutes on two cores. These seeds were fixed
# after the method was final: the batches used while developing it (seeds 11, 2027, 90210,
# 31337, 555) are not the ones reported.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
out="$root/results/diagnose"
work="$root/build/diagnose_rates"
mkdir -p "$out"
rm -rf "$work"
run() {  # name seed worlds cases
  /usr/bin/python3 "$root/scripts/diagnose_blind.py" --odomcov "$root/build/src/cli/odomcov" \
    --seed "$2" --worlds "$3" --cases "$4" --out "$work/$1" --report "$out/$1.json" > "$out/$1.txt"
}
run mixed 20261121 110 mixed
run none 11212026 200 none
echo "rates in $out/mixed.txt and $out/none.txt" >&2
