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

log "bench: baseline vs change, interleaved (2^20 and 2^24, spheres and ellipsoids, tuned cell, 10 runs)"
for round in 1 2; do
  for scene in spheres ellipsoids; do
    for which in base new; do
      dir=$BASE; [ $which = new ] && dir=$BIN
      "$dir/contactgrid_cuda_bench" 20 24 4 10 auto $scene 2>&1 | sed "s/^/$which$round $scene /"
    done
  done
done >"$OUT/bench.md"
grep -E '\| 2\^(20|24) ' "$OUT/bench.md" | cut -d'|' -f1-14

log "resident steps (the step loop): np 1 and np 2, cuda, 20 steps, spheres and ellipsoids"
{
  "$CG" generate "$W/e20.h5" -n 1048576 --seed 20 --kind ellipsoids -q
  for np in 1 2; do
    for sc in s22 e20; do
      echo "=== steps $sc np=$np"
      mpirun --bind-to none -np $np "$CG" detect "$W/$sc.h5" -o "$W/steps.$sc.np$np.h5" --backend cuda --steps 20
    done
  done
  for sc in s22 e20; do echo "compare steps $sc np1/np2: $("$CG" compare "$W/steps.$sc.np1.h5" "$W/steps.$sc.np2.h5" 2>&1 | tail -1)"; done
} >"$OUT/steps.log" 2>&1
grep -E '===|^compare|error|step|resident' "$OUT/steps.log" | head -40

log "memcheck (CUDA cases)"
timeout 200 compute-sanitizer --tool memcheck --leak-check full "$BIN/contactgrid_tests" \
  --gtest_filter='*cuda*:*Cuda*' >"$OUT/memcheck.log" 2>&1
grep -E 'ERROR SUMMARY|LEAK SUMMARY|^\[  (PASSED|FAILED) ' "$OUT/memcheck.log" | head
log "done"
