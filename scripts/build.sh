#!/usr/bin/env bash
# Installs missing Debian packages, configures (once) and builds objdb incrementally.
# Usage: scripts/build.sh [extra cmake --build args]; BUILD_DIR and BUILD_TYPE may be set.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/deps.sh

BUILD_DIR=${BUILD_DIR:-build}
BUILD_TYPE=${BUILD_TYPE:-Release}
if [[ ! -f "$BUILD_DIR/build.ninja" ]]; then
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="$BUILD_TYPE"
fi
# Two cores and ~1 GB per PCL-heavy translation unit: one job per core.
cmake --build "$BUILD_DIR" -j "$(nproc)" "$@"
