#!/usr/bin/env bash
# The crosscheck's false-alarm rate, measured: `bounce crosscheck` at --spp 1024 (the default) over
# SEEDS seeds on a scene whose radiosity answer is right, judged at alpha 0.05 and 0.1. Each seed
# runs once; its verdict at each alpha follows from the worst z of the two families (per entry,
# per-layer power) against that alpha's critical values, which depend only on the family size and
# the samples and are read once per alpha from the command itself. Form factors are cached.
# The observed rate's exact binomial 95% interval (Clopper-Pearson) must contain alpha or lie
# below it. Prints a markdown table; the last line is the verdict. Resumable: each seed's result is
# appended to WORKDIR/seeds.tsv, and seeds already there are not run again.
# usage: bench/crosscheck_rate.sh BOUNCE SCENE UNIT SEEDS WORKDIR [LABEL]
set -euo pipefail
exe=$1 scene=$2 unit=$3 seeds=$4 work=$5 label=${6:-$(basename "$scene")}
mkdir -p "$work"
cache="$work/F.bin"
field() { sed -n "s/.* $1=\([^ ]*\).*/\1/p" <<<"$2"; }
run() {   # seed alpha -> the verdict line
  "$exe" crosscheck "$scene" --unit "$unit" --seed "$1" --alpha "$2" --cache "$cache" -q 2>/dev/null | tail -1 || true
}
declare -A crit pcrit fails
for a in 0.05 0.1; do
  line=$(run 1 "$a")
  crit[$a]=$(field crit "$line")
  pcrit[$a]=$(field power_crit "$line")
  fails[$a]=0
  [ -n "${crit[$a]}" ] || { echo "crosscheck_rate: no verdict line from $exe ($line)" >&2; exit 1; }
done
t0=$(date +%s)
# each seed's worst z values are kept in WORKDIR/seeds.tsv as they come: a run stopped part way
# goes on from where it was (the same binary, scene and unit), and its seeds are not run again
log="$work/seeds.tsv"
touch "$log"
for s in $(seq 1 "$seeds"); do
  if ! grep -q "^$s	" "$log"; then
    line=$(run "$s" 0.1)
    wz=$(field worst_z "$line")
    pz=$(field power_worst_z "$line")
    [ -n "$wz" ] || { echo "crosscheck_rate: seed $s gave no verdict ($line)" >&2; exit 1; }
    printf '%s\t%s\t%s\n' "$s" "$wz" "$pz" >>"$log"
  fi
  wz=$(awk -v s="$s" '$1 == s { print $2; exit }' "$log")
  pz=$(awk -v s="$s" '$1 == s { print $3; exit }' "$log")
  for a in 0.05 0.1; do
    if awk -v w="$wz" -v c="${crit[$a]}" -v p="$pz" -v q="${pcrit[$a]}" 'BEGIN { exit !(w > c || p > q) }'; then
      fails[$a]=$((fails[$a] + 1))
    fi
  done
  [ $((s % 25)) = 0 ] && echo "crosscheck_rate: $s seeds, failures at 0.05: ${fails[0.05]}, at 0.1: ${fails[0.1]}" >&2
done
secs=$(( $(date +%s) - t0 ))
echo "| scene | alpha | seeds | failures | rate | binomial 95% interval | holds |"
echo "|---|---|---|---|---|---|---|"
ok=1
for a in 0.05 0.1; do
  read -r rate lo hi holds < <(/usr/bin/python3 - "${fails[$a]}" "$seeds" "$a" <<'EOF'
import sys
from math import comb
k, n, a = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
def cdf(k, n, p):
    return sum(comb(n, i) * p**i * (1 - p)**(n - i) for i in range(k + 1))
def solve(f, lo=0.0, hi=1.0):
    for _ in range(100):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if f(mid) else (lo, mid)
    return (lo + hi) / 2
# Clopper-Pearson: lo where P(X >= k) = 0.025, hi where P(X <= k) = 0.025
lo = 0.0 if k == 0 else solve(lambda p: 1 - cdf(k - 1, n, p) < 0.025)
hi = 1.0 if k == n else solve(lambda p: cdf(k, n, p) > 0.025)
print("%.4f %.4f %.4f %s" % (k / n, lo, hi, "yes" if lo <= a else "no"))
EOF
)
  [ "$holds" = yes ] || ok=0
  echo "| $label | $a | $seeds | ${fails[$a]} | $rate | [$lo, $hi] | $holds |"
done
echo
echo "($seeds seeds in ${secs} s; critical values: alpha 0.05 ${crit[0.05]} per entry, ${pcrit[0.05]} per power; alpha 0.1 ${crit[0.1]}, ${pcrit[0.1]})"
[ $ok = 1 ] && echo "verdict: the stated rate holds" || echo "verdict: the observed rate is above alpha"
