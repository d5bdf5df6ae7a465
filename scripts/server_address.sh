# Sourced by the scripts that start objdb-server in the background (bash): the binaries of
# $BUILD_DIR (default build), and the wait for a server's address.
BUILD_DIR=${BUILD_DIR:-build}
OBJDB="$BUILD_DIR/bin/objdb"
SERVER="$BUILD_DIR/bin/objdb-server"

# wait_for_address PID LOG: prints the address the server logged ("listening on HOST:PORT") once
# it did; exits the script, with the log on stderr, when the server ends first or within 60 s.
wait_for_address() {
  local pid=$1 log=$2 address=""
  for _ in $(seq 1 600); do
    address=$(sed -n 's/.*listening on \([0-9.]*:[0-9]*\).*/\1/p' "$log" | head -n 1)
    [[ -n $address ]] && { echo "$address"; return 0; }
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  echo "objdb-server did not start:" >&2
  cat "$log" >&2
  exit 1
}
