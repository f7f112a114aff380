#!/usr/bin/env bash
# Ctrl-C during a sweep: exit code 130, and every row in the CSV is complete.
#   sweep_interrupt.sh ODOMCOV SWEEP.yaml WORKDIR
set -u
odomcov=$1 sweep=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
csv="$work/out.csv"
"$odomcov" sweep "$sweep" --out "$csv" > /dev/null 2> "$work/err" &
pid=$!
for _ in $(seq 1 300); do  # wait (up to 30 s) for the header and one row
  [ -f "$csv" ] && [ "$(wc -l < "$csv")" -ge 2 ] && break
  sleep 0.1
done
kill -INT "$pid"
wait "$pid"
code=$?
[ "$code" -eq 130 ] || { echo "FAIL: exit code $code, expected 130"; cat "$work/err"; exit 1; }
fields=$(head -1 "$csv" | awk -F, '{print NF}')
rows=$(($(wc -l < "$csv") - 1))
awk -F, -v n="$fields" 'NF != n { bad = 1 } END { exit bad }' "$csv" || { echo "FAIL: a partial row"; exit 1; }
[ -z "$(tail -c 1 "$csv")" ] || { echo "FAIL: the last line is unterminated"; exit 1; }
[ "$rows" -ge 1 ] && [ "$rows" -lt 10 ] || { echo "FAIL: $rows rows"; exit 1; }
grep -q "interrupted after $rows of 10 points" "$work/err" || { echo "FAIL: message"; cat "$work/err"; exit 1; }
echo "ok: interrupted with $rows complete rows"
