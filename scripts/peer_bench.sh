#!/usr/bin/env bash
# Peer benchmarks: builds objdb with -DOBJDB_BUILD_PEERS=ON and runs our TSDF
# integration and registration against Open3D's and PCL's on the same inputs, in one run.
# Installs Debian's libopen3d-dev when it is missing (root or sudo; not part of the main build,
# which never needs Open3D). Run from anywhere; the benchmarks use a real TUM-layout sequence
# (e.g. SUN3D) when one is present.
# Usage: scripts/peer_bench.sh [--repeats R] (passed to every peer benchmark)
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/deps.sh libopen3d-dev

BUILD_DIR=${BUILD_DIR:-build}
BUILD_TYPE=${BUILD_TYPE:-Release}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="$BUILD_TYPE" -DOBJDB_BUILD_PEERS=ON >/dev/null
cmake --build "$BUILD_DIR" -j "$(nproc)" --target tsdf_peers registration_peers

"$BUILD_DIR/bin/tsdf_peers" "$@"
"$BUILD_DIR/bin/registration_peers" "$@"
