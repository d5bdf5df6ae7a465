#!/usr/bin/env bash
# Installs the Debian packages objdb needs, skipping the ones already present.
#   scripts/deps.sh [--build-only] [EXTRA_PACKAGE...]
# --build-only: what building objdb-server and objdb needs (docker/Dockerfile's build stage), not
# the test and benchmark packages (PostgreSQL, GoogleTest, Python, Chromium).
# Extra packages may be given as arguments (scripts/peer_bench.sh: libopen3d-dev). postgresql is
# the server the PostgreSQL tests start their own throwaway cluster with (scripts/pg_test_cluster.sh);
# the python3 packages are the Python client's (client/python) and its tests'; libcpp-httplib-dev
# and libjs-three are `objdb web`'s, chromium, chromium-driver and python3-selenium its
# browser test's.
# Safe to run repeatedly; a second run with everything installed takes well under a second.
set -euo pipefail

BUILD_PACKAGES=(
  build-essential cmake ninja-build pkg-config git
  libgrpc++-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler libabsl-dev
  libpcl-dev libflann-dev liblz4-dev libopencv-dev libeigen3-dev libfaiss-dev
  libsqlite3-dev libzstd-dev zlib1g-dev
  libpq-dev
  libspdlog-dev libfmt-dev nlohmann-json3-dev
  openssl libssl-dev libcpp-httplib-dev libjs-three
)
TEST_PACKAGES=(
  postgresql
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-grpcio python3-protobuf python3-numpy python3-pytest python3-yaml
  chromium chromium-driver python3-selenium
)
PACKAGES=("${BUILD_PACKAGES[@]}")
if [[ "${1:-}" == "--build-only" ]]; then
  shift
else
  PACKAGES+=("${TEST_PACKAGES[@]}")
fi
PACKAGES+=("$@")

missing=()
for p in "${PACKAGES[@]}"; do
  status=$(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true)
  [[ "$status" == "installed" ]] || missing+=("$p")
done

if [[ ${#missing[@]} -eq 0 ]]; then
  exit 0
fi

echo "objdb: installing ${#missing[@]} missing Debian packages: ${missing[*]}"
SUDO=""
if [[ $(id -u) -ne 0 ]]; then
  command -v sudo >/dev/null || { echo "objdb: need root or sudo to install packages" >&2; exit 1; }
  SUDO=sudo
fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -q
$SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
