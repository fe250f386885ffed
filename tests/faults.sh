#!/usr/bin/env bash
# Faults from outside: a file-size limit (ulimit -f), a full and a read-only directory (small
# tmpfs mounts, as root; skipped visibly otherwise), too little address space (ulimit -v) at
# meshing, form factors and the gather, and SIGTERM during meshing, form factors, refinement and the
# gather. Refinement and the bake under too little address space, and the bake and a commit
# interrupted, are in test_faults.c (in-process: no command-line limit singles those stages out).
# Each must end with a clear message, the right exit code and no file left behind (no output, no
# temporary). ulimit -v runs only in the normal build: ASan reserves terabytes of address space.
# Two parts, two tests: "files" (the limits and the directories) runs beside other tests; "signals"
# (SIGTERM) alone, since each row's 5 s allowance to stop should time bounce, not the machine's load.
# usage: faults.sh BOUNCE SOURCE_DIR WORK_DIR files|signals [asan]
set -u
exe=$1 src=$2 work=$3 part=$4 asan=${5:-}
cornell="$src/meshes/cornell-box.obj"
fails=0 passes=0 skips=0
rm -rf "$work" && mkdir -p "$work"

ok() { passes=$((passes + 1)); echo "ok   $*"; }
bad() { fails=$((fails + 1)); echo "FAIL $*"; }
skip() { skips=$((skips + 1)); echo "SKIP $*"; }

# expect DIR CODE NEEDLE LABEL -- CMD...: exit CODE, NEEDLE in stderr, DIR empty afterwards
expect() {
  local dir=$1 code=$2 needle=$3 label=$4 rc left
  shift 5
  (cd "$dir" && "$@" >/dev/null 2>"$work/err")
  rc=$?
  left=$(ls -A "$dir")
  if [ "$rc" != "$code" ]; then bad "$label: exit $rc, expected $code: $(tail -1 "$work/err")"
  elif ! grep -q -- "$needle" "$work/err"; then bad "$label: no '$needle' in: $(tail -1 "$work/err")"
  elif [ -n "$left" ]; then bad "$label: left behind: $left"
  else ok "$label: exit $code, $(grep error "$work/err" | tail -1)"
  fi
  rm -rf "${dir:?}"/* "$dir"/.[!.]* 2>/dev/null
}

small="--unit mm --patches 100 --ff-visibility rays -q"
writers() {   # DIR CODE NEEDLE-PREFIX WRAP...: every writer in DIR
  local dir=$1 code=$2 why=$3
  shift 3
  expect "$dir" "$code" "big.csv" "$why: patch CSV" -- "$@" "$exe" solve "$cornell" $small -o big.csv
  expect "$dir" "$code" "img.exr" "$why: EXR" -- "$@" "$exe" bounces "$cornell" $small --size 32x32 -o img.exr
  # the bakes' patch means (--gather none): the writers are what is tested (a gathered bake of these 100
  # large patches takes 1.6 s, five times that under the sanitizers; the gathered bake's own faults are test_faults.c's)
  expect "$dir" "$code" "b.ply" "$why: PLY" -- "$@" "$exe" bake "$cornell" $small --gather none -o b.ply
  expect "$dir" "$code" "b.glb" "$why: glTF" -- "$@" "$exe" bake "$cornell" $small --gather none -o b.glb
}

files() {
# 1. ulimit -f 2 (KiB; every output here is 5 KiB or more): the write fails with EFBIG (SIGXFSZ is
# ignored), exit 3
mkdir -p "$work/fsize"
writers "$work/fsize" 3 "ulimit -f" bash -c 'ulimit -f 2 && exec "$@"' sh

# 2. a full directory and a read-only one: one-page (4 KiB) tmpfs mounts
for kind in full ro; do
  d="$work/$kind"
  mkdir -p "$d"
  opts="size=4k"
  [ $kind = ro ] && opts="ro,size=4k"
  if [ "$(id -u)" = 0 ] && mount -t tmpfs -o "$opts" tmpfs "$d" 2>/dev/null; then
    writers "$d" 3 "$kind directory"
    umount "$d"
  else
    skip "$kind directory: needs root and a tmpfs mount (mount -t tmpfs -o $opts)"
  fi
done

# 3. ulimit -v 2 GB: each stage's allocation refused with exit 4 (normal build only)
if [ -z "$asan" ]; then
  mkdir -p "$work/vm"
  vm() { bash -c 'ulimit -v 2000000 && exec "$@"' sh "$@"; }
  expect "$work/vm" 4 "out of memory for" "ulimit -v: meshing 3e7 patches" -- vm "$exe" info "$cornell" --unit mm --patches 30000000 -q
  expect "$work/vm" 4 "cannot allocate dense F" "ulimit -v: dense F of 20000 patches" -- vm "$exe" solve "$cornell" --unit mm --patches 20000 --transport dense --ff-visibility rays -o x.csv -q
  expect "$work/vm" 4 "6000x6000 image" "ulimit -v: gather images" -- vm "$exe" bounces "$cornell" $small --size 6000x6000 -o g.exr
else
  skip "ulimit -v: not under AddressSanitizer (it reserves terabytes of address space)"
fi
}

# 4. SIGTERM in a stage: exit 143 within 5 s of the signal, nothing left. The signal goes once the
# log names the line before the stage (the load's warning, the contact cuts, the camera) and a moment
# more has passed: under load a fixed sleep from the start may land in an earlier stage.
term() {   # MARKER STAGE LABEL CMD...: STAGE, the stage the error must name
  local marker=$1 stage=$2 label=$3 pid rc t0 t1 left
  shift 3
  mkdir -p "$work/term" && cd "$work/term" || return
  : >"$work/err"
  "$@" >/dev/null 2>"$work/err" &
  pid=$!
  for _ in $(seq 600); do
    grep -q -- "$marker" "$work/err" && break
    kill -0 $pid 2>/dev/null || break
    sleep 0.1
  done
  sleep "$moment"
  if ! kill -0 $pid 2>/dev/null; then wait $pid; bad "$label: ended (exit $?) before the signal"; cd "$work"; return; fi
  t0=$(date +%s.%N)
  kill -TERM $pid
  wait $pid
  rc=$?
  t1=$(date +%s.%N)
  cd "$work" || return
  left=$(ls -A "$work/term")
  rm -rf "$work/term"
  if [ $rc != 143 ]; then bad "$label: exit $rc, expected 143"
  elif awk -v a="$t0" -v b="$t1" 'BEGIN { exit !(b - a > 5) }'; then bad "$label: took over 5 s to stop"
  elif [ -n "$left" ]; then bad "$label: left behind: $left"
  elif ! grep -q "error: $stage interrupted" "$work/err"; then
    bad "$label: not '$stage interrupted': $(grep -m1 error: "$work/err")"
  else ok "$label: exit 143 in $(awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }') s, $stage"
  fi
}
signals() {
moment=0.5
[ -n "$asan" ] && moment=1.5
local verbose="--unit mm --patches 100 --ff-visibility rays"
term "non-planar" meshing "SIGTERM while meshing (2e6 patches, contact cuts)" \
  "$exe" info "$cornell" --unit mm --patches 2000000
term "contact lines" "form-factor assembly" "SIGTERM in the form factors (dense, exact visibility)" \
  "$exe" solve "$cornell" --unit mm --patches 4000 --transport dense -o f.csv
term "contact lines" "hierarchy refinement" "SIGTERM while refining the hierarchy" \
  "$exe" bounces "$cornell" --unit mm --transport hierarchical --eps 1e-6 --ff-visibility rays --size 64x64 -o h.exr
term "camera:" gather "SIGTERM in the gather" \
  "$exe" bounces "$cornell" $verbose --size 1024x1024 --spp 16 -o g.exr
term "left out of the vertex averages" "gather at points:" "SIGTERM in the bake's gather at its vertices" \
  "$exe" bake "$cornell" --unit mm --patches 20000 --transport hierarchical --ff-visibility rays -o b.glb
}

case $part in
  files | signals) "$part" ;;
  *) echo "faults.sh: part must be files or signals, not '$part'"; exit 2 ;;
esac

echo "$passes passed, $fails failed, $skips skipped"
[ $fails = 0 ]
