#!/usr/bin/env bash
# Sweep contract: rows are deterministic, and the shards of a sweep together give exactly the
# rows of the unsharded sweep (up to row order).
#   sweep_shards.sh ODOMCOV SWEEP.yaml WORKDIR
set -euo pipefail
odomcov=$1 sweep=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
"$odomcov" sweep "$sweep" --out "$work/all.csv" --threads 2 > /dev/null
"$odomcov" sweep "$sweep" --out "$work/again.csv" --threads 1 > /dev/null
cmp "$work/all.csv" "$work/again.csv" || { echo "FAIL: not deterministic across runs/threads"; exit 1; }
for i in 1 2 3; do "$odomcov" sweep "$sweep" --out "$work/shard$i.csv" --shard "$i/3" > /dev/null; done
head -1 "$work/all.csv" > "$work/merged.csv"
tail -q -n +2 "$work"/shard?.csv | sort >> "$work/merged.csv"
{ head -1 "$work/all.csv"; tail -n +2 "$work/all.csv" | sort; } > "$work/all_sorted.csv"
cmp "$work/merged.csv" "$work/all_sorted.csv" || { echo "FAIL: shards differ from the whole"; diff "$work/merged.csv" "$work/all_sorted.csv" | head; exit 1; }
rows=$(($(wc -l < "$work/all.csv") - 1))
[ "$rows" -eq 12 ] || { echo "FAIL: expected 12 rows, got $rows"; exit 1; }
echo "ok: $rows rows, shards identical"
