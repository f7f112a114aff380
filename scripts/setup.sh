#!/usr/bin/env bash
# Installs the Debian packages odomcov needs, only those that are missing (idempotent, quiet).
# Sourced or run by scripts/run.sh and scripts/test.sh; safe to run on its own.
set -euo pipefail

packages=(
  cmake ninja-build g++ pkg-config
  libeigen3-dev libtbb-dev libyaml-cpp-dev libcli11-dev nlohmann-json3-dev
  libboost-math-dev librandom123-dev libnlopt-cxx-dev libmuparser-dev libhwy-dev
  libgtest-dev libbenchmark-dev clang-tidy
  python3-matplotlib python3-numpy
  pybind11-dev python3-pybind11 python3-dev python3-pytest
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done
[ ${#missing[@]} -eq 0 ] && exit 0

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then sudo_cmd=(sudo); else
    echo "setup: missing packages (${missing[*]}) and not root; install them and retry" >&2
    exit 1
  fi
fi
echo "setup: installing ${missing[*]}" >&2
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq >/dev/null
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
