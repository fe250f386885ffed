#!/bin/bash
# bounce under mpirun -np 1, 2 and 4 (oversubscribed on small machines) gives one process's bits:
# - bounce trace: every pixel of every layer of the EXR (idiff -fail 0) and every row of the
#   per-patch CSV (the '#' provenance lines record the process count and timings, so they may differ);
# - bounce crosscheck (the tracer split among ranks, the hierarchy too): every figure of its report
#   (non-'#' lines);
# - the hierarchical solve (each rank refines and gathers its share of the receivers): every row of
#   the solve CSV with every bounce term, and every pixel of every layer of `bounce bounces`' EXR;
# - the bunny box (../shared, skipped visibly without it; only with BN_TEST_BIG=1, which
#   bench/run.sh --big sets: a big scene): a short trace under -np 2 and 4; the
#   hierarchical solve's rows (bounces --patches-out) and EXR, and the crosscheck's figures, under
#   -np 2 and 4 against -np 1;
# - a rank killed, and SIGINT to mpirun: every rank ends, with a message, and no output is left;
# - dense K under P > 1 is refused with a clear message (exit 2) and leaves no output.
# With BN_TEST_SANITIZED=1 (the ASan + UBSan build): the same identity checks at -np 2 only, on
# smaller settings, without the kill and interrupt rows (each rank is instrumented; OpenMPI's own
# allocations are suppressed for LeakSanitizer in tests/lsan.supp).
# usage: mpi_check.sh BOUNCE SOURCE_DIR WORK_DIR
set -u
bounce=$1 src=$2 work=$3
mkdir -p "$work" && cd "$work" || exit 1
rm -f ./*.exr ./*.csv ./*.txt
if ! command -v mpirun >/dev/null 2>&1; then
    echo "SKIP: no mpirun (apt-get install openmpi-bin; scripts/setup.sh does)"
    exit 77
fi
if [ "$(id -u)" = 0 ]; then   # OpenMPI refuses root unless told twice
    export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
export OMPI_MCA_btl_vader_single_copy_mechanism=none   # containers without CMA (ptrace) permissions
fails=0
check() {   # check CONDITION-EXIT-CODE MESSAGE
    if [ "$1" = 0 ]; then echo "ok   $2"; else echo "FAIL $2"; fails=$((fails + 1)); fi
}
run() {   # run NP ARGS...: bounce under mpirun (NP 0: without mpirun)
    local np=$1
    shift
    # P ranks x T threads = the cores (two here): oversubscribed OpenMP threads spin at each barrier;
    # the answer does not depend on T
    local th=$(( $(nproc) / (np > 0 ? np : 1) ))
    [ "$th" -lt 1 ] && th=1
    local fwd=()   # the sanitizers' settings reach every rank only when named
    for v in ASAN_OPTIONS LSAN_OPTIONS UBSAN_OPTIONS; do [ -n "${!v:-}" ] && fwd+=(-x "$v"); done
    if [ "$np" = 0 ]; then "$bounce" "$@"; else mpirun --oversubscribe -np "$np" -x OMP_NUM_THREADS=$th "${fwd[@]}" "$bounce" "$@"; fi
}
cornell="$src/meshes/cornell-box.obj"
targs=(trace "$cornell" --unit mm --spp 8 --patches 300 --size 48x48 -n 3 -q)
cargs=(crosscheck "$cornell" --unit mm --patches 300 --spp 256 --transport hierarchical -q)
sargs=(solve "$cornell" --unit mm --patches 3000 --transport hierarchical -n 3 -q)
bargs0=(bounces "$cornell" --unit mm --patches 1200 --transport hierarchical --size 64x64 --no-previews -q)
nps="1 2 4"
if [ "${BN_TEST_SANITIZED:-0}" = 1 ]; then
    targs=(trace "$cornell" --unit mm --spp 4 --patches 100 --size 24x24 -n 3 -q)
    cargs=(crosscheck "$cornell" --unit mm --patches 100 --spp 64 --transport hierarchical --ff-visibility rays -q)
    sargs=(solve "$cornell" --unit mm --patches 600 --transport hierarchical -n 3 -q)
    bargs0=(bounces "$cornell" --unit mm --patches 300 --transport hierarchical --size 24x24 --no-previews -q)
    nps="2"
    # OpenMPI unloads its plugins (mca_*.so) before LeakSanitizer reports, leaving their frames
    # unnamed: keep them loaded, and unwind fully, so tests/lsan.supp can name OpenMPI's own leaks
    export OMPI_MCA_mca_base_component_disable_dlclose=1
    export ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}fast_unwind_on_malloc=0"
    # LeakSanitizer's full unwinding costs each mpirun 3.5 s of its 5: the leaks are looked for in the
    # crosscheck (the tracer and the hierarchy split among ranks), the solve and the refusal of dense K;
    # the trace and the images under mpirun run the same split code and are checked for their bits only
    noleaks="detect_leaks=0"
fi
leaks_off() { ASAN_OPTIONS="${ASAN_OPTIONS:-}${noleaks:+:$noleaks}" "$@"; }
run 0 "${targs[@]}" -o t0.exr --patches-out t0.csv 2>/dev/null
check $? "bounce trace, one process"
run 0 "${cargs[@]}" >c0.txt 2>/dev/null
rc=$?
# the sanitized run's small settings may fail the verdict (6); its figures are what is compared
[ "$rc" = 0 ] || { [ "${BN_TEST_SANITIZED:-0}" = 1 ] && [ "$rc" = 6 ]; }
check $? "bounce crosscheck, one process (exit $rc)"
run 0 "${sargs[@]}" -o s0.csv 2>/dev/null
check $? "bounce solve (hierarchical), one process"
run 0 "${bargs0[@]}" -o i0.exr 2>/dev/null
check $? "bounce bounces (hierarchical), one process"
for np in $nps; do
    leaks_off run "$np" "${targs[@]}" -o "t$np.exr" --patches-out "t$np.csv" 2>"t$np.err"
    check $? "trace under mpirun -np $np ($(tail -1 "t$np.err"))"
    idiff -fail 0 -warn 0 -a t0.exr "t$np.exr" >/dev/null 2>&1
    check $? "trace -np $np: every pixel of every layer equals one process's (idiff -fail 0)"
    cmp -s <(grep -v '^#' t0.csv) <(grep -v '^#' "t$np.csv")
    check $? "trace -np $np: every per-patch row equals one process's"
    if [ "$np" != 1 ]; then   # one process records the plain command (checked below)
        grep -q "^# command=mpirun -np $np " "t$np.csv"
        check $? "trace -np $np: the provenance records the process count"
    else
        ! grep -q "^# command=mpirun" "t$np.csv"
        check $? "trace -np 1: the provenance is the plain command (no process count)"
    fi
    n_tmp=$(find . -name '*.tmp*' | wc -l)
    [ "$n_tmp" = 0 ]
    check $? "trace -np $np: no temporary file left by any rank ($n_tmp)"
    run "$np" "${cargs[@]}" >"c$np.txt" 2>"c$np.err"
    rc=$?
    [ "$rc" = 0 ] || { [ "${BN_TEST_SANITIZED:-0}" = 1 ] && [ "$rc" = 6 ]; }
    check $? "crosscheck under mpirun -np $np (exit $rc; $(tail -1 "c$np.err"))"
    cmp -s <(grep -v '^#' c0.txt) <(grep -v '^#' "c$np.txt")
    check $? "crosscheck -np $np: every figure equals one process's ($(grep -c . "c$np.txt") lines)"
    run "$np" "${sargs[@]}" -o "s$np.csv" 2>"s$np.err"
    check $? "solve (hierarchical) under -np $np"
    cmp -s <(grep -v '^#' s0.csv) <(grep -v '^#' "s$np.csv")
    check $? "solve -np $np: every row, L and each term, equals one process's ($(grep -vc '^#' s0.csv) rows)"
    leaks_off run "$np" "${bargs0[@]}" -o "i$np.exr" 2>/dev/null
    check $? "bounces (hierarchical) under -np $np"
    idiff -fail 0 -warn 0 -a i0.exr "i$np.exr" >/dev/null 2>&1
    check $? "bounces -np $np: every pixel of E, KE, K2E, K3E, rest and L equals one process's"
done
# a rank that dies, and a run that is interrupted: every rank ends, a clear message, no output
long=(trace "$cornell" --unit mm --spp 1000000 --patches 300 --size 16x16 -q -o k.exr --patches-out k.csv)
hows="kill interrupt"
[ "${BN_TEST_SANITIZED:-0}" = 1 ] && hows="" && echo "SKIP (part): kill and interrupt rows in the normal build only"
for how in $hows; do
    rm -f k.exr k.csv k.err
    mpirun --oversubscribe -np 2 "$bounce" "${long[@]}" >/dev/null 2>k.err &
    mpid=$!
    # until both ranks are at work (a second of CPU each: past start-up and the signal handlers), not
    # a fixed sleep: under load the ranks may take seconds to start
    for _ in $(seq 120); do
        ranks=$(pgrep -P "$mpid" -f "bounce trace" | tr '\n' ' ')
        busy=0
        for p in $ranks; do [ "$(ps -o times= -p "$p" 2>/dev/null | tr -d ' ')" -ge 1 ] 2>/dev/null && busy=$((busy + 1)); done
        [ "$busy" -ge 2 ] && break
        sleep 0.5
    done
    if [ "$how" = kill ]; then
        kill -9 "$(echo "$ranks" | awk '{ print $NF }')" 2>/dev/null   # one rank dies
    else
        kill -INT "$mpid"   # Ctrl-C on mpirun: it forwards SIGINT to every rank
    fi
    for _ in $(seq 60); do kill -0 "$mpid" 2>/dev/null || break; sleep 1; done
    wait "$mpid"
    rc=$?
    alive() { for p in $ranks; do ps -o stat= -p "$p" 2>/dev/null | grep -qv Z && echo "$p"; done | wc -l; }
    for _ in $(seq 20); do [ "$(alive)" = 0 ] && break; sleep 0.5; done
    left=$(alive)
    n_tmp=$(find . -name '*.tmp*' | wc -l)
    [ "$rc" != 0 ] && [ "$left" = 0 ] && [ ! -e k.exr ] && [ ! -e k.csv ] && [ "$n_tmp" = 0 ]
    check $? "$how: mpirun exit $rc, $left of the ranks ($ranks) left, no output, $n_tmp temporaries"
    if [ "$how" = kill ]; then
        grep -qiE "signal 9|killed" k.err
        check $? "kill: mpirun says which rank died ($(grep -m1 -iE 'signal 9|killed' k.err | cut -c1-80))"
    else
        grep -q "interrupted; no partial output was left" k.err
        check $? "interrupt: bounce says so ($(grep -m1 interrupted k.err))"
    fi
done
# dense K is single-process
run 2 solve "$cornell" --unit mm --patches 100 --transport dense -o dense.csv >/dev/null 2>dense.err
rc=$?
[ "$rc" != 0 ] && grep -q "single-process" dense.err && [ ! -e dense.csv ]
check $? "dense K under -np 2: refused (exit $rc: $(grep -m1 single-process dense.err | cut -c1-90)), no output"
bb="$src/../shared/data/scenes/bunny-box.obj"
if [ "${BN_TEST_BIG:-0}" != 1 ]; then
    # a big scene (three minutes of the suite's budget): bench/run.sh --big runs this script with
    # BN_TEST_BIG=1 and reports its verdict
    echo "SKIP (part): the bunny box's rows are run by bench/run.sh --big (BN_TEST_BIG=1)"
elif [ -f "$bb" ]; then
    bargs=(trace "$bb" --unit mm --spp 2 --size 32x32 -n 2 -q)
    run 0 "${bargs[@]}" -o b0.exr --patches-out b0.csv 2>/dev/null
    check $? "bunny box: trace, one process"
    for np in 2 4; do
        run "$np" "${bargs[@]}" -o "b$np.exr" --patches-out "b$np.csv" 2>/dev/null
        check $? "bunny box: trace under -np $np"
        cmp -s <(grep -v '^#' b0.csv) <(grep -v '^#' "b$np.csv") && idiff -fail 0 -warn 0 -a b0.exr "b$np.exr" >/dev/null 2>&1
        check $? "bunny box -np $np: every per-patch row ($(grep -vc '^#' b0.csv)) and pixel equals one process's"
    done
    # the hierarchical solve and its images (eps 1: the near field alone, 5 M links, ~25 s a run) and the
    # crosscheck over regions, under -np 2 and 4 against -np 1 (one process: the same code as without
    # mpirun, which the Cornell box checks above)
    hargs=(bounces "$bb" --unit mm --eps 1 -n 3 --size 32x32 --no-previews -q)
    xargs=(crosscheck "$bb" --unit mm --eps 1 --regions 20 --spp 64 --disc none -q)
    for np in 1 2 4; do
        run "$np" "${hargs[@]}" -o "h$np.exr" --patches-out "h$np.csv" 2>"h$np.err"
        check $? "bunny box: hierarchical bounces at eps 1 under -np $np"
        run "$np" "${xargs[@]}" >"x$np.txt" 2>"x$np.err"
        rc=$?
        [ "$rc" = 0 ] || [ "$rc" = 6 ]   # 6: the verdict fails (eps 1, no discretisation allowance); the figures count
        check $? "bunny box: crosscheck over 20 regions under -np $np (exit $rc)"
        [ "$np" = 1 ] && continue
        cmp -s <(grep -v '^#' h1.csv) <(grep -v '^#' "h$np.csv")
        check $? "bunny box -np $np: every row of the solve, L and each term, equals one process's ($(grep -vc '^#' h1.csv) rows)"
        idiff -fail 0 -warn 0 -a h1.exr "h$np.exr" >/dev/null 2>&1
        check $? "bunny box -np $np: every pixel of E, KE, K2E, K3E, rest and L equals one process's"
        cmp -s <(grep -v '^#' x1.txt) <(grep -v '^#' "x$np.txt")
        check $? "bunny box -np $np: every crosscheck figure equals one process's ($(grep -c . "x$np.txt") lines)"
    done
else
    echo "SKIP (part): $bb is not there (../shared beside the checkout): the bunny box's rows not run"
fi
echo "$fails failures"
[ "$fails" = 0 ]
