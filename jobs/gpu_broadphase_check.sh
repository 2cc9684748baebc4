#!/usr/bin/env bash
# The broad phases (issue #34) on one GPU, in one call (about 5 minutes of device time):
#   1. the unit tests of the broad phases with their CUDA cases (none may skip, none may fail);
#   2. CPU = CUDA, byte for byte: every scene family, fp32 and fp64, the CPU's auto against the CUDA
#      backend's grid, levels and sweep (brute on the small scenes), and mpirun np 2 with CUDA;
#   3. the H100 table at 2^24 fp32 (bench-broad: uniform, bimodal 1:10 and 1:100 at 10 % large by
#      volume, log-uniform 1:1000, 64 intruders r = 100 among r = 1): seconds per broad phase, auto
#      against the best, time per contact against the uniform row (/unif/c).
#   BIN=dir OUT=results-dir jobs/gpu_broadphase_check.sh
# BIN holds the CUDA build's contactgrid and contactgrid_tests. Exits non-zero naming every failed
# check (the last lines of the output); each step runs whatever an earlier one did.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
BIN=${BIN:-.devbin}; OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"; W=${WORK:-/tmp/cgbroad}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
failed=()
fail() { failed+=("$1"); echo "FAILED: $1"; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$OUT/device.txt"
cat "$OUT/device.txt"

log "1. unit tests of the broad phases (CUDA cases must run, not skip)"
"$BIN/contactgrid_tests" --gtest_filter='BroadPhaseTest/cuda.*:LevelsPlan.*:SweepKeys.*:BoxRadius.*:AutoBroadPhase.*' \
  >"$OUT/tests.log" 2>&1 || fail "unit tests (tests.log)"
grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/tests.log" | head -20
grep -q 'BroadPhaseTest/cuda' "$OUT/tests.log" || fail "no CUDA case of BroadPhaseTest ran"
grep -E '^\[  SKIPPED \] BroadPhaseTest/cuda' "$OUT/tests.log" && fail "CUDA cases skipped (no GPU seen?)"

log "2. CPU = CUDA byte for byte, every scene family (2^20; brute at 2^13), fp32 and fp64; np 2"
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
: >"$OUT/compare.log"
for entry in "${families[@]}"; do
  name=${entry%%|*}; args=${entry#*|}
  for lg in 20 13; do
    n=$((1 << lg)); scene="$W/$name.$lg.h5"
    # shellcheck disable=SC2086
    "$CG" generate "$scene" -n $n --seed 34 $args -q >>"$OUT/compare.log" 2>&1 || { fail "generate $name 2^$lg"; continue; }
    phases="grid levels sweep"; [ $lg = 13 ] && phases="grid levels sweep brute"
    for prec in fp32 fp64; do
      ref="$W/$name.$lg.cpu.$prec.h5"
      "$CG" detect "$scene" -o "$ref" --backend cpu --precision $prec -q >>"$OUT/compare.log" 2>&1 ||
        { fail "detect cpu $name 2^$lg $prec"; continue; }
      for bp in $phases; do
        got="$W/$name.$lg.cuda.$bp.$prec.h5"
        if ! "$CG" detect "$scene" -o "$got" --backend cuda --precision $prec --broad-phase $bp -q >>"$OUT/compare.log" 2>&1; then
          fail "detect cuda $name 2^$lg $prec $bp"; continue
        fi
        if "$CG" compare "$ref" "$got" >>"$OUT/compare.log" 2>&1; then r=IDENTICAL; else r=DIFFERENT; fail "cpu/cuda $name 2^$lg $prec $bp"; fi
        printf '%-15s 2^%-3s %-5s %-7s %s\n' "$name" "$lg" "$prec" "$bp" "$r" >>"$OUT/compare.txt"
      done
    done
  done
done
echo "$(grep -c IDENTICAL "$OUT/compare.txt" 2>/dev/null || echo 0) identical, $(grep -c DIFFERENT "$OUT/compare.txt" 2>/dev/null || echo 0) different"
grep DIFFERENT "$OUT/compare.txt" 2>/dev/null
for name in intruders64 bimodal100; do
  got="$W/$name.np2.h5"
  if mpirun --bind-to none -np 2 "$CG" detect "$W/$name.20.h5" -o "$got" --backend cuda --precision fp64 -q >>"$OUT/compare.log" 2>&1 &&
     "$CG" compare "$W/$name.20.cpu.fp64.h5" "$got" >>"$OUT/compare.log" 2>&1; then
    echo "np2 cuda $name: IDENTICAL"
  else
    fail "np2 cuda $name against the CPU's np1"
  fi
done

log "3. the table: 2^24 fp32 (and 2^20), bench-broad on CUDA"
"$CG" bench-broad --backend cuda --precision fp32 --lo 20 --hi 24 --step 4 \
  --families uniform,bimodal10,bimodal100,loguniform1000,intruders64 --repetitions 5 \
  --brute-hi 16 --sweep-hi 24 --budget 5 --csv "$OUT/broad_h100.csv" >"$OUT/broad_h100.txt" 2>&1 ||
  fail "bench-broad (broad_h100.txt)"
cat "$OUT/broad_h100.txt"

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED CHECK: %s\n' "${failed[@]}"
  exit 1
fi
echo "ALL BROAD-PHASE CHECKS PASSED"
