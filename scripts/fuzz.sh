#!/usr/bin/env bash
# Runs each libFuzzer harness for a bounded time (default 60 s each) with its seed corpus in
# tests/fuzz/corpus/NAME; new crashes are written to build-fuzz/crashes/. Needs clang and
# libclang-rt-14-dev (scripts/setup.sh installs them). Usage: scripts/fuzz.sh [SECONDS] [NAME...]
# FUZZ_RUNS=N also stops each harness after N executions (the depth run: FUZZ_RUNS=10000000
# scripts/fuzz.sh 3600, 1e7 executions or an hour each, whichever comes first). The last lines are
# a markdown table: executions, rate, coverage (libFuzzer's cov/ft) and crashes per harness.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
secs=${1:-60}
shift || true
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(fuzz_obj fuzz_cli fuzz_ply fuzz_camera fuzz_glb fuzz_gltf)
runs=${FUZZ_RUNS:--1}
# only the harnesses that exist, built with clang (7c0e909 dropped these lines: the script ran whatever
# build-fuzz/ held, and nothing on a fresh clone)
have=(); for n in "${names[@]}"; do [ -f "tests/fuzz/$n.c" ] && have+=("$n"); done; names=("${have[@]}")
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DBOUNCE_FUZZ=ON \
  -DBOUNCE_BUILD_TESTS=OFF -DBOUNCE_BUILD_BENCH=OFF >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target "${names[@]}"
mkdir -p build-fuzz/crashes
export ASAN_OPTIONS="detect_leaks=1"
# undefined behaviour stops the run and counts as a crash (UBSan recovers and only prints by default: a
# null-pointer offset in the glTF reader went by so once)
export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1"
export LSAN_OPTIONS="suppressions=$PWD/tests/lsan.supp:print_suppressions=0"
table="| harness | executions | exec/s | cov | ft | corpus | crashes |
|---|---|---|---|---|---|---|"
for n in "${names[@]}"; do
  [ -x "build-fuzz/tests/fuzz/$n" ] || { echo "fuzz: no harness $n" >&2; continue; }
  work=build-fuzz/corpus-$n
  mkdir -p "$work" "build-fuzz/crashes/$n"
  echo "== $n for ${secs}s (runs: $runs)" >&2
  "build-fuzz/tests/fuzz/$n" "$work" "tests/fuzz/corpus/${n#fuzz_}" -max_total_time="$secs" -runs="$runs" -timeout=10 \
    -artifact_prefix="build-fuzz/crashes/$n/" -print_final_stats=1 >"build-fuzz/$n.log" 2>&1 || true
  grep -E "stat::number_of_executed_units|stat::average_exec_per_sec|ERROR|SUMMARY|Done" "build-fuzz/$n.log" || true
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "build-fuzz/$n.log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "build-fuzz/$n.log" | tail -1)
  cov=$(grep -oE 'cov: [0-9]+' "build-fuzz/$n.log" | tail -1 | cut -d' ' -f2)
  ft=$(grep -oE 'ft: [0-9]+' "build-fuzz/$n.log" | tail -1 | cut -d' ' -f2)
  corp=$(grep -oE 'corp: [0-9]+' "build-fuzz/$n.log" | tail -1 | cut -d' ' -f2)
  table="$table
| $n | ${execs:-?} | ${rate:-?} | ${cov:-?} | ${ft:-?} | ${corp:-?} | $(ls "build-fuzz/crashes/$n" | wc -l) |"
done
echo "$table"
ls build-fuzz/crashes/*
