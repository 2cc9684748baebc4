#!/usr/bin/env bash
# One GPU call for this wave's work (issues #11 #12 #13 #21), on the device machine:
#   the whole unit suite with CUDA present; CLI CPU vs CUDA byte-identical /contacts and np 2 = np 1
#   (jobs/gpu_shapes_check.sh); validate on ellipsoid and mixed scenes (float Bullet, the judge);
#   contactgrid_cuda_bench on spheres (fp32, mixed, fp64 at 2^20 and 2^24) and on ellipsoid and mixed
#   scenes (2^16 … 2^22, 0.4 contacts per body); the precision study on both backends.
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_wave_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
log "unit suite"
"$BIN/contactgrid_tests" >"$OUT/unit.log" 2>&1; echo "exit $?"
grep -E '^\[  (PASSED|FAILED) |^\[  FAILED  \]|SKIPPED \]' "$OUT/unit.log" | head -20
grep -E 'certificate' "$OUT/unit.log" | head -4
log "CLI: cpu vs cuda byte-identical /contacts (every mode), mpirun np 2 vs np 1"
{
  "$CG" generate "$W/s.h5" -n 262144 --seed 4 -q
  "$CG" generate "$W/e.h5" -n 262144 --seed 5 --kind ellipsoids -q
  "$CG" generate "$W/m.h5" -n 262144 --seed 6 --kind mixed --ellipsoid-fraction 0.5 -q
  for s in s e m; do
    for prec in fp64 mixed fp32; do
      "$CG" detect "$W/$s.h5" -o "$W/$s.cpu.$prec.h5" --backend cpu --precision $prec --fields full -q
      "$CG" detect "$W/$s.h5" -o "$W/$s.cuda.$prec.h5" --backend cuda --precision $prec --fields full -q
      echo "compare $s cpu/cuda $prec: $("$CG" compare "$W/$s.cpu.$prec.h5" "$W/$s.cuda.$prec.h5" 2>&1 | tail -1)"
    done
    echo "compare $s mixed/fp64 (cuda): $("$CG" compare "$W/$s.cuda.mixed.h5" "$W/$s.cuda.fp64.h5" 2>&1 | tail -1)"
    mpirun --bind-to none -np 2 "$CG" detect "$W/$s.h5" -o "$W/$s.np2.h5" --backend cuda --fields full -q
    echo "compare $s np1/np2 cuda fp64: $("$CG" compare "$W/$s.cuda.fp64.h5" "$W/$s.np2.h5" 2>&1 | tail -1)"
  done
} >"$OUT/cli.log" 2>&1
grep -E '^compare' "$OUT/cli.log"; grep -ciE 'error' "$OUT/cli.log"
log "validate ellipsoids and mixed (CUDA contacts, float Bullet)"
for k in ellipsoids mixed; do
  "$CG" generate "$W/v_$k.h5" -n 65536 --seed 3 --kind $k -q
  "$CG" detect "$W/v_$k.h5" -o "$W/v_$k.c.h5" --backend cuda -q
  "$CG" validate "$W/v_$k.h5" "$W/v_$k.c.h5" 2>&1 | tail -6
done
log "cuda bench: spheres"
"$BIN/contactgrid_cuda_bench" 20 24 4 10 auto spheres >"$OUT/bench_spheres.txt" 2>&1; grep -E '^\| 2' "$OUT/bench_spheres.txt"
for s in ellipsoids mixed; do
  log "cuda bench: $s"
  "$BIN/contactgrid_cuda_bench" 16 22 2 10 auto $s >"$OUT/bench_$s.txt" 2>&1; grep -E '^#|^\| 2' "$OUT/bench_$s.txt"
done
log "study (cpu, cuda)"
timeout 300 "$CG" study --backends cpu,cuda --csv "$OUT/study_gpu.csv" --svg "$OUT/study_gpu.svg" \
  >"$OUT/study_gpu.txt" 2>"$OUT/study_gpu.progress"; echo "study exit $?"
cat "$OUT/study_gpu.txt" | head -80
log "done"
