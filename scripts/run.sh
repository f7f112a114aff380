#!/usr/bin/env bash
# Quick start, step 1: install dependencies, build, and run the main job on a config.
#   scripts/run.sh configs/kleeman95/table3.yaml [extra odomcov run arguments]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ $# -lt 1 ]; then
  echo "usage: scripts/run.sh CONFIG [odomcov options...]" >&2
  exit 2
fi
"$root/scripts/setup.sh"
"$root/scripts/build.sh"
exec "$root/build/src/cli/odomcov" run "$@"
