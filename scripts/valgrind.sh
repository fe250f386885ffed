#!/usr/bin/env bash
# valgrind memcheck over every subcommand on a small scene: reports invalid accesses and
# definite or indirect leaks of ours; exits non-zero if any. Usage: scripts/valgrind.sh [BUILD_DIR]
# libgomp's and TBB's thread stacks are kept for the process's life ("possibly lost", not errors).
set -euo pipefail
cd "$(dirname "$0")/.."
B=${1:-build}
command -v valgrind >/dev/null || { echo "valgrind: not installed (apt-get install valgrind)" >&2; exit 1; }
[ -x "$B/bounce" ] || { echo "valgrind: build $B first" >&2; exit 1; }
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
# Embree and OpenBLAS pick their instruction set from CPUID at run time, and valgrind's CPUID
# shows only what it emulates, so both stay within it. Should one not, pin them: e.g.
# BOUNCE_EMBREE_CONFIG=isa=sse4.2 OPENBLAS_CORETYPE=Haswell scripts/valgrind.sh
VG=(valgrind --error-exitcode=42 --leak-check=full --errors-for-leak-kinds=definite,indirect
    --suppressions=tests/valgrind.supp -q)
S=meshes/cornell-box.obj
P=(--unit mm --patches 60 -q --threads 2)
fail=0
run() {
  echo "== bounce $*" >&2
  if ! "${VG[@]}" "$B/bounce" "$@" >/dev/null; then
    echo "valgrind: FAILED: bounce $*" >&2
    fail=1
  fi
}
run info "$S" "${P[@]}"
run formfactors "$S" "${P[@]}" -o "$T/F.csv"
for m in jacobi gauss-seidel neumann direct; do
  run solve "$S" "${P[@]}" --method $m -n 2 --log "$T/conv.csv" -o "$T/p.csv"
done
run bounces "$S" "${P[@]}" -n 2 --size 64x64 -o "$T/b.exr"
run bake "$S" "${P[@]}" -o "$T/b.ply"
run bake "$S" "${P[@]}" -o "$T/b.obj"
run trace "$S" "${P[@]}" --spp 4 --size 32x32 -n 2 -o "$T/t.exr" --patches-out "$T/t.csv"
run crosscheck meshes/furnace-box.obj --patches 24 --spp 16 -n 1 -q --threads 2
run study "$S" "${P[@]}" --vary bounces=0,1,2 -o "$T/s.csv"
[ $fail -eq 0 ] && echo "valgrind: no errors of ours in any subcommand" >&2
exit $fail
