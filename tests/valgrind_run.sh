#!/bin/sh
# Runs memcheck on one bounce command (tests/valgrind.cmake). Valgrind cannot run every CPU's
# instructions: where it stops on an illegal opcode before bounce's own code runs (seen: Highway's
# timer set-up in libhwy, loaded through OpenImageIO, on an AVX-512 machine under valgrind 3.19),
# memcheck cannot say anything here, so the test is skipped visibly (exit 77) naming the cause;
# every other failure fails the test.
# usage: valgrind_run.sh VALGRIND SUPPRESSIONS BOUNCE ARGS...
set -u
vg=$1; supp=$2; shift 2
probe=$("$vg" -q --error-exitcode=42 "$1" --version 2>&1 >/dev/null)
rc=$?
if [ "$rc" -ne 0 ] && printf '%s\n' "$probe" | grep -q "Illegal opcode"; then
    echo "valgrind cannot run bounce on this CPU: $(printf '%s\n' "$probe" | grep -m1 -A1 'Illegal opcode' | tr -s ' \n' ' ')" >&2
    echo "skipped: memcheck is unavailable on this machine (the sanitized build still runs)" >&2
    exit 77
fi
exec "$vg" --error-exitcode=42 --leak-check=full --errors-for-leak-kinds=definite,indirect \
    --suppressions="$supp" -q "$@"
