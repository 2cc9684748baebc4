#!/usr/bin/env bash
# Ellipsoid and mixed scenes on one GPU: the unit suite's shape cases, CLI CPU vs CUDA byte-identical
# /contacts (fp64, fp32, --fields full), mpirun np 2 (CUDA) vs np 1, and the per-stage times of the
# CUDA engine on ellipsoid scenes of 2^16 … 2^22 (the summary's stage table; file job, one rank).
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_shapes_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
log "shape cases of the unit suite"
"$BIN/contactgrid_tests" --gtest_filter='*Shape*:*shape*:*Ellipsoid*' 2>&1 | grep -E '^\[  (PASSED|FAILED) |Failure' | head
log "CLI: ellipsoids and mixed, cpu vs cuda, np 1 vs 2"
{
  "$CG" generate "$W/e.h5" -n 262144 --seed 5 --kind ellipsoids -q
  "$CG" generate "$W/m.h5" -n 262144 --seed 6 --kind mixed --ellipsoid-fraction 0.5 -q
  for s in e m; do
    for prec in fp64 fp32; do
      "$CG" detect "$W/$s.h5" -o "$W/$s.cpu.$prec.h5" --backend cpu --precision $prec --fields full -q
      "$CG" detect "$W/$s.h5" -o "$W/$s.cuda.$prec.h5" --backend cuda --precision $prec --fields full -q
      echo "compare $s cpu/cuda $prec:"; "$CG" compare "$W/$s.cpu.$prec.h5" "$W/$s.cuda.$prec.h5"
    done
    mpirun --bind-to none -np 2 "$CG" detect "$W/$s.h5" -o "$W/$s.np2.h5" --backend cuda --fields full -q
    echo "compare $s np1/np2 cuda fp64:"; "$CG" compare "$W/$s.cuda.fp64.h5" "$W/$s.np2.h5"
  done
} >"$OUT/shapes_cli.log" 2>&1
grep -E 'compare|IDENTICAL|DIFFERENT|rror' "$OUT/shapes_cli.log"
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
