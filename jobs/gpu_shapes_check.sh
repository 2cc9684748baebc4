#!/usr/bin/env bash
# Ellipsoid and mixed scenes on one GPU: the unit suite's shape cases, CLI CPU vs CUDA byte-identical
# /contacts (fp64, fp32, --fields full; jobs/cpu_cuda_compare.sh), mpirun np 2 (CUDA) vs the CPU, and the per-stage times of the
# CUDA engine on ellipsoid scenes of 2^16 … 2^22 (the summary's stage table; file job, one rank).
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_shapes_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
log "shape cases of the unit suite (not Cli.*: they run the build tree's binary)"
"$BIN/contactgrid_tests" --gtest_filter='*Shape*:*shape*:*Ellipsoid*:-Cli.*' 2>&1 | grep -E '^\[  (PASSED|FAILED) |Failure' | head
log "CLI: ellipsoids and mixed, cpu vs cuda, np 1 vs 2"
. "$(dirname "$0")/cpu_cuda_compare.sh"
{
  "$CG" generate "$W/e.h5" -n 262144 --seed 5 --kind ellipsoids -q
  "$CG" generate "$W/m.h5" -n 262144 --seed 6 --kind mixed --ellipsoid-fraction 0.5 -q
  for s in e m; do
    for prec in fp64 fp32; do
      DETECT_ARGS="--fields full" compare_cuda "$W/$s" $prec "$s cpu/cuda $prec"
    done
    DETECT_ARGS="--fields full" MPIRUN_NP=2 compare_cuda "$W/$s" fp64 "$s cpu/cuda np 2 fp64"
  done
} >"$OUT/shapes_cli.log" 2>&1
grep -E 'compare|rror' "$OUT/shapes_cli.log"
log "CUDA engine on ellipsoid scenes: summary per N and precision"
for e in 16 18 20 22; do
  "$CG" generate "$W/e$e.h5" -n $((1 << e)) --seed $e --kind ellipsoids -q
  for prec in fp32 fp64; do
    echo "=== 2^$e ellipsoids $prec"
    "$CG" detect "$W/e$e.h5" -o "$W/o.h5" --backend cuda --precision $prec
  done
done >"$OUT/shapes_perf.log" 2>&1
grep -E '===|contactgrid detect:|ellipsoids|^    (pack|pairs|order|narrow|sort|entries)|^  detect' "$OUT/shapes_perf.log"
log "done"
