#!/usr/bin/env bash
# One batched run on a GPU machine (the library's device tool, or any node with GPUs): the test
# suite with its CUDA cases, Bullet validation, the bench table (CPU and CUDA), CPU-vs-CUDA
# byte-identical output at the CLI, and, with 2+ GPUs, MPI correctness and scaling.
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_check.sh [single|multi|all]
# BIN holds contactgrid, contactgrid-bullet-float, contactgrid_tests, contactgrid_validation_tests,
# plot_bench.gp. Logs and CSVs go to $OUT (at most 8 files).
set -u
BIN=${BIN:-.devbin}; OUT=${OUT:-/tmp/out}; WHAT=${1:-all}
mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export CONTACTGRID_BULLET_FLOAT="$BIN/contactgrid-bullet-float"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
NGPU=$(nvidia-smi -L 2>/dev/null | wc -l)
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; echo "GPUs: $NGPU"; } >"$OUT/device.txt"

if [ "$WHAT" != multi ]; then
  log "tests"
  { "$BIN/contactgrid_tests" 2>&1 | grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]|Failure' ;
    "$BIN/contactgrid_validation_tests" 2>&1 | grep -E '^\[  (PASSED|FAILED) |^\[==========\]|Failure'; } >"$OUT/tests.log" 2>&1
  tail -4 "$OUT/tests.log"
  log "CLI: cpu vs cuda, byte-identical, then Bullet"
  {
    "$CG" generate "$W/s22.h5" -n 4194304 --seed 22 -q
    for prec in fp64 fp32; do
      "$CG" detect "$W/s22.h5" -o "$W/cpu.$prec.h5" --backend cpu --precision $prec --fields full
      "$CG" detect "$W/s22.h5" -o "$W/cuda.$prec.h5" --backend cuda --precision $prec --fields full
      echo "compare cpu/cuda $prec:"; "$CG" compare "$W/cpu.$prec.h5" "$W/cuda.$prec.h5"
    done
    "$CG" validate "$W/s22.h5" "$W/cuda.fp64.h5" --sample 16
    "$CG" generate "$W/s20.h5" -n 1048576 --seed 20 -q
    "$CG" detect "$W/s20.h5" -o "$W/c20.h5" --backend cuda
    "$CG" validate "$W/s20.h5" "$W/c20.h5"
  } >"$OUT/cli.log" 2>&1
  grep -E 'IDENTICAL|DIFFERENT|PASS|FAIL|error' "$OUT/cli.log"
  log "bench"
  "$CG" bench --lo 10 --bullet-hi 20 --engine-hi 24 --repetitions 5 --csv "$OUT/bench.csv" --no-plot \
    >"$OUT/bench.log" 2>&1
  tail -20 "$OUT/bench.log"
fi

if [ "$WHAT" != single ] && [ "$NGPU" -ge 2 ]; then
  log "MPI on $NGPU GPUs"
  {
    for e in 24 25 26; do "$CG" generate "$W/m$e.h5" -n $((1 << e)) --seed $e -q; done
    "$CG" detect "$W/m24.h5" -o "$W/m24.np1.h5" --backend cuda --precision fp64 -q
    mpirun --bind-to none -np 2 "$CG" detect "$W/m24.h5" -o "$W/m24.np2.h5" --backend cuda --precision fp64 -q
    echo "compare np1/np2 fp64 cuda:"; "$CG" compare "$W/m24.np1.h5" "$W/m24.np2.h5"
    for e in 24 25 26; do
      for np in 1 2; do
        echo "=== N=2^$e np=$np (cuda, fp32; then 30 resident steps)"
        mpirun --bind-to none -np $np "$CG" detect "$W/m$e.h5" -o "$W/out.h5" --backend cuda --precision fp32 \
          --steps 30
      done
    done
  } >"$OUT/mpi.log" 2>&1
  grep -E 'IDENTICAL|DIFFERENT|===|detect:|^  (read|redistribute|halo|detect|gather|exchange|merge|write|total|interior|boundary|step) |^    (upload|download) |^resident' "$OUT/mpi.log" | head -160
fi
log "done"
