#!/usr/bin/env bash
# Several objdb-servers on one PostgreSQL database, each ingesting a lounge session at the same
# time, then the defined reference order checked: `objdb db replay` inserts every raw segment
# again, in the order its row was created (the order the servers took the writer lock), through
# one database in memory, and compares the models and merges with what the fleet stored.
# The sessions extract their segments only at their end (gsm.extraction_age_frames very large),
# so that every segment is inserted once and its stored version is the one that was inserted:
# then the replay must match exactly. merging.noise_sigmas is 0 on both sides: a raw segment row
# does not keep the session's measured noise scale, which the live insert used.
# The fleet's models are also scored against the lounge's ground truth (objdb report truth).
# Usage: [SERVERS=4] scripts/fleet_bench.sh   (needs the Debian package postgresql; the fourth
# session is the lounge's session_1 rendered with another noise seed, generated when missing)
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/server_address.sh  # OBJDB, SERVER, wait_for_address
SERVERS=${SERVERS:-4}
[[ -x $OBJDB && -x $SERVER ]] || { echo "build first: scripts/build.sh" >&2; exit 1; }
[[ $SERVERS -ge 1 && $SERVERS -le 4 ]] || { echo "SERVERS must be 1..4" >&2; exit 2; }
if [[ ! -d data/lounge ]]; then
  echo "generating the lounge into data/lounge (objdb sim --preset lounge)"
  "$OBJDB" sim --preset lounge --out data/lounge --overwrite >/dev/null 2>&1
fi
if [[ ! -d data/lounge-seed2 ]]; then
  echo "generating the lounge with noise seed 2 into data/lounge-seed2"
  "$OBJDB" sim --preset lounge --seed 2 --out data/lounge-seed2 --overwrite >/dev/null 2>&1
fi

work=$(mktemp -d /tmp/objdb-fleet.XXXXXX)
cluster="$work/cluster"
mkdir -p "$cluster" "$work/sessions"
declare -a PIDS=()
LOGS=${LOGS:-}  # a folder to keep the servers' and streams' logs in
cleanup() {
  for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  bash scripts/pg_test_cluster.sh stop "$cluster" >/dev/null 2>&1 || true
  if [[ -n $LOGS ]]; then mkdir -p "$LOGS" && cp "$work"/*.log "$LOGS"/ 2>/dev/null || true; fi
  rm -rf "$work"
}
trap cleanup EXIT
ln -s "$PWD/data/lounge/session_1" "$work/sessions/session_1"
ln -s "$PWD/data/lounge/session_2" "$work/sessions/session_2"
ln -s "$PWD/data/lounge/session_3" "$work/sessions/session_3"
ln -s "$PWD/data/lounge-seed2/session_1" "$work/sessions/session_4"
# EXTRACT_AT_END=0: the default extraction while streaming (segments may then be re-extracted,
# and the replay is no longer exact; the count of poses without a scene shows what the other
# servers' live maps cost).
if [[ ${EXTRACT_AT_END:-1} == 1 ]]; then
  echo '{"gsm": {"extraction_age_frames": 1000000}}' >"$work/session.json"
else
  echo '{}' >"$work/session.json"
fi
cat >"$work/server.json" <<'JSON'
{"merging": {"noise_sigmas": 0}}
JSON

bash scripts/pg_test_cluster.sh start "$cluster" >/dev/null
base_uri=$(<"$cluster/uri")
uri=${base_uri/\/postgres\?/\/objdb_fleet?}
psql "$base_uri" -XAtq -c "CREATE DATABASE objdb_fleet" >/dev/null

declare -a ADDRESSES=()
for ((s = 1; s <= SERVERS; s++)); do
  log="$work/server$s.log"
  "$SERVER" --listen 127.0.0.1:0 --db "$uri" --config "$work/server.json" \
    --server-id "fleet-$s" --log-level "${LOG_LEVEL:-info}" >"$log" 2>&1 &
  PIDS+=($!)
  address=$(wait_for_address "${PIDS[-1]}" "$log") || exit 1
  ADDRESSES+=("$address")
done

echo "$SERVERS objdb-servers on one PostgreSQL database, 4 lounge sessions streamed at once" \
  "($(nproc) cores)"
start=$(date +%s.%N)
declare -a STREAMS=()
for n in 1 2 3 4; do
  address=${ADDRESSES[$(((n - 1) % SERVERS))]}
  "$OBJDB" stream --server "$address" --params "$work/session.json" \
    "$work/sessions/session_$n" >"$work/stream$n.log" 2>&1 &
  STREAMS+=($!)
done
failed=0
for n in 1 2 3 4; do
  wait "${STREAMS[$((n - 1))]}" || { echo "session_$n failed:" >&2; cat "$work/stream$n.log" >&2; failed=1; }
done
end=$(date +%s.%N)
[[ $failed -eq 0 ]] || exit 1
python3 -c "import sys; print(f'streamed and ended in {float(sys.argv[2]) - float(sys.argv[1]):.1f} s')" \
  "$start" "$end"
for n in 1 2 3 4; do
  grep -E "^  ended:" "$work/stream$n.log" | sed "s/^  /  session_$n /"
done
for ((s = 1; s <= SERVERS; s++)); do
  "$OBJDB" remote stats --server "${ADDRESSES[$((s - 1))]}" |
    sed -n -e "s/^\(inserts: .*\)/  server $s: \1/p" -e "s/^\(.*without a scene.*\)/  server $s: \1/p" \
      -e "s/^\(live maps across .*\)/  server $s: \1/p"
done
for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
for pid in "${PIDS[@]}"; do wait "$pid" 2>/dev/null || true; done
PIDS=()
echo "what the fleet stored, against the lounge's ground truth (objdb report truth):"
"$OBJDB" report truth --db "$uri" $(for n in 1 2 3 4; do echo "session_$n=$work/sessions/session_$n"; done) |
  sed 's/^/  /'
echo "the reference order (objdb db replay):"
"$OBJDB" db replay --db "$uri" --config "$work/server.json"
