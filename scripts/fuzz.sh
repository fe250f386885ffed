#!/usr/bin/env bash
# Runs each libFuzzer harness for a bounded time (default 60 s each) with its seed corpus in
# tests/fuzz/corpus/NAME; new crashes are written to build-fuzz/crashes/. Needs clang and
# libclang-rt-14-dev (scripts/setup.sh installs them). Usage: scripts/fuzz.sh [SECONDS] [NAME...]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
secs=${1:-60}
shift || true
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(fuzz_obj fuzz_cli fuzz_ply)
# only the harnesses that exist
have=(); for n in "${names[@]}"; do [ -f "tests/fuzz/$n.c" ] && have+=("$n"); done; names=("${have[@]}")
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBOUNCE_FUZZ=ON \
  -DBOUNCE_BUILD_TESTS=OFF -DBOUNCE_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target "${names[@]}"
mkdir -p build-fuzz/crashes
export ASAN_OPTIONS="detect_leaks=1"
export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0"
for n in "${names[@]}"; do
  [ -x "build-fuzz/tests/fuzz/$n" ] || { echo "fuzz: no harness $n" >&2; continue; }
  work=build-fuzz/corpus-$n
  mkdir -p "$work"
  echo "== $n for ${secs}s" >&2
  "build-fuzz/tests/fuzz/$n" "$work" "tests/fuzz/corpus/${n#fuzz_}" -max_total_time="$secs" -timeout=10 \
    -artifact_prefix=build-fuzz/crashes/ -print_final_stats=1 2>&1 | grep -E "stat::number_of_executed_units|stat::average_exec_per_sec|ERROR|SUMMARY|Done" || true
done
ls build-fuzz/crashes
