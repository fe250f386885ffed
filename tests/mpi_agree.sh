#!/usr/bin/env bash
# Runs tests/mpi_agree.c under mpirun -np 2 (as root too), the sanitizers' settings forwarded.
# usage: mpi_agree.sh PROGRAM
set -u
command -v mpirun >/dev/null 2>&1 || { echo "SKIP: no mpirun (apt-get install openmpi-bin)"; exit 77; }
[ "$(id -u)" = 0 ] && export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none OMPI_MCA_mca_base_component_disable_dlclose=1
# full stacks under LeakSanitizer, so tests/lsan.supp can name OpenMPI's own allocations
[ -n "${ASAN_OPTIONS:-}" ] && export ASAN_OPTIONS="$ASAN_OPTIONS:fast_unwind_on_malloc=0"
fwd=()
for v in ASAN_OPTIONS LSAN_OPTIONS UBSAN_OPTIONS; do [ -n "${!v:-}" ] && fwd+=(-x "$v"); done
exec mpirun --oversubscribe -np 2 -x OMP_NUM_THREADS=1 "${fwd[@]}" "$1"
