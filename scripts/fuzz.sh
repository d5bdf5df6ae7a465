#!/usr/bin/env bash
# Fuzzes the decoders that read outside bytes (docs/fuzzing.md) with libFuzzer under ASan and
# UBSan, then minimises the corpus into tests/fuzz/corpus/TARGET (committed; corpus_replay_test
# replays it on every test run). Not part of CI: it takes SECONDS per target (default 600).
#   scripts/fuzz.sh [SECONDS] [TARGET...]      TARGET: frame blob config (default all)
# Needs clang (installed here: clang, libclang-rt-dev). A crash leaves its input in
# build-fuzz/crashes/TARGET; once fixed, add it to tests/fuzz/regressions/TARGET under a name
# that says what it found (the minimisation never touches that folder).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=600
if [[ $# -gt 0 && $1 =~ ^[0-9]+$ ]]; then
  seconds=$1
  shift
fi
targets=("$@")
[[ ${#targets[@]} -gt 0 ]] || targets=(frame blob config)

bash scripts/deps.sh
missing=()
for p in clang libclang-rt-dev; do
  [[ "$(dpkg-query -W -f='${db:Status-Status}' "$p" 2>/dev/null || true)" == installed ]] || missing+=("$p")
done
if [[ ${#missing[@]} -gt 0 ]]; then
  SUDO=""; [[ $(id -u) -eq 0 ]] || SUDO=sudo
  $SUDO apt-get update -q && $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
fi

cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DOBJDB_SANITIZE=ON -DOBJDB_FUZZ=ON -DOBJDB_BUILD_BENCH=OFF >/dev/null
ninja -C build-fuzz fuzz_seeds $(printf 'fuzz_%s ' "${targets[@]}")

work=build-fuzz/work
rm -rf "$work/seeds" && build-fuzz/bin/fuzz_seeds "$work/seeds"
for t in "${targets[@]}"; do
  mkdir -p "$work/corpus/$t" "build-fuzz/crashes/$t" "tests/fuzz/corpus/$t"
  echo "== fuzz_$t for ${seconds}s"
  # ASan's leak check and UBSan reports abort the run: every finding is a crash input.
  # No allocation may reach 256 MB. The process limit is higher: under ASan the binary starts at
  # ~175 MB (shadow memory, libraries) and the in-memory corpus grows. A smaller ASan quarantine:
  # freed memory it holds back counts against the RSS limit.
  ASAN_OPTIONS=quarantine_size_mb=16 UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
    build-fuzz/bin/fuzz_"$t" "$work/corpus/$t" "$work/seeds/$t" "tests/fuzz/corpus/$t" \
      "tests/fuzz/regressions/$t" \
      -max_total_time="$seconds" -timeout=1 -malloc_limit_mb=256 -rss_limit_mb=512 \
      -max_len=32768 \
      -artifact_prefix="build-fuzz/crashes/$t/" -print_final_stats=1 > "build-fuzz/crashes/$t/log" 2>&1 ||
    { tail -n 60 "build-fuzz/crashes/$t/log"
      echo "fuzz_$t found a problem: input and report in build-fuzz/crashes/$t/" >&2
      exit 1; }
  tail -n 8 "build-fuzz/crashes/$t/log"
  # Minimise into the committed corpus (merge keeps one input per new coverage feature).
  rm -rf "$work/min/$t" && mkdir -p "$work/min/$t"
  ASAN_OPTIONS=quarantine_size_mb=16 build-fuzz/bin/fuzz_"$t" -merge=1 "$work/min/$t" "tests/fuzz/corpus/$t" "$work/seeds/$t" \
    "$work/corpus/$t" 2>&1 | tail -n 1
  rm -rf "tests/fuzz/corpus/$t" && mv "$work/min/$t" "tests/fuzz/corpus/$t"
  echo "tests/fuzz/corpus/$t: $(ls "tests/fuzz/corpus/$t" | wc -l) inputs"
done
