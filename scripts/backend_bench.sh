#!/usr/bin/env bash
# The lounge through one objdb-server on SQLite and on PostgreSQL, in one run (the
# overhead target: PostgreSQL within 1.5x of SQLite). Both are durable: SQLite synchronous=FULL
# (the default), PostgreSQL fsync, full_page_writes and synchronous_commit on, on a throwaway
# cluster (scripts/pg_test_cluster.sh) in /tmp. Prints the wall time of `objdb stream` (every
# session streamed and ended) and the database stage from GetStats, per backend, and the ratio.
# Usage: [REPEATS=2] scripts/backend_bench.sh [DATASET]   (default data/lounge, generated when
# missing); each repeat runs both backends, in alternating order.
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/server_address.sh  # OBJDB, SERVER, wait_for_address
DATASET=${1:-data/lounge}
REPEATS=${REPEATS:-2}
[[ -x $OBJDB && -x $SERVER ]] || { echo "build first: scripts/build.sh" >&2; exit 1; }
if [[ ! -d $DATASET ]]; then
  [[ $DATASET == data/lounge ]] || { echo "no dataset $DATASET" >&2; exit 1; }
  echo "generating the lounge into $DATASET (objdb sim --preset lounge)"
  "$OBJDB" sim --preset lounge --out "$DATASET" --overwrite >/dev/null 2>&1
fi

work=$(mktemp -d /tmp/objdb-backends.XXXXXX)
cluster="$work/cluster"
mkdir -p "$cluster"
cleanup() {
  [[ -n ${SERVER_PID:-} ]] && kill -TERM "$SERVER_PID" 2>/dev/null || true
  bash scripts/pg_test_cluster.sh stop "$cluster" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT
bash scripts/pg_test_cluster.sh start "$cluster" >/dev/null
base_uri=$(<"$cluster/uri")
psql "$base_uri" -XAtq -c "ALTER SYSTEM SET fsync = on" -c "ALTER SYSTEM SET full_page_writes = on" \
  -c "ALTER SYSTEM SET synchronous_commit = on" -c "SELECT pg_reload_conf()" >/dev/null
pg_uri=${base_uri/\/postgres\?/\/objdb_bench?}

# Runs the dataset through a server on $1; prints "stream_s db_s inserts writer_wait_s
# writer_hold_s" (the last: the time under the writer lock, the part serial across servers).
run() {
  local db=$1 log="$work/server.log" address=""
  "$SERVER" --listen 127.0.0.1:0 --db "$db" >"$log" 2>&1 &
  SERVER_PID=$!
  address=$(wait_for_address "$SERVER_PID" "$log") || exit 1
  local start end
  start=$(date +%s.%N)
  "$OBJDB" stream --server "$address" "$DATASET" >"$work/stream.log" 2>&1 ||
    { cat "$work/stream.log" >&2; exit 1; }
  end=$(date +%s.%N)
  "$OBJDB" remote stats --server "$address" >"$work/stats.txt"
  kill -TERM "$SERVER_PID"
  wait "$SERVER_PID" || true
  SERVER_PID=""
  python3 - "$start" "$end" "$work/stats.txt" <<'PY'
import re, sys
start, end = float(sys.argv[1]), float(sys.argv[2])
m = re.search(r"inserts: (\d+), ([0-9.]+) s in the database stage, ([0-9.]+) s waiting for the "
              r"writer lock, ([0-9.]+) s under it", open(sys.argv[3]).read())
nan = float("nan")
inserts, db, wait, hold = (int(m[1]), float(m[2]), float(m[3]), float(m[4])) if m else (0, nan, nan, nan)
print(f"{end - start:.1f} {db:.1f} {inserts} {wait:.2f} {hold:.1f}")
PY
}

echo "$(basename "$DATASET") through one objdb-server, $(nproc) cores (noisy: compare within a run)"
# Each repeat on a new database of each backend; the order alternates (SQLite first, then
# PostgreSQL first), so that neither always runs on a cold machine.
printf '%-12s %7s %12s %14s %9s %16s %14s\n' backend repeat "stream s" "database s" inserts \
  "writer wait s" "under lock s"
declare -a s_streams=() p_streams=() s_dbs=() p_dbs=()
for ((r = 1; r <= REPEATS; r++)); do
  order=(sqlite postgres)
  ((r % 2 == 0)) && order=(postgres sqlite)
  for backend in "${order[@]}"; do
    if [[ $backend == sqlite ]]; then
      rm -f "$work/objects.sqlite"*
      result=$(run "$work/objects.sqlite")
      label=SQLite
    else
      PGOPTIONS="-c client_min_messages=warning" psql "$base_uri" -XAtq -c "DROP DATABASE IF EXISTS objdb_bench" -c "CREATE DATABASE objdb_bench" >/dev/null
      result=$(run "$pg_uri")
      label=PostgreSQL
    fi
    read -r stream db inserts wait hold <<<"$result"
    printf '%-12s %7d %12s %14s %9s %16s %14s\n' "$label" "$r" "$stream" "$db" "$inserts" "$wait" \
      "$hold"
    if [[ $backend == sqlite ]]; then s_streams+=("$stream"); s_dbs+=("$db"); else p_streams+=("$stream"); p_dbs+=("$db"); fi
  done
done
python3 - "${s_streams[*]}" "${p_streams[*]}" "${s_dbs[*]}" "${p_dbs[*]}" <<'PY'
import sys
s, p, sd, pd = ([float(x) for x in a.split()] for a in sys.argv[1:])
mean = lambda v: sum(v) / len(v)
print(f"PostgreSQL / SQLite, mean of {len(s)} runs each: stream {mean(p) / mean(s):.2f}x, "
      f"database stage {mean(pd) / mean(sd):.2f}x")
PY
