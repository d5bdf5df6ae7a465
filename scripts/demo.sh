#!/usr/bin/env bash
# README command (a): installs what is missing, builds, generates the synthetic three-session
# lounge (paper §IV) into data/lounge and prints what it contains.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
BUILD_DIR=${BUILD_DIR:-build}
OUT=${OUT:-data/lounge}
"$BUILD_DIR/bin/objdb" sim --preset lounge --out "$OUT" --overwrite
echo
"$BUILD_DIR/bin/objdb" info "$OUT"
