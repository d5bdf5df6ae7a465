#!/usr/bin/env bash
# README command (a): installs what is missing, builds, generates the synthetic three-session
# lounge (paper §IV) into data/lounge, prints what it contains, runs the three sessions through
# segmentation, GSM and the object database into data/objects.sqlite, describes the result and
# writes session 1's scene completed by the merged models (data/session_1_completed.ply).
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
BUILD_DIR=${BUILD_DIR:-build}
OUT=${OUT:-data/lounge}
"$BUILD_DIR/bin/objdb" sim --preset lounge --out "$OUT" --overwrite
echo
"$BUILD_DIR/bin/objdb" info "$OUT"
DB=${DB:-data/objects.sqlite}
rm -f "$DB" "$DB-wal" "$DB-shm"  # the lounge was just regenerated: start a fresh database
echo
"$BUILD_DIR/bin/objdb" ingest --db "$DB" "$OUT"
echo
"$BUILD_DIR/bin/objdb" db stats --db "$DB"
echo
"$BUILD_DIR/bin/objdb" db complete --db "$DB" --session session_1 \
  --out "$(dirname "$DB")/session_1_completed.ply"
