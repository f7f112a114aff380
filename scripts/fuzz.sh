#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz with clang, ASan and UBSan (in build-fuzz/, apart
# from the normal build) and runs each for SECONDS (default 60), starting from the committed
# seed corpus tests/fuzz/corpus/<target>/. Prints one line per target: executions, coverage
# (libFuzzer's edge counter "cov") after loading the corpora ("cov0") and at the end, features
# ("ft") and the corpus size, and where any crash input went. Exit status 1 if any target crashed.
#   scripts/fuzz.sh [SECONDS] [TARGET...]
# With ODOMCOV_FUZZ_JOBS=N, N targets run at the same time (each still for SECONDS of wall time);
# the default 1 runs them one after another. The build uses ODOMCOV_FUZZ_BUILD_JOBS jobs (2).
set -u
cd "$(dirname "$0")/.."
seconds=${1:-60}
shift || true
build=${ODOMCOV_FUZZ_BUILD:-build-fuzz}
cxx=${CXX_FUZZ:-clang++}
command -v "$cxx" >/dev/null || { echo "fuzz.sh: $cxx not found (apt-get install clang libclang-rt-dev)"; exit 2; }
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER="$cxx" \
  -DODOMCOV_FUZZ=ON -DODOMCOV_BUILD_TESTS=OFF -DODOMCOV_BUILD_BENCHMARKS=OFF "${launcher[@]}" >/dev/null || exit 2
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for f in tests/fuzz/fuzz_*.cpp; do
    t=$(basename "$f" .cpp); t=${t#fuzz_}
    [ "$t" = util ] || targets+=("$t")
  done
fi
cmake --build "$build" --parallel "${ODOMCOV_FUZZ_BUILD_JOBS:-2}" --target $(printf 'fuzz_%s ' "${targets[@]}") >/dev/null || { echo "fuzz.sh: build failed"; exit 2; }

jobs=${ODOMCOV_FUZZ_JOBS:-1}
fuzz_one() {  # target -> its result line in $build/result_<target>.txt
  local t=$1 work="$build/corpus/$1" artifacts="$build/artifacts/$1/" log="$build/fuzz_$1.log"
  mkdir -p "$work" "$artifacts"
  ASAN_OPTIONS=detect_leaks=0 "$build/tests/fuzz/fuzz_$t" -max_total_time="$seconds" -timeout=10 \
    -rss_limit_mb=2048 -max_len=8192 -print_final_stats=1 -artifact_prefix="$artifacts" \
    "$work" "tests/fuzz/corpus/$t" >"$log" 2>&1
  local code=$? execs last cov ft corp result cov0
  cov0=$(grep -m1 'INITED' "$log" | sed -n 's/.* cov: \([0-9]*\).*/\1/p')
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  last=$(grep -E '^#[0-9]+' "$log" | tail -1)
  cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
  ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
  corp=$(sed -n 's/.* corp: \([0-9]*\)\/.*/\1/p' <<<"$last")
  if [ $code -eq 0 ]; then result=ok; else
    result="CRASH: $(ls -t "$artifacts" | head -1 | sed "s|^|$artifacts|") (log $log)"
  fi
  printf '%-12s %10s %8s %8s %8s %8s  %s\n' "$t" "${execs:-?}" "${cov0:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$result" \
    >"$build/result_$t.txt"
}

printf '%-12s %10s %8s %8s %8s %8s  %s\n' target execs cov0 cov ft corpus result
running=0
for t in "${targets[@]}"; do
  rm -f "$build/result_$t.txt"
  if [ "$jobs" -gt 1 ]; then
    fuzz_one "$t" &
    running=$((running + 1))
    if [ $running -ge "$jobs" ]; then wait -n; running=$((running - 1)); fi
  else
    fuzz_one "$t"
  fi
done
wait
crashed=0
for t in "${targets[@]}"; do
  cat "$build/result_$t.txt"
  grep -q '  ok$' "$build/result_$t.txt" || crashed=1
done
exit $crashed
