#!/usr/bin/env bash
# A throwaway PostgreSQL cluster for tests (CTest fixture postgres_cluster, tests/CMakeLists.txt).
#   scripts/pg_test_cluster.sh start DIR   fresh cluster in /tmp/objdb-pg.XXXXXX; writes DIR/uri, DIR/datadir
#   scripts/pg_test_cluster.sh stop DIR    stops it and deletes its temp dir (harmless if none runs)
#   scripts/pg_test_cluster.sh uri DIR     prints its libpq URI
# The server listens on a Unix socket in its private temp dir only (no TCP), trusts every local
# user as role `objdb` and runs without fsync: test data only. Under root the server runs as the
# `postgres` user (initdb and postgres refuse root). Needs the Debian package postgresql.
set -euo pipefail

usage() {
  sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
}
die() {
  echo "pg_test_cluster: $*" >&2
  exit 1
}

[[ $# -eq 2 ]] || usage
action=$1
state_dir=$2
tmp=""  # the cluster's temp dir: socket, log, data/

# The newest installed server (Debian: /usr/lib/postgresql/N/bin), else pg_config's bindir.
find_bindir() {
  local dir best="" best_version=0 version
  for dir in /usr/lib/postgresql/*/bin; do
    [[ -x "$dir/initdb" ]] || continue
    version=$(basename "$(dirname "$dir")")
    [[ $version =~ ^[0-9]+$ ]] || continue
    if ((version > best_version)); then
      best=$dir
      best_version=$version
    fi
  done
  if [[ -z $best ]] && command -v pg_config >/dev/null; then
    dir=$(pg_config --bindir)
    if [[ -x "$dir/initdb" ]]; then best=$dir; fi
  fi
  [[ -n $best ]] || die "no PostgreSQL server binaries (initdb) found: install the Debian package" \
    "postgresql (scripts/deps.sh does)"
  echo "$best"
}

# Runs a command as the cluster's owner: as that user when we are root, else as ourselves, from
# the temp dir (root's working directory may be closed to the owner). fd 9 holds the state dir
# lock: the server must not inherit it.
as_owner() {
  local owner=$1
  shift
  if [[ $(id -u) -eq 0 ]]; then
    (cd "$tmp" && runuser -u "$owner" -- "$@") 9>&-
  else
    (cd "$tmp" && "$@") 9>&-
  fi
}

# The unprivileged user a root invocation runs the server as.
server_user() {
  if id -u postgres >/dev/null 2>&1; then
    echo postgres
    return
  fi
  if ! id -u objdb-pg >/dev/null 2>&1; then
    useradd --system --no-create-home --home-dir /nonexistent --shell /usr/sbin/nologin objdb-pg \
      || die "cannot create the system user objdb-pg to run PostgreSQL as"
  fi
  echo objdb-pg
}

stop_cluster() {
  local recorded="$state_dir/datadir"
  [[ -f $recorded ]] || return 0
  tmp=$(<"$recorded")
  # Only ever delete what start created: a temp dir of our own naming.
  [[ $tmp =~ ^/tmp/objdb-pg\.[A-Za-z0-9]+$ ]] || die "$recorded names '$tmp', not a test" \
    "cluster's temp dir (/tmp/objdb-pg.*): remove $recorded by hand"
  if [[ -f "$tmp/data/postmaster.pid" ]]; then
    local owner bindir
    owner=$(stat -c %U "$tmp/data")
    bindir=$(find_bindir)
    # Fast shutdown ends open sessions; immediate is the fallback for a server that hangs.
    as_owner "$owner" "$bindir/pg_ctl" stop -D "$tmp/data" -m fast -w -t 30 >/dev/null 2>&1 ||
      as_owner "$owner" "$bindir/pg_ctl" stop -D "$tmp/data" -m immediate -w -t 30 \
        >/dev/null 2>&1 || true
    # pg_ctl status exits 0 while a server runs on the data dir.
    if as_owner "$owner" "$bindir/pg_ctl" status -D "$tmp/data" >/dev/null 2>&1; then
      die "cannot stop the PostgreSQL server in $tmp/data (log: $tmp/postgres.log)"
    fi
  fi
  rm -rf "$tmp"
  rm -f "$state_dir/uri" "$state_dir/datadir"
  echo "pg_test_cluster: stopped the test cluster in $tmp"
}

# Shows the end of a log, removes the half-started cluster and exits with an error.
fail_start() {
  local log=$1
  shift
  echo "--- $log (last 20 lines)" >&2
  tail -n 20 "$log" >&2 || true
  stop_cluster >/dev/null || true
  die "$@"
}

start_cluster() {
  stop_cluster
  local bindir owner port uri log
  bindir=$(find_bindir)
  tmp=$(mktemp -d /tmp/objdb-pg.XXXXXX)
  # Recorded at once, so that a start killed half-way is cleaned up by the next stop or start.
  echo "$tmp" >"$state_dir/datadir"
  # Open to all, so clients of any user reach the socket; initdb makes data/ 0700.
  chmod 755 "$tmp"
  owner=$(id -un)
  if [[ $(id -u) -eq 0 ]]; then
    owner=$(server_user)
    chown "$owner:" "$tmp"
  fi
  # The socket dir is private, so any port works; a random one keeps the socket's name apart
  # from the system cluster's (5432) when someone points a tool at the wrong place.
  port=$((20000 + RANDOM % 20000))
  log="$tmp/postgres.log"

  as_owner "$owner" "$bindir/initdb" -D "$tmp/data" --auth=trust -U objdb -E UTF8 --locale=C \
    --no-sync >"$tmp/initdb.log" 2>&1 || fail_start "$tmp/initdb.log" "initdb failed (output above)"
  printf '%s\n' "" \
    "# pg_test_cluster.sh: a Unix socket in the private temp dir only; no durability (test data)." \
    "listen_addresses = ''" \
    "unix_socket_directories = '$tmp'" \
    "port = $port" \
    "fsync = off" \
    "synchronous_commit = off" \
    "full_page_writes = off" >>"$tmp/data/postgresql.conf"
  as_owner "$owner" "$bindir/pg_ctl" start -D "$tmp/data" -l "$log" -w -t 60 >/dev/null 2>&1 ||
    fail_start "$log" "the PostgreSQL server did not start (log above; pg_ctl waits up to 60 s)"

  uri="postgresql://objdb@/postgres?host=$tmp&port=$port"
  # pg_ctl -w waited for the server; this checks the URI itself, from this (maybe root) process.
  local i
  for ((i = 0; i < 50; i++)); do
    if "$bindir/psql" "$uri" -XAtqc 'SELECT 1' >/dev/null 2>&1; then break; fi
    sleep 0.1
  done
  ((i < 50)) || fail_start "$log" "the server runs but $uri refuses connections (log above)"

  # Written last and atomically: a uri file means a running cluster.
  echo "$uri" >"$state_dir/uri.new"
  mv "$state_dir/uri.new" "$state_dir/uri"
  echo "pg_test_cluster: PostgreSQL $("$bindir/postgres" -V | awk '{print $3}') as $owner," \
    "socket $tmp/.s.PGSQL.$port, data $tmp/data: $uri"
}

case $action in
  start | stop)
    mkdir -p "$state_dir"
    state_dir=$(cd "$state_dir" && pwd)
    # One start or stop at a time per DIR (say, two ctest runs in one build folder).
    exec 9>"$state_dir/.lock"
    flock 9
    "${action}_cluster"
    ;;
  uri)
    [[ -f "$state_dir/uri" ]] || die "no test cluster in $state_dir: run $0 start $state_dir"
    cat "$state_dir/uri"
    ;;
  *) usage ;;
esac
