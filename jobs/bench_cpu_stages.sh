#!/usr/bin/env bash
# Per-stage CPU table for BENCHMARKS.md: for N = 2^LO … 2^HI uniform spheres (default 10 … 22),
# generate, then run `contactgrid detect` REPS times (default 3) and keep the run with the smallest
# detect time; prints a markdown table of contacts, the engine's stage times, detect total, and the
# process's peak resident memory (GNU time). Usage: jobs/bench_cpu_stages.sh [LO] [HI] [REPS]
set -euo pipefail
cd "$(dirname "$0")/.."
LO=${1:-10}; HI=${2:-22}; REPS=${3:-3}
CG=${CG:-build/src/contactgrid}
TMP=$(mktemp -d); trap 'rm -rf "$TMP"' EXIT
stages="pack entries sort pairs order narrow"
printf '| N | contacts | per body |'; for s in $stages; do printf ' %s ms |' "$s"; done
printf ' detect ms | read ms | peak RSS MiB | B/sphere |\n'
printf '|---|---|---|'; for s in $stages; do printf -- '---|'; done; printf -- '---|---|---|---|\n'
for ((e = LO; e <= HI; e++)); do
  n=$((1 << e))
  $CG generate "$TMP/s.h5" -n "$n" --seed "$e" -q
  best=""; bestt=1e9
  for ((r = 0; r < REPS; r++)); do
    /usr/bin/time -f 'PEAK_KB %M' -o "$TMP/time" $CG detect "$TMP/s.h5" -o "$TMP/c.h5" --backend cpu >"$TMP/log"
    cat "$TMP/time" >>"$TMP/log"
    t=$(awk '$1=="detect"{print $2}' "$TMP/log")
    if awk -v a="$t" -v b="$bestt" 'BEGIN{exit !(a<b)}'; then bestt=$t; cp "$TMP/log" "$TMP/best"; fi
  done
  awk -v n="$n" -v e="$e" -v stages="$stages" '
    /contactgrid detect:/ {k=$5}
    $1=="detect" {det=$2} $1=="read" {rd=$2} $1=="PEAK_KB" {kb=$2}
    {t[$1]=$2}
    END {
      printf "| 2^%d | %d | %.3f |", e, k, k/n
      m=split(stages, s, " "); for (i=1;i<=m;i++) printf " %.1f |", t[s[i]]*1000
      printf " %.1f | %.1f | %.0f | %.0f |\n", det*1000, rd*1000, kb/1024, kb*1024/n
    }' "$TMP/best"
done
