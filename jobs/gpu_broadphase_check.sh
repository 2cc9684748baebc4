#!/usr/bin/env bash
# The broad phases (issue #34) on one GPU, in one call (under 4 minutes on an H100):
#   1. the unit tests of the broad phases with their CUDA cases (none may skip, none may fail), among
#      them LevelsCpuCuda (CUDA levels = the CPU's on log-uniform 1:1000 scenes, every mode);
#   2. CPU = CUDA, byte for byte: every scene family at 2^13 and 2^18, fp32 and fp64, the CPU's auto
#      against the CUDA backend's grid, levels and sweep (brute at 2^13), and mpirun np 2 with CUDA;
#   3. the H100 table (bench-broad, fp32): grid, levels, sweep and auto at 2^20, 2^22 and 2^24 (sweep
#      stops at the first N where it passes 0.5 s), brute at 2^13 … 2^16.
#   BIN=dir OUT=results-dir jobs/gpu_broadphase_check.sh
# BIN holds the CUDA build's contactgrid and contactgrid_tests. Everything lands in
# $OUT/broadphase.tgz (logs, compare table, the tables as text and CSV); the summary is printed.
# Exits non-zero naming every failed check (the last lines of the output); each step runs whatever
# an earlier one did.
set -u
cd "$(dirname "$0")/.." || exit 2
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
BIN=${BIN:-.devbin}; OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"; W=${WORK:-/tmp/cgbroad}; R="$W/results"; rm -rf "$R"; mkdir -p "$R"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
failed=()
fail() { failed+=("$1"); echo "FAILED: $1"; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
pack() { tar czf "$OUT/broadphase.tgz" -C "$W" results; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$R/device.txt"
cat "$R/device.txt"

log "1. unit tests of the broad phases (CUDA cases must run, not skip)"
timeout 120 "$BIN/contactgrid_tests" \
  --gtest_filter='BroadPhaseTest/cuda.*:LevelsCpuCuda.*:LevelsDeviceFlow.*:LevelsPlan.*:SweepKeys.*:BoxRadius.*:AutoBroadPhase.*' \
  >"$R/tests.log" 2>&1 || fail "unit tests (tests.log)"
grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]|Failure|Expected|Which is|actual' "$R/tests.log" | head -40
grep -q 'BroadPhaseTest/cuda' "$R/tests.log" || fail "no CUDA case of BroadPhaseTest ran"
grep -E '^\[  SKIPPED \] (BroadPhaseTest/cuda|LevelsCpuCuda)' "$R/tests.log" && fail "CUDA cases skipped (no GPU seen?)"

log "2. CPU = CUDA byte for byte, every scene family at 2^13 and 2^18 (brute at 2^13), fp32 and fp64"
# name  generate-arguments
families=(
  "uniform|--kind uniform"
  "bimodal10|--kind bimodal --rhigh 1 --ratio 10 --large-fraction 0.1"
  "bimodal100|--kind bimodal --rhigh 1 --ratio 100 --large-fraction 0.1"
  "loguniform1000|--kind polydisperse --rhigh 1 --ratio 1000"
  "intruders64|--kind intruders --rhigh 100 --ratio 100 --intruders 64"
  "intruder1|--kind intruders --rhigh 1 --ratio 100 --intruders 1"
  "mixed|--kind mixed --max-aspect 4"
)
: >"$R/compare.log"; : >"$R/compare.txt"
# the scenes and the CPU references in parallel (the host's cores), then the CUDA runs one at a time
for entry in "${families[@]}"; do
  name=${entry%%|*}; args=${entry#*|}
  for lg in 13 18; do
    (
      scene="$W/$name.$lg.h5"
      # shellcheck disable=SC2086
      "$CG" generate "$scene" -n $((1 << lg)) --seed 34 $args -q >"$W/$name.$lg.gen.log" 2>&1 || exit 1
      for prec in fp32 fp64; do
        "$CG" detect "$scene" -o "$W/$name.$lg.cpu.$prec.h5" --backend cpu --threads 2 --precision $prec -q \
          >"$W/$name.$lg.cpu.$prec.log" 2>&1
      done
    ) &
  done
done
wait
step2() {
  for entry in "${families[@]}"; do
    name=${entry%%|*}
    for lg in 13 18; do
      scene="$W/$name.$lg.h5"
      [ -f "$scene" ] || { fail "generate $name 2^$lg"; cat "$W/$name.$lg.gen.log" >>"$R/compare.log"; continue; }
      phases="grid levels sweep"; [ $lg = 13 ] && phases="grid levels sweep brute"
      for prec in fp32 fp64; do
        ref="$W/$name.$lg.cpu.$prec.h5"
        [ -f "$ref" ] || { fail "detect cpu $name 2^$lg $prec"; cat "$W/$name.$lg.cpu.$prec.log" >>"$R/compare.log"; continue; }
        for bp in $phases; do
          got="$W/$name.$lg.cuda.$bp.$prec.h5"
          if ! "$CG" detect "$scene" -o "$got" --backend cuda --precision $prec --broad-phase $bp -q >>"$R/compare.log" 2>&1; then
            fail "detect cuda $name 2^$lg $prec $bp"; continue
          fi
          echo "== $name 2^$lg $prec $bp" >>"$R/compare.log"
          if "$CG" compare "$ref" "$got" >>"$R/compare.log" 2>&1; then r=IDENTICAL; else r=DIFFERENT; fail "cpu/cuda $name 2^$lg $prec $bp"; fi
          printf '%-15s 2^%-3s %-5s %-7s %s\n' "$name" "$lg" "$prec" "$bp" "$r" >>"$R/compare.txt"
        done
      done
    done
  done
  for name in intruders64 loguniform1000; do
    got="$W/$name.np2.h5"
    if mpirun --bind-to none -np 2 "$CG" detect "$W/$name.18.h5" -o "$got" --backend cuda --precision fp64 -q >>"$R/compare.log" 2>&1 &&
       "$CG" compare "$W/$name.18.cpu.fp64.h5" "$got" >>"$R/compare.log" 2>&1; then
      echo "np2 cuda $name 2^18: IDENTICAL" | tee -a "$R/compare.txt"
    else
      fail "np2 cuda $name 2^18 against the CPU's np1"
    fi
  done
}
step2
echo "$(grep -c IDENTICAL "$R/compare.txt") identical, $(grep -c DIFFERENT "$R/compare.txt") different"
grep DIFFERENT "$R/compare.txt"
pack

log "3. the H100 table, fp32: 2^20, 2^22, 2^24 (grid, levels, sweep, auto); brute at 2^13 … 2^16"
# the issue's rows; sweep stops at the first N where it passes 0.5 s (2.4 s at 2^24 on uniform)
timeout 120 "$CG" bench-broad --backend cuda --precision fp32 --lo 20 --hi 24 --step 2 \
  --families uniform,bimodal10,bimodal100,loguniform1000 --repetitions 3 --brute-hi 0 --sweep-hi 24 \
  --budget 0.5 --csv "$R/broad_h100.csv" >"$R/broad_h100.txt" 2>&1 || fail "bench-broad 2^20-2^24 (broad_h100.txt)"
cat "$R/broad_h100.txt"
# the intruders: the grid's cells hold every grain (quadratic), so one timed run each and the grid
# stops after 2^20 (budget); uniform again for the /uniform columns
timeout 60 "$CG" bench-broad --backend cuda --precision fp32 --lo 20 --hi 24 --step 2 \
  --families uniform,intruder1,intruders64 --repetitions 1 --brute-hi 0 --sweep-hi 22 --budget 0.5 \
  --csv "$R/broad_h100_intruders.csv" >"$R/broad_h100_intruders.txt" 2>&1 ||
  fail "bench-broad intruders 2^20-2^24 (broad_h100_intruders.txt)"
cat "$R/broad_h100_intruders.txt"
timeout 40 "$CG" bench-broad --backend cuda --precision fp32 --lo 13 --hi 16 --step 1 \
  --families uniform,bimodal10,bimodal100,loguniform1000,intruder1,intruders64 --repetitions 3 \
  --brute-hi 16 --sweep-hi 16 --budget 2 --csv "$R/broad_h100_small.csv" >"$R/broad_h100_small.txt" 2>&1 ||
  fail "bench-broad 2^13-2^16 (broad_h100_small.txt)"
cat "$R/broad_h100_small.txt"
pack

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED CHECK: %s\n' "${failed[@]}"
  exit 1
fi
echo "ALL BROAD-PHASE CHECKS PASSED"
