#!/usr/bin/env bash
# Cross-builds odomcov for aarch64 (64-bit ARM: Jetson, Raspberry Pi) with Debian's cross compiler
# and runs the GoogleTest unit tests (the ctest names with a dot, Suite.Case) under qemu-user.
# The CLI tests are left out: they start the binary from shell scripts, which would need the
# kernel's binfmt registration of qemu, which CI cannot set. The arm64 libraries are Debian's packages, downloaded
# and extracted into a sysroot under build-aarch64/ (never installed, so the host is unchanged).
#   scripts/cross_aarch64.sh [ctest arguments...]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="$root/build-aarch64"
sysroot="$out/sysroot"

host_packages=(g++-aarch64-linux-gnu qemu-user)
arm_packages=(libtbb-dev libtbb12 libtbbmalloc2 libtbbbind-2-5 libhwloc15 libyaml-cpp-dev libyaml-cpp0.7
              libnlopt-dev libnlopt-cxx-dev libnlopt-cxx0 libnlopt0 libmuparser-dev libmuparser2v5
              libhwy-dev libhwy1
              libgtest-dev libgmock-dev)

sudo_cmd=()
[ "$(id -u)" -eq 0 ] || sudo_cmd=(sudo)
missing=()
for p in "${host_packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
need_update=0
if ! dpkg --print-foreign-architectures | grep -qx arm64; then
  "${sudo_cmd[@]}" dpkg --add-architecture arm64
  need_update=1
fi
if [ ${#missing[@]} -gt 0 ] || [ $need_update -eq 1 ]; then
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq >/dev/null
  [ ${#missing[@]} -eq 0 ] || "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

# The sysroot is kept between runs; it is made again when the package list changes.
if [ "$(cat "$sysroot/.complete" 2>/dev/null)" != "${arm_packages[*]}" ]; then
  rm -rf "$sysroot" "$out/debs"
  mkdir -p "$sysroot" "$out/debs"
  (cd "$out/debs" && apt-get download -qq "${arm_packages[@]/%/:arm64}" 2>/dev/null)
  for deb in "$out"/debs/*.deb; do dpkg-deb -x "$deb" "$sysroot"; done
  # Header-only, architecture-independent packages come from the host through links.
  mkdir -p "$sysroot/host-headers"
  ln -sfn /usr/include/boost "$sysroot/host-headers/boost"
  ln -sfn /usr/include/Random123 "$sysroot/host-headers/Random123"
  echo "${arm_packages[*]}" > "$sysroot/.complete"
fi

cmake -S "$root" -B "$out/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
      -DCMAKE_TOOLCHAIN_FILE="$root/cmake/toolchains/aarch64-linux-gnu.cmake" \
      -DODOMCOV_AARCH64_SYSROOT="$sysroot" -DODOMCOV_BUILD_BENCHMARKS=OFF -DODOMCOV_BUILD_PYTHON=OFF >/dev/null
cmake --build "$out/build" --parallel "$(nproc)" -- --quiet
readelf -h "$out/build/src/cli/odomcov" | grep -q "AArch64" || { echo "cross_aarch64: not an aarch64 binary" >&2; exit 1; }
cd "$out/build"
# Under qemu-user the unit tests run 60-100 times slower than natively: on two cores, 235 of them
# took 63 minutes (7533 s of CPU; 2026-12-01), most of CI's 90-minute budget with the native build and
# tests beside. Four are left out here: the statistical checks of the fitting loop and the referee
# that cost most under emulation and whose code has nothing that differs between the instruction
# sets.
#   - Diagnose.FastAndExactAgreeOnTheWinnerWithANonlinearCandidate (912 s): the fast and exact
#     fits of a custom effect, scalar likelihood code only;
#   - Diagnose.TheTailsDecideBetweenANoiseLevelAndBumps (1082 s): the diagnose rule built on the
#     tails test, whose own size and power (TailsTest.HasItsSizeOnCorrectModelsAndPowerOnWrongTails)
#     are checked here;
#   - Compare.OverEveryLookACorrectModelIsRejectedAtMostAlpha (1328 s): the referee's size over
#     every look;
#   - Compare.SimulatedVerdictHasItsSizeAndPower (2756 s since the normals by inversion, 2026-12-02:
#     qemu emulates each float operation, and a normal is now about 55 of them where the
#     ziggurat's fast path was two loads; it held the stage at 48 minutes, 58 for all of CI):
#     the referee's size and power at one look, whose parts run here (the replicates' bits,
#     ModelWorld.*, the looks' rule SequentialMcTest.*, the tails TailsTest.*).
# The NEON kernel's bits are pinned against the scalar reference (Simulator.*, Random.* and the
# effect tests, run here), so these four would compute the same numbers as natively, where
# scripts/test.sh runs them; what could differ is libm's last bits in the scalar fitting code,
# which the tests left here exercise too.
# ODOMCOV_AARCH64_ALL=1 runs every unit test. ctest's limit per test is there to catch a hang,
# so it is 3600 s here (the default 1500 s is near the slowest tests' time under emulation).
skip="^(Diagnose[.]FastAndExactAgreeOnTheWinnerWithANonlinearCandidate|Diagnose[.]TheTailsDecideBetweenANoiseLevelAndBumps|Compare[.]OverEveryLookACorrectModelIsRejectedAtMostAlpha|Compare[.]SimulatedVerdictHasItsSizeAndPower)$"
[ "${ODOMCOV_AARCH64_ALL:-0}" = 1 ] && skip="^$"
# ctest starts the tests its cost data (from an earlier run in this tree) say are longest first;
# a fresh tree has none and starts them in the order they are defined, where the slowest comes
# near the end and would run alone for its last 20 minutes. So a fresh tree gets the emulated
# seconds of the slowest tests measured above ("name runs seconds", ctest's own format).
costs=Testing/Temporary/CTestCostData.txt
if [ ! -s "$costs" ]; then
  mkdir -p Testing/Temporary
  printf '%s\n' "TailsTest.HasItsSizeOnCorrectModelsAndPowerOnWrongTails 1 654" \
    "Verdict.ConstantNoiseLevelIsNotAdoptedForNoiseThatGrowsWithSpeed 1 240" \
    "Simulator.NoiseInducedMeanMatchesLargeNoise 1 184" \
    "ResidualFeatures.SimulatedDispersionKeepsTheScatterTestsSizeOnHeavyTails 1 175" \
    "CrossValidation.TheCacheKeepsVerdictsAndForgetsWhatARoundDidNotRead 1 162" \
    "Statistics.AdfTestHasItsSizeOnABananaWhereTheLrtDoesNot 1 150" \
    "SequentialMcTest.KeepsItsSizeOverEveryLookOnExchangeableScores 1 137" "---" > "$costs"
fi
ctest --output-on-failure --parallel "$(nproc)" --timeout 3600 -R "[.]" -E "$skip" "$@"
