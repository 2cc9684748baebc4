#!/usr/bin/env bash
# One GPU call for the ellipsoid narrow stage (issue #12's speed targets): the unit cases that touch CUDA
# and shapes, CLI CPU vs CUDA byte-identical /contacts on ellipsoid and mixed scenes (fp32, fp64,
# --fields full, the hard pairs' whole set one warp per pair and one thread per pair), and
# contactgrid_cuda_bench on the scenes named in SCENES (default ellipsoids) with the knobs named in
# BENCH_ENVS (each a comma-separated set of VAR=value, "-" for none) — and with $BASE_BIN's bench first
# when given (the commit before, in the same call).
#   BIN=dir OUT=dir [BASE_BIN=dir] [SIZES="20 24 4 10"] [SCENES="ellipsoids spheres"] [SKIP_TESTS=1]
#   jobs/gpu_narrow_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
SIZES=${SIZES:-20 24 4 10}
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
if [ "${SKIP_TESTS:-0}" != 1 ]; then
  log "unit cases: CUDA, shapes, ellipsoids, precision"
  "$BIN/contactgrid_tests" --gtest_filter="${FILTER:-*uda*:*Shape*:*Ellipsoid*:*Precision*}" >"$OUT/unit.log" 2>&1
  echo "exit $?"
  grep -E '^\[  (PASSED|FAILED) |^\[  FAILED  \]|runs in batches' "$OUT/unit.log" | head -20
  log "CLI: cpu vs cuda byte-identical /contacts (2^18 ellipsoids and mixed; fp32, fp64; warp / thread whole set)"
  {
    "$CG" generate "$W/e.h5" -n 262144 --seed 5 --kind ellipsoids -q
    "$CG" generate "$W/m.h5" -n 262144 --seed 6 --kind mixed --ellipsoid-fraction 0.5 -q
    for s in e m; do
      for prec in fp32 fp64; do
        "$CG" detect "$W/$s.h5" -o "$W/$s.cpu.$prec.h5" --backend cpu --precision $prec --fields full -q
        for ws in 1 0; do
          CONTACTGRID_CUDA_WARP_SOLVE=$ws "$CG" detect "$W/$s.h5" -o "$W/$s.cuda.$prec.$ws.h5" --backend cuda \
            --precision $prec --fields full -q
          echo "compare $s cpu/cuda $prec warp_solve=$ws: $("$CG" compare "$W/$s.cpu.$prec.h5" "$W/$s.cuda.$prec.$ws.h5" 2>&1 | tail -1)"
        done
      done
    done
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
