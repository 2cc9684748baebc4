#!/usr/bin/env bash
# Runaway scenes on one GPU (#35, #34 "Bad input"): the unit suite's pair-estimate cases with the CUDA
# backend present (none may skip; the CPU and CUDA estimates must be equal), and a pile of bodies in
# one cell refused by `detect --backend cuda --max-pair-tests` (exit 9, the estimate with its time, no
# output file, quickly). Then a smaller pile run to its end on the GPU, its summary kept under $OUT for
# the device's pair-test rate, and a pile on two quiet cores of the host for the host's rate
# (kernels/pair_estimate.hpp: kDevicePairTestsPerSecond, kHostPairTestsPerSecondPerThread). The unit
# cases include the GPU pair stage's progress on long work (PairEstimate.CudaPairStageReports...).
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_faults_check.sh
# Prints PASS/FAIL per check; exits non-zero naming the failed checks.
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgfaults}; mkdir -p "$W"
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
CG="$BIN/contactgrid"
failed=()
check() {  # check NAME CONDITION...
  local name=$1; shift
  if "$@"; then echo "PASS $name"; else echo "FAIL $name"; failed+=("$name"); fi
}
log() { echo "[$(date -u +%H:%M:%S)] $*"; }

log "unit: PairEstimate* (both backends)"
"$BIN/contactgrid_tests" --gtest_filter='PairEstimate*:-PairLimitCli.*' >"$OUT/faults_unit.log" 2>&1
unit_rc=$?
grep -E '^\[ +(OK|SKIPPED|FAILED) +\]' "$OUT/faults_unit.log"
check "unit PairEstimate* pass" test $unit_rc -eq 0
check "unit no case skipped (GPU present)" bash -c "! grep -q '^\[  SKIPPED ' '$OUT/faults_unit.log'"
check "unit CUDA cases ran" grep -q '^\[       OK \] PairEstimateTest/cuda' "$OUT/faults_unit.log"
check "unit same estimate CPU and CUDA" grep -q '^\[       OK \] PairEstimate.SameOnCpuAndCuda' "$OUT/faults_unit.log"

log "CLI: a pile refused on the GPU"
"$CG" generate "$W/pile.h5" -n 60000 --seed 2 --rlow 0.001 --rhigh 0.001 --contacts-per-body 100000 -q
rm -f "$W/out.h5"
start=$(date +%s%N)
"$CG" detect "$W/pile.h5" -o "$W/out.h5" --backend cuda --max-pair-tests 1000000 >"$OUT/faults_pile.log" 2>&1
rc=$?
secs=$(awk -v a="$start" -v b="$(date +%s%N)" 'BEGIN { printf "%.2f", (b - a) / 1e9 }')
cat "$OUT/faults_pile.log"; echo "exit $rc after $secs s"
check "pile refused with exit 9" test $rc -eq 9
check "pile message names the limit" grep -q 'more than --max-pair-tests 1000000' "$OUT/faults_pile.log"
check "pile message gives the time" grep -q 'tests a second' "$OUT/faults_pile.log"
check "pile warned before" grep -q 'warning: the pair stage will make about' "$OUT/faults_pile.log"
check "pile left no output" test ! -e "$W/out.h5"
check "pile refused within 60 s" awk -v s="$secs" 'BEGIN { exit !(s < 60) }'
ls "$W" | grep -v '^pile.h5$' >"$OUT/faults_left.txt"
check "pile left no temporary" test ! -s "$OUT/faults_left.txt"

log "CLI: a smaller pile run to its end on the GPU (its times, for the rate)"
"$CG" generate "$W/pile10k.h5" -n 10000 --seed 3 --rlow 0.001 --rhigh 0.001 --contacts-per-body 100000 -q
"$CG" detect "$W/pile10k.h5" -o "$W/p10k.h5" --backend cuda --precision fp64 >"$OUT/faults_pile10k.log" 2>&1
rc=$?
cat "$OUT/faults_pile10k.log"
check "pile 10k detected on the GPU" test $rc -eq 0

# The rates of kernels/pair_estimate.hpp: pair tests over the detect stage's seconds of a pile (every
# test a contact), the GPU's from the pile above, the host's on two quiet cores (taskset) per thread.
rate() {  # LOG THREADS: tests a second (per thread)
  awk -v threads="$2" '
    / pair tests$/ { for (i = 1; i < NF; ++i) if ($(i + 1) == "pair") tests = $i }
    $1 == "detect" && NF == 2 { seconds = $2 }
    END { if (seconds > 0) printf "%.3g", tests / seconds / threads; else print "?" }' "$1"
}
"$CG" generate "$W/pile4k.h5" -n 4000 --seed 3 --rlow 0.001 --rhigh 0.001 --contacts-per-body 100000 -q
taskset -c 0,1 "$CG" detect "$W/pile4k.h5" -o "$W/p4k.h5" --backend cpu --threads 2 --precision fp64 \
  >"$OUT/faults_pile4k_cpu.log" 2>&1
check "pile 4k detected on two quiet cores" test $? -eq 0
cat "$OUT/faults_pile4k_cpu.log"
echo "RATE device $(rate "$OUT/faults_pile10k.log" 1) pair tests/s (kDevicePairTestsPerSecond)" | tee "$OUT/faults_rates.txt"
echo "RATE host $(rate "$OUT/faults_pile4k_cpu.log" 2) pair tests/s per thread (kHostPairTestsPerSecondPerThread; load $(cut -d' ' -f1 /proc/loadavg))" |
  tee -a "$OUT/faults_rates.txt"
rm -f "$W"/*.h5

log "done"
if ((${#failed[@]})); then
  echo "gpu_faults_check: FAILED: ${failed[*]}"
  exit 1
fi
echo "gpu_faults_check: all checks PASS"
