#!/usr/bin/env bash
# README command (a): installs what is missing, builds, generates the synthetic three-session
# lounge (paper §IV) into data/lounge and prints what it contains; then starts objdb-server on a
# fresh database (data/objects.sqlite), streams the three sessions to it over gRPC (segmentation,
# GSM and the object database run in the server), asks it for its statistics, sessions and session
# 1's scene completed by the merged models (data/session_1_completed.ply), stops it with SIGTERM
# and checks the database file it left.
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/build.sh
BUILD_DIR=${BUILD_DIR:-build}
OBJDB="$BUILD_DIR/bin/objdb"
OUT=${OUT:-data/lounge}
"$OBJDB" sim --preset lounge --out "$OUT" --overwrite
echo
"$OBJDB" info "$OUT"
DB=${DB:-data/objects.sqlite}
rm -f "$DB" "$DB-wal" "$DB-shm"  # the lounge was just regenerated: start a fresh database

# The server on a free loopback port; its log tells which.
LOG="$(dirname "$DB")/server.log"
"$BUILD_DIR/bin/objdb-server" --listen 127.0.0.1:0 --db "$DB" >"$LOG" 2>&1 &
SERVER_PID=$!
trap 'kill -TERM "$SERVER_PID" 2>/dev/null || true' EXIT
ADDRESS=""
for _ in $(seq 1 300); do
  ADDRESS=$(sed -n 's/.*listening on \([0-9.]*:[0-9]*\).*/\1/p' "$LOG" | head -n 1)
  [[ -n "$ADDRESS" ]] && break
  if ! kill -0 "$SERVER_PID" 2>/dev/null; then
    echo "objdb-server did not start:" >&2
    cat "$LOG" >&2
    exit 1
  fi
  sleep 0.1
done
[[ -n "$ADDRESS" ]] || { echo "objdb-server did not report its address" >&2; exit 1; }
echo
echo "objdb-server listening on $ADDRESS (log: $LOG)"
echo
"$OBJDB" stream --server "$ADDRESS" "$OUT"
echo
"$OBJDB" remote stats --server "$ADDRESS"
echo
"$OBJDB" remote sessions --server "$ADDRESS"
echo
"$OBJDB" remote scene --server "$ADDRESS" --session session_1 --completed \
  --out "$(dirname "$DB")/session_1_completed.ply"
kill -TERM "$SERVER_PID"
wait "$SERVER_PID"
trap - EXIT
echo
# The file the server left behind, read offline.
"$OBJDB" db check --db "$DB"
"$OBJDB" db stats --db "$DB"
