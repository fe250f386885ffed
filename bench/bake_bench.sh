#!/bin/bash
# Bakes of large scenes (issue 36), as a user runs them: `bounce bake SCENE --per-bounce -o X.glb` with the
# defaults (the gathered, refined bake at the default vertex budget), and with --gather none (the patch
# means) for comparison: wall time, peak memory, vertices, and each bake's per-vertex relative error of L
# and K2E against `bounce trace --points` at a sample of its vertices (65,536 paths a point, the tracer's
# variance subtracted; tests/bake_gather_check.py's measure; with 4,096 the reference's own noise read as
# about a fifth of the bunny box's 95th percentile of L: 6.25% against 5.10%). Markdown rows on stdout.
#
# usage: bench/bake_bench.sh BOUNCE SCENE UNIT WORKDIR [EVERY]
#   EVERY: every EVERY-th vertex is measured (default 40)
set -u
bounce=$1 scene=$2 unit=$3 work=$4 every=${5:-40}
root=$(cd "$(dirname "$0")/.." && pwd)
name=$(basename "$scene" .obj)
mkdir -p "$work"
echo "| scene | bake | wall s | peak MiB | vertices | L median | L 95th | K2E median | K2E 95th | points |"
echo "|---|---|---|---|---|---|---|---|---|---|"
for mode in final none; do
    glb="$work/$name-$mode.glb"
    t0=$(date +%s.%N)
    /usr/bin/time -v "$bounce" bake "$scene" --unit "$unit" --per-bounce --gather "$mode" -o "$glb" \
        >"$work/$name-$mode.out" 2>"$work/$name-$mode.err"
    rc=$?
    t1=$(date +%s.%N)
    peak=$(sed -n 's/.*Maximum resident set size (kbytes): //p' "$work/$name-$mode.err" | awk '{ printf "%.0f", $1 / 1024 }')
    verts=$(sed -n 's/.*: \([0-9]*\) vertices, .*/\1/p' "$work/$name-$mode.out" | head -1)
    label=$([ "$mode" = final ] && echo "gathered, refined (the defaults)" || echo "patch means (--gather none)")
    if [ "$rc" != 0 ]; then
        echo "| $name | $label | failed (exit $rc: $(tail -1 "$work/$name-$mode.err")) | | | | | | | |"
        continue
    fi
    errs=$(python3 - "$bounce" "$scene" "$glb" "$work" "$every" "$unit" "$root" <<'PY'
import sys
sys.path.insert(0, sys.argv[7] + "/tests")
import bake_gather_check as B
bounce, scene, glb, work, every, unit = sys.argv[1:7]
_, _, used, _ = B.vertices(glb)
e = B.errors(bounce, scene, glb, work, 65536, int(every), unit)
print("%.2f%% | %.2f%% | %.2f%% | %.2f%% | %d" % (100 * e["L"][0], 100 * e["L"][1], 100 * e["K2E"][0], 100 * e["K2E"][1],
                                                len(used[::int(every)])))
PY
)
    echo "| $name | $label | $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.0f", b - a }') | $peak | $verts | $errs |"
done
