#!/usr/bin/env bash
# Installs odomcov from BUILD_DIR into a temporary prefix, then configures, builds and runs
# examples/ekf_predict against the installed package, as a user outside the tree would.
#   install_consumer.sh BUILD_DIR SOURCE_DIR WORK_DIR
set -euo pipefail
build=$1 source=$2 work=$3
rm -rf "$work"
mkdir -p "$work"
cmake --install "$build" --prefix "$work/prefix" > "$work/install.log"
test -f "$work/prefix/include/odomcov/closed_form/odometry_covariance.hpp"
test -f "$work/prefix/include/odomcov/odometry_covariance.hpp"  # the forwarding header (docs/library.md)
test -f "$work/prefix/lib/cmake/odomcov/odomcovConfigVersion.cmake" || \
  test -f "$work/prefix/lib/"*/cmake/odomcov/odomcovConfigVersion.cmake
cmake -S "$source/examples/ekf_predict" -B "$work/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
      -DCMAKE_PREFIX_PATH="$work/prefix" > "$work/configure.log"
cmake --build "$work/build" > "$work/build.log"
# closed_form alone: the link line names no TBB, yaml-cpp, NLopt or Boost library
if grep -Eq "tbb|yaml|nlopt|boost" "$work/build/build.ninja"; then
  echo "FAIL: the example links more than odomcov::closed_form"; grep -En "tbb|yaml|nlopt|boost" "$work/build/build.ninja" | head; exit 1
fi
"$work/build/ekf_predict"
