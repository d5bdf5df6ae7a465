#!/usr/bin/env bash
# The server's own protocol on any dataset folders, without ground truth (issue 17; the full
# evaluation with ground truth is still bench/database_eval on the lounge, another protocol):
# starts objdb-server on a fresh database, streams the folders in order (one session each, as
# `objdb stream` does), and prints what the database holds: objects by surface (object, planar,
# structure), the models built from two or more segments, the scene checks and the wall time.
#   bench/stream_eval.sh [--config FILE.json] DATASET...
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BUILD_DIR:-build}/bin
config=()
if [[ "${1:-}" == "--config" ]]; then config=(--config "$2"); shift 2; fi
[[ $# -ge 1 ]] || { echo "usage: bench/stream_eval.sh [--config FILE.json] DATASET..." >&2; exit 2; }
work=$(mktemp -d)
trap 'kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; rm -rf "$work"' EXIT
"$BIN/objdb-server" --listen 127.0.0.1:0 --db "$work/db.sqlite" "${config[@]}" > "$work/server.log" 2>&1 &
pid=$!
for _ in $(seq 100); do
  address=$(grep -o 'listening on [0-9.:]*' "$work/server.log" | awk '{print $3}' || true)
  [[ -n "$address" ]] && break
  sleep 0.1
done
[[ -n "$address" ]] || { cat "$work/server.log" >&2; exit 1; }
start=$(date +%s.%N)
"$BIN/objdb" stream --server "$address" "$@" 2>&1 | grep -E '^session|ended:' || true
end=$(date +%s.%N)
"$BIN/objdb" remote objects --server "$address" > "$work/objects.txt"
"$BIN/objdb" remote stats --server "$address" | tail -1
printf 'objects: %s object, %s planar, %s structure\n' \
  "$(grep -c ' object ' "$work/objects.txt" || true)" "$(grep -c ' planar ' "$work/objects.txt" || true)" \
  "$(grep -c ' structure ' "$work/objects.txt" || true)"
echo "models from >= 2 segments:"
awk 'NR == 1 || ($3 >= 2 && $1 ~ /^[0-9]+$/)' "$work/objects.txt"
awk -v a="$start" -v b="$end" 'BEGIN { printf "streamed and ended in %.1f s\n", b - a }'
