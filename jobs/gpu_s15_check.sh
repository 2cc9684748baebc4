#!/usr/bin/env bash
# The fifteenth session's GPU checks (issue #37's host path), from the repository root on the device:
#   PART=host OUT=dir jobs/gpu_s15_check.sh   (binaries: .devbin/n.tar.xz)
#   unit    the whole unit suite with the GPU (every CUDA host-array call now takes the device's bounds),
#           then contactgrid_mpi_tests' CUDA cases at np 2; expect no FAILED line
#   file    2^24 sphere and ellipsoid file jobs (CUDA fp32, /dev/shm -> /dev/shm), 3 new processes each
#           with the default host path and CONTACTGRID_CUDA_HOST_PATH=old (PATHS may add dlstream: the
#           first download streamed through the ring), interleaved: each run's stage
#           table, then /contacts of each path compared with old's (expect IDENTICAL)
#   hostunit  the host path cases (HostPath*, UploadPack*, HostPool*) with the GPU
#   host    contactgrid_cuda_bench LO..HI (20 20) SCENE (spheres; NO_TRACE=1: no traced run): the host path table with every stage's median
#           (plan on the host's clock, the rest CUDA events; "wall - sum" is what no stage holds), and
#           the same calls under CONTACTGRID_CUDA_TRACE=1: when the host queued each stage (host_trace.log)
set -u
cd "$(dirname "$0")/.."
[ -d .devbin/n ] || tar xJf .devbin/n.tar.xz -C .devbin
source .devrt/env.sh .devrt >/dev/null 2>&1
B=$(realpath .devbin/n); OUT=${OUT:-/tmp/out}; PART=${PART:-host}
export GTEST_COLOR=no OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
export CG_BINARY=$B/contactgrid CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpirun)
mkdir -p "$OUT"
case $PART in
unit)
  timeout 420 "$B/contactgrid_tests" >"$OUT/unit.log" 2>&1
  echo "-- unit (rc $?)"; grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$OUT/unit.log"; grep -E '^\[  (FAILED|SKIPPED) +\]' "$OUT/unit.log" | head -20
  timeout 150 mpirun --bind-to none -np 2 "$B/contactgrid_mpi_tests" --gtest_filter='*Cuda*:*cuda*' >"$OUT/mpi2.log" 2>&1
  echo "-- np 2 CUDA cases (rc $?)"; grep -E '^\[  (PASSED|FAILED) ' "$OUT/mpi2.log" ;;
hostunit)
  timeout 200 "$B/contactgrid_tests" --gtest_filter='HostPath*:UploadPack*:HostPool*' >"$OUT/hostunit.log" 2>&1
  echo "-- host path cases (rc $?)"; grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$OUT/hostunit.log" ;;
file)
  d=/dev/shm/cg15; rm -rf "$d"; mkdir -p "$d"
  timeout 90 "$B/contactgrid" generate "$d/s24.h5" -n 16777216 --seed 7 -q
  timeout 90 "$B/contactgrid" generate "$d/e24.h5" --kind ellipsoids -n 16777216 --seed 7 -q
  for scene in s24 e24; do
    for run in 1 2 3; do
      for p in ${PATHS:-device old}; do
        rm -f "$d/c_$p.h5"
        hp=device; [ "$p" = old ] && hp=old
        dl=; [ "$p" = dlstream ] && dl=streamed
        CONTACTGRID_CUDA_DOWNLOAD=$dl CONTACTGRID_CUDA_TRACE=${TRACE:-0} CONTACTGRID_CUDA_HOST_PATH=$hp /usr/bin/time -f "wall %e" timeout 60 "$B/contactgrid" detect "$d/$scene.h5" \
          -o "$d/c_$p.h5" --backend cuda --precision fp32 -v >"$OUT/run.txt" 2>&1
        echo "== $scene $p run $run (rc $?)"
        sed -n '/^  stage/,/^  total/p;/^wall/p' "$OUT/run.txt" | tr '\n' ' ' | tr -s ' '; echo
        grep -E '^(host path|cuda trace)' "$OUT/run.txt" | cut -c1-400
      done
    done
    for p in ${PATHS:-device old}; do
      [ "$p" = old ] && continue
      echo -n "compare $scene $p vs old: "; "$B/contactgrid" compare "$d/c_old.h5" "$d/c_$p.h5" 2>&1 | tail -1
    done
  done
  rm -rf "$d" "$OUT/run.txt" ;;
host)
  LO=${LO:-20}; HI=${HI:-20}; SCENE=${SCENE:-spheres}
  timeout 200 "$B/contactgrid_cuda_bench" "$LO" "$HI" 2 10 auto "$SCENE" >"$OUT/host_bench.log" 2>&1
  echo "-- bench (rc $?)"; sed -n '/^Host arrays/,$p' "$OUT/host_bench.log"
  [ -n "${NO_TRACE:-}" ] && exit 0
  CONTACTGRID_CUDA_TRACE=1 timeout 200 "$B/contactgrid_cuda_bench" "$LO" "$HI" 2 10 auto "$SCENE" \
    >"$OUT/host_trace.out" 2>"$OUT/host_trace.log"
  echo "-- traced (rc $?)"; grep -c 'cuda trace' "$OUT/host_trace.log"; grep 'upload queued' "$OUT/host_trace.log" | tail -40 ;;
esac
