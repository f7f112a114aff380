#!/usr/bin/env bash
# CLI contract check used by ctest:
#   cli_expect.sh EXIT_CODE STDERR_REGEX OUTPUT_FILE -- COMMAND...
# Runs COMMAND and requires: the exit code; when EXIT_CODE is 2, exactly one stderr line that
# matches STDERR_REGEX (extended regex) and no OUTPUT_FILE left behind (no partial output);
# otherwise STDERR_REGEX is matched against stdout. OUTPUT_FILE may be "-" for none.
set -u
want_code=$1 regex=$2 output=$3
shift 3
[ "$1" = "--" ] && shift
[ "$output" != "-" ] && rm -rf "$output"
out=$(mktemp) err=$(mktemp)
trap 'rm -f "$out" "$err"' EXIT
"$@" >"$out" 2>"$err"
code=$?
fail() { echo "FAIL: $*"; echo "--- stdout"; head -40 "$out"; echo "--- stderr"; cat "$err"; exit 1; }
[ "$code" -eq "$want_code" ] || fail "exit code $code, expected $want_code"
if [ "$want_code" -eq 2 ]; then
  lines=$(wc -l <"$err")
  [ "$lines" -eq 1 ] || fail "expected exactly one stderr line, got $lines"
  grep -Eq -- "$regex" "$err" || fail "stderr does not match /$regex/"
  if [ "$output" != "-" ] && [ -e "$output" ]; then fail "partial output $output was written"; fi
else
  grep -Eq -- "$regex" "$out" || fail "stdout does not match /$regex/"
  if [ "$output" != "-" ] && [ ! -s "$output" ]; then fail "output $output missing"; fi
fi
echo "ok"
