#!/usr/bin/env bash
# Races under ThreadSanitizer, on a reduced concurrent load: builds the concurrency tests in
# build-tsan (GCC, -fsanitize=thread) and runs them; a failing test or a race report in our code
# fails the script. Not part of CI: a first build takes ~10 min on two cores, and the database's
# PCL work runs 30-100x slower instrumented, so object_database_service_test takes over an hour
# (its reduced concurrency test fails its stretched deadlines under TSan; docs/server.md, "Races").
#   scripts/tsan.sh [gtest filter]     default: every test of the three binaries
# Only our code is instrumented. Debian's gRPC, protobuf, abseil and libgomp are not, so TSan
# reports thousands of races it cannot see the synchronisation of; scripts/tsan_triage.py sorts
# them (its docstring says how) and prints only those left for us. Logs: build-tsan/tsan-*.log.
set -euo pipefail
cd "$(dirname "$0")/.."
filter=${1:-*}

bash scripts/deps.sh
command -v python3 >/dev/null || {
  SUDO=""; [[ $(id -u) -eq 0 ]] || SUDO=sudo
  $SUDO apt-get update -q && $SUDO apt-get install -y -q --no-install-recommends python3
}
BUILD_DIR=build-tsan
if [[ ! -f "$BUILD_DIR/build.ninja" ]]; then
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DOBJDB_TSAN=ON \
    -DCMAKE_C_COMPILER=gcc -DCMAKE_CXX_COMPILER=g++ \
    -DOBJDB_BUILD_BENCH=OFF >/dev/null
fi
tests=(storage_concurrency_test server_test object_database_service_test)
cmake --build "$BUILD_DIR" -j "$(nproc)" --target "${tests[@]}"

export TSAN_OPTIONS="halt_on_error=0 exitcode=0 history_size=4"
export OBJDB_DEADLINE_SCALE=10  # the instrumented build is ~10x slower: test deadlines stretch
status=0
for t in "${tests[@]}"; do
  log="$BUILD_DIR/tsan-$t.log"
  echo "== $t (log: $log)"
  # Kernels with 32 bits of mmap randomness break GCC 12's TSan runtime ("unexpected memory
  # mapping"); without address randomisation it runs.
  if ! setarch "$(uname -m)" -R "$BUILD_DIR/bin/$t" --gtest_filter="$filter" >"$log" 2>&1; then
    grep -E "^\[  FAILED  \]|Failure$" "$log" || true
    echo "== $t: a test FAILED"
    status=1
  fi
  grep -E "^\[  PASSED  \]" "$log" || true
  python3 scripts/tsan_triage.py "$(pwd -P)" "$log" || status=1
done
exit $status
