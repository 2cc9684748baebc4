#!/usr/bin/env bash
# One GPU call for this wave's work (issues #11 #12 #13 #21), on the device machine:
#   the whole unit suite with CUDA present; CLI CPU vs CUDA byte-identical /contacts and np 2 = np 1
#   (jobs/gpu_shapes_check.sh); validate on ellipsoid and mixed scenes (float Bullet, the judge);
#   contactgrid_cuda_bench on spheres (fp32, mixed, fp64 at 2^20 and 2^24) and on ellipsoid and mixed
#   scenes (2^16 … 2^22, 0.4 contacts per body); the precision study on both backends; --precision auto
#   on cuda (default: mixed = fp64's bytes; --accuracy 1e-2,0.1: fp32).
#   BIN=dir-with-binaries OUT=results-dir [PART=first|second] jobs/gpu_wave_check.sh
# (first: tests, CLI, validate, cuda bench; second: the study and the bench against float Bullet)
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
if [ "${PART:-all}" != second ]; then
log "unit suite: the cases that touch CUDA, the precision modes, the study, the shapes"
"$BIN/contactgrid_tests" --gtest_filter="${FILTER:-*uda*:*Precision*:*Study*:*Shape*:*Ellipsoid*:*Skin*:*skin*}" \
  >"$OUT/unit.log" 2>&1; echo "exit $?"
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
  # --precision auto on cuda (the default): mixed, fp64's bytes; a lax --accuracy: fp32
  "$CG" detect "$W/s.h5" -o "$W/s.cuda.auto.h5" --backend cuda --fields full | grep -o 'precision auto: [a-z0-9]*, the cheapest on [a-z]*'
  echo "compare s auto/fp64 (cuda): $("$CG" compare "$W/s.cuda.auto.h5" "$W/s.cuda.fp64.h5" 2>&1 | tail -1)"
  "$CG" detect "$W/s.h5" -o "$W/s.cuda.lax.h5" --backend cuda --fields full --accuracy 1e-2,0.1 | grep -o 'precision auto: [a-z0-9]*, the cheapest on [a-z]*'
  echo "compare s auto-lax/fp32 (cuda): $("$CG" compare "$W/s.cuda.lax.h5" "$W/s.cuda.fp32.h5" 2>&1 | tail -1)"
} >"$OUT/cli.log" 2>&1
grep -E '^compare|^precision auto' "$OUT/cli.log"; grep -ciE 'error' "$OUT/cli.log"
log "validate ellipsoids and mixed (CUDA contacts, float Bullet)"
for k in ellipsoids mixed; do
  "$CG" generate "$W/v_$k.h5" -n 65536 --seed 3 --kind $k -q
  "$CG" detect "$W/v_$k.h5" -o "$W/v_$k.c.h5" --backend cuda -q
  "$CG" validate "$W/v_$k.h5" "$W/v_$k.c.h5" 2>&1 | tail -6
done
log "resident steps with shapes: 1 M mixed bodies, np 2, orientations refreshed; --spin turns them"
{
  "$CG" generate "$W/r.h5" -n 1000000 --seed 9 --kind mixed --ellipsoid-fraction 0.4 --rlow 0.3 --rhigh 1 \
    --contacts-per-body 1 -q
  "$CG" detect "$W/r.h5" -o "$W/r.one.h5" --backend cuda --precision fp64 --fields full -q
  mpirun --bind-to none -np 2 "$CG" detect "$W/r.h5" -o "$W/r.steps.h5" --backend cuda --precision fp64 \
    --fields full --steps 10
  mpirun --bind-to none -np 2 "$CG" detect "$W/r.h5" -o "$W/r.spin.h5" --backend cuda --precision fp64 \
    --fields full --steps 10 --spin 0.3
  "$CG" detect "$W/r.h5" -o "$W/r.spin1.h5" --backend cuda --precision fp64 --fields full --steps 10 --spin 0.3
  for f in steps spin spin1; do echo "compare one/$f: $("$CG" compare "$W/r.one.h5" "$W/r.$f.h5" 2>&1 | tail -1)"; done
} >"$OUT/steps.log" 2>&1
grep -E 'compare|contacts per step|turning|halo|rror' "$OUT/steps.log" | head -20
log "cuda bench: spheres"
"$BIN/contactgrid_cuda_bench" 20 24 4 10 auto spheres >"$OUT/bench_spheres.txt" 2>&1; grep -E '^\| 2' "$OUT/bench_spheres.txt"
for s in ellipsoids mixed; do
  log "cuda bench: $s"
  "$BIN/contactgrid_cuda_bench" 16 22 2 10 auto $s >"$OUT/bench_$s.txt" 2>&1; grep -E '^#|^\| 2' "$OUT/bench_$s.txt"
done
fi
[ "${PART:-all}" = first ] && { log "done (first part)"; exit 0; }
log "study (cpu, cuda)"
timeout 300 "$CG" study --backends cpu,cuda --csv "$OUT/study_gpu.csv" --svg "$OUT/study_gpu.svg" \
  >"$OUT/study_gpu.txt" 2>"$OUT/study_gpu.progress"; echo "study exit $?"
cat "$OUT/study_gpu.txt" | head -80
log "bench vs float Bullet: ellipsoids at 0.4 contacts per body (--contacts-per-body 0.87), 2^16 … 2^20"
for p in fp32 fp64; do
  timeout 200 "$CG" bench --kind ellipsoids --precision $p --contacts-per-body 0.87 --lo 16 --bullet-hi 20 \
    --engine-hi 20 --repetitions 10 --no-plot --csv "$OUT/bench_ell_${p}_h100.csv" >"$OUT/bench_ell_$p.txt" 2>&1
  echo "exit $?"; cat "$OUT/bench_ell_$p.txt" | tail -12
done
log "done"
