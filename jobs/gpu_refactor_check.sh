#!/usr/bin/env bash
# A change that must not move the output nor slow the GPU path, checked on one GPU in one call:
# the unit suite with its CUDA cases (EveryPathIsBitIdentical among them), CPU vs CUDA byte-identical
# /contacts at the CLI in both precisions, mpirun np 1 vs 2 vs 3 byte-identical with the CUDA backend,
# memcheck on the CUDA cases, and the per-stage bench of the change against a baseline build,
# interleaved (base, new, base, new) so that both see the same machine.
#   BASE=dir BIN=dir OUT=results-dir jobs/gpu_refactor_check.sh
# BASE holds the baseline's contactgrid_cuda_bench; BIN holds the change's contactgrid,
# contactgrid_tests and contactgrid_cuda_bench.
set -u
BIN=${BIN:-.devbin/new}; BASE=${BASE:-.devbin/base}; OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$OUT/device.txt"
cat "$OUT/device.txt"

log "unit tests (CUDA cases included)"
"$BIN/contactgrid_tests" >"$OUT/tests.log" 2>&1
grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]|EveryPathIsBitIdentical' "$OUT/tests.log" | head -20

log "CLI: cpu vs cuda, np 1 vs 2 vs 3 (cuda)"
{
  "$CG" generate "$W/s22.h5" -n 4194304 --seed 22 -q
  for prec in fp64 fp32; do
    "$CG" detect "$W/s22.h5" -o "$W/cpu.$prec.h5" --backend cpu --precision $prec --fields full -q
    "$CG" detect "$W/s22.h5" -o "$W/cuda.$prec.h5" --backend cuda --precision $prec --fields full -q
    echo "compare cpu/cuda $prec:"; "$CG" compare "$W/cpu.$prec.h5" "$W/cuda.$prec.h5"
  done
  for np in 2 3; do
    mpirun --bind-to none -np $np "$CG" detect "$W/s22.h5" -o "$W/np$np.h5" --backend cuda --fields full -q
    echo "compare np1/np$np cuda fp64:"; "$CG" compare "$W/cuda.fp64.h5" "$W/np$np.h5"
  done
} >"$OUT/cli.log" 2>&1
grep -E 'compare|IDENTICAL|DIFFERENT|error' "$OUT/cli.log"

log "bench: baseline vs change, interleaved (2^20 … 2^24, tuned cell, 20 runs)"
for round in 1 2; do
  for which in base new; do
    dir=$BASE; [ $which = new ] && dir=$BIN
    "$dir/contactgrid_cuda_bench" 20 24 2 20 auto 2>&1 | sed "s/^/$which$round /"
  done
done >"$OUT/bench.md"
grep -E '\| 2\^(20|24) ' "$OUT/bench.md" | cut -d'|' -f1-14

log "memcheck (CUDA cases)"
timeout 200 compute-sanitizer --tool memcheck --leak-check full "$BIN/contactgrid_tests" \
  --gtest_filter='*cuda*:*Cuda*' >"$OUT/memcheck.log" 2>&1
grep -E 'ERROR SUMMARY|LEAK SUMMARY|^\[  (PASSED|FAILED) ' "$OUT/memcheck.log" | head
log "done"
