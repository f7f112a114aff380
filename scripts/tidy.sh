#!/usr/bin/env bash
# Runs clang-tidy (the checks of .clang-tidy: cognitive complexity <= 25) over every source file
# of src/, with the compile commands of a configured build tree, and fails on any finding.
#   scripts/tidy.sh [BUILD_DIR]   (default build/; scripts/build.sh configures it)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${1:-$root/build}"
if ! command -v clang-tidy >/dev/null 2>&1; then
  echo "tidy: clang-tidy is not installed (scripts/setup.sh installs it)" >&2
  exit 1
fi
if [ ! -f "$build/compile_commands.json" ]; then
  echo "tidy: $build/compile_commands.json missing: configure the build first (scripts/build.sh)" >&2
  exit 1
fi
out="$(mktemp)"
trap 'rm -f "$out"' EXIT
cd "$root"
# One clang-tidy per file, as many at once as there are cores; a header's finding is reported
# by every file that includes it, so findings are de-duplicated.
find src -name '*.cpp' -print0 | sort -z |
  xargs -0 -P "$(nproc)" -n 1 clang-tidy -p "$build" --quiet 2>/dev/null |
  grep -E "^[^ ]+:[0-9]+:[0-9]+: (warning|error): " | sort -u > "$out" || true
if [ -s "$out" ]; then
  cat "$out"
  echo "tidy: $(wc -l < "$out") finding(s)" >&2
  exit 1
fi
echo "tidy: clean ($(find src -name '*.cpp' | wc -l) files)"
