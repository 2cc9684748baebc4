#!/usr/bin/env bash
# One GPU call for the ellipsoid narrow stage (issue #12's speed targets): the unit cases that touch CUDA
# and shapes, CLI CPU vs CUDA byte-identical /contacts on ellipsoid and mixed scenes (fp32, fp64,
# --fields full, the hard pairs' whole set one warp per pair and one thread per pair), and
# contactgrid_cuda_bench on the scenes named in SCENES (default ellipsoids) with the knobs named in
# BENCH_ENVS (each a comma-separated set of VAR=value, "-" for none) — and with $BASE_BIN's bench first
# when given (the commit before, in the same call).
#   BIN=dir OUT=dir [BASE_BIN=dir] [SIZES="20 24 4 10"] [SCENES="ellipsoids spheres"] [SKIP_TESTS=1]
#   [LARGE=0] jobs/gpu_narrow_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
SIZES=${SIZES:-20 24 4 10}
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
if [ "${SKIP_TESTS:-0}" != 1 ]; then
  log "unit cases: CUDA, shapes, ellipsoids, precision"
  "$BIN/contactgrid_tests" --gtest_filter="${FILTER:-*uda*:*Shape*:*Ellipsoid*:*Precision*}" >"$OUT/unit.log" 2>&1
  echo "exit $?"
  grep -E '^\[  (PASSED|FAILED) |^\[  FAILED  \]|runs in batches' "$OUT/unit.log" | head -20
  log "CLI: cpu vs cuda byte-identical /contacts (2^18 ellipsoids and mixed, fp32 and fp64, --fields full: warp /"
  log "     thread whole set; LARGE=1 (default): 2^22 ellipsoids, mixed and spheres, renumbering auto / on / off,"
  log "     type passes, mpirun -np 2)"
  . "$(dirname "$0")/cpu_cuda_compare.sh"
  {
    "$CG" generate "$W/e.h5" -n 262144 --seed 5 --kind ellipsoids -q
    "$CG" generate "$W/m.h5" -n 262144 --seed 6 --kind mixed --ellipsoid-fraction 0.5 -q
    for s in e m; do
      for prec in fp32 fp64; do
        for ws in 1 0; do
          DETECT_ARGS="--fields full" compare_cuda "$W/$s" $prec "$s cpu/cuda $prec warp_solve=$ws" \
            CONTACTGRID_CUDA_WARP_SOLVE=$ws
        done
      done
    done
    if [ "${LARGE:-1}" = 1 ]; then
      "$CG" generate "$W/e22.h5" -n 4194304 --seed 9 --kind ellipsoids -q
      "$CG" generate "$W/m22.h5" -n 4194304 --seed 10 --kind mixed --ellipsoid-fraction 0.5 -q
      "$CG" generate "$W/s22.h5" -n 4194304 --seed 11 -q
      for s in e22 m22 s22; do
        for prec in fp32 fp64; do
          compare_cuda "$W/$s" $prec "$s cpu/cuda $prec"
          for knob in CONTACTGRID_CUDA_RENUMBER=1 CONTACTGRID_CUDA_RENUMBER=0 CONTACTGRID_CUDA_TYPE_PASSES=1; do
            compare_cuda "$W/$s" $prec "$s cpu/cuda $prec $knob" $knob
          done
          MPIRUN_NP=2 compare_cuda "$W/$s" $prec "$s cpu/cuda mpirun -np 2 $prec"
        done
      done
    fi
  } >"$OUT/cli.log" 2>&1
  grep -E '^compare' "$OUT/cli.log"; echo "error lines: $(grep -ciE 'error' "$OUT/cli.log")"
fi
for scene in ${SCENES:-ellipsoids}; do
  if [ -n "${BASE_BIN:-}" ]; then
    log "bench (base): contactgrid_cuda_bench $SIZES auto $scene"
    "$BASE_BIN/contactgrid_cuda_bench" $SIZES auto $scene >"$OUT/bench_base_$scene.md" 2>&1
    grep -E '^\| 2\^' "$OUT/bench_base_$scene.md"
  fi
  i=0
  for envs in ${BENCH_ENVS:--}; do
    i=$((i + 1))
    log "bench ($envs): contactgrid_cuda_bench $SIZES auto $scene"
    if [ "$envs" = - ]; then
      "$BIN/contactgrid_cuda_bench" $SIZES auto $scene >"$OUT/bench_${scene}_$i.md" 2>&1
    else
      env ${envs//,/ } "$BIN/contactgrid_cuda_bench" $SIZES auto $scene >"$OUT/bench_${scene}_$i.md" 2>&1
    fi
    grep -E '^\| (N|2\^)' "$OUT/bench_${scene}_$i.md"
  done
done
log "done"
