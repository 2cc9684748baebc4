#!/usr/bin/env bash
# The wave's GPU checks in device calls of under the device's 10-minute limit each, every check one
# engineer's script run as written:
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh a     one GPU: the whole unit suite with its CUDA cases,
#                                                 the broad phases' checks (#34)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh b     one GPU: simulate (#32: physics on CUDA, steps/s and
#                                                 the stage breakdown)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh c     one GPU: bodies that move on one GPU (#31), contacts in
#                                                 pieces under a memory limit (#37)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh d     one GPU: the broad phases' CPU = CUDA comparison at
#                                                 2^18 and their timing table (#34)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh f     one GPU: the file jobs of #37 (2^24 spheres and
#                                                 ellipsoids, fp32, file in the page cache → file) and
#                                                 the host path table
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh py    one GPU: the Python module (#33) and the laptop mode on
#                                                 two quiet cores (#33, #37; .devbin/py packed by
#                                                 jobs/gpu_python_check.sh pack)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh two   two GPUs: bodies that move at np 2 (#31), simulate
#                                                 under mpirun on two GPUs (#32)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh e     one GPU: the whole unit suite, simulate's steps/s and
#                                                 stages (#32), bodies that move on one GPU (#31)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh g     one GPU: the unit cases of simulate and pieces,
#                                                 simulate's steps/s (#32), contacts in pieces (#37), the
#                                                 resident steps by radius and auto's rows (#34)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh l     the pieces' unit cases; the laptop mode on two quiet
#                                                 cores (#33, #37)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh s1    one GPU: the whole unit suite, the host path's 16-byte
#                                                 upload and direct download (#37)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh s2    one GPU: the resident steps in cell order (#31), the
#                                                 levels' cost-model cells (#34)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh s3    one GPU: simulate before/after (#32)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh s4    the laptop mode's cell list on two quiet cores (#33,
#                                                 #37), the file jobs (#37)
# BIN holds the CUDA build's contactgrid, contactgrid_tests, contactgrid_mpi_tests,
# contactgrid_cuda_bench, host_stage_bench, host_bandwidth and file_write_bandwidth. Each part writes $OUT/<part>.tgz; the
# script exits non-zero naming every script that failed.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}
export BIN
# the unit cases that run the command line take this copy's binary and source tree (tests/support/paths.hpp)
export CG_BINARY=$(realpath "$BIN/contactgrid") CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpiexec)
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
part() {  # part NAME COMMAND...: OUT=$OUT/NAME for the command; its output kept in NAME.log
  local name=$1; shift
  log "== $name"
  mkdir -p "$OUT/$name"
  OUT="$OUT/$name" "$@" >"$OUT/$name.log" 2>&1 || failed+=("$name")
  tail -25 "$OUT/$name.log"
  tar czf "$OUT/$name.tgz" -C "$OUT" "$name" && rm -rf "${OUT:?}/$name"  # one file: the device returns few
}
unit() {
  "$BIN/contactgrid_tests" >"$OUT/unit_tests.log" 2>&1
  local rc=$?
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_tests.log" | head -30
  return $rc
}
unit_filtered() {  # unit_filtered FILTER: the unit cases of FILTER (after a fix, the cases it touches)
  "$BIN/contactgrid_tests" --gtest_filter="$1" >"$OUT/unit_tests.log" 2>&1
  local rc=$?
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_tests.log" | head -30
  return $rc
}
host_path() {
  "$BIN/contactgrid_cuda_bench" 20 24 2 10 auto spheres >"$OUT/bench.md" 2>&1 || return 1
  sed -n '/Host arrays/,$p' "$OUT/bench.md"
}
file_job() {  # the stage table of two runs of each: the second is the figure (page cache warm)
  local dir=${SCRATCH:-/dev/shm}/cg_filejob
  mkdir -p "$dir" || return 1
  "$BIN/contactgrid" generate "$dir/s24.h5" -n 16777216 --seed 7 -q || return 1
  "$BIN/contactgrid" generate "$dir/e24.h5" --kind ellipsoids -n 16777216 --seed 7 -q || return 1
  ls -l "$dir"
  local scene rc=0
  for scene in s24 e24; do
    for run in 1 2; do
      echo "== $scene run $run"
      "$BIN/contactgrid" detect "$dir/$scene.h5" -o "$dir/c_$scene.h5" --backend cuda --precision fp32 -v \
        2>&1 | sed -n '/contactgrid detect/p;/stage/,$p' || rc=1
    done
    ls -l "$dir/c_$scene.h5"
  done
  # the host's own file-write bandwidth, the floor of the write stage (tests/bench/file_write_bandwidth.cpp)
  [ -x "$BIN/file_write_bandwidth" ] && "$BIN/file_write_bandwidth" "$dir" 375 && "$BIN/file_write_bandwidth" /tmp 375
  rm -rf "$dir"
  return $rc
}
python_module() { jobs/gpu_python_check.sh run "${PY:-.devbin/py}" "$OUT"; }

{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } 2>&1 | tee "$OUT/device.txt"
case ${1:-a} in
  a)
    part unit unit
    part broadphase jobs/gpu_broadphase_check.sh check ;;
  b)
    part simulate jobs/gpu_simulate_check.sh unit perf ;;
  c)
    part steploop jobs/gpu_steploop_check.sh one
    part pieces env MODE=pieces jobs/gpu_hostpath_check.sh ;;
  d)
    part broad_compare jobs/gpu_broadphase_check.sh compare
    part broad_table jobs/gpu_broadphase_check.sh table ;;
  f)
    part filejob file_job
    part hostpath host_path ;;
  py)
    part python python_module
    part library jobs/gpu_library_check.sh "${PY:-.devbin/py}" ;;
  e)
    part unit unit
    part simulate jobs/gpu_simulate_check.sh perf
    part steploop jobs/gpu_steploop_check.sh one ;;
  g)
    part unit_g unit_filtered 'Dem*:Pieces*:Simulate*:AutoBroadPhase*'
    part simulate jobs/gpu_simulate_check.sh perf
    part pieces env MODE=pieces jobs/gpu_hostpath_check.sh
    part broad_steps jobs/gpu_broadphase_check.sh steps ;;
  l)
    part unit_pieces unit_filtered 'Pieces*'
    part laptop env MODE=laptop jobs/gpu_hostpath_check.sh ;;
  s1)
    part unit unit
    part library env PART=hostpath jobs/gpu_library_check.sh "$BIN" ;;
  s2)
    part steploop jobs/gpu_steploop_check.sh one
    part broad_cells jobs/gpu_broadphase_check.sh cells ;;
  s3)
    part simulate jobs/gpu_simulate_check.sh unit perf ;;
  s4)
    part laptop env MODE=laptop jobs/gpu_hostpath_check.sh
    part filejob file_job ;;
  two)
    part steploop_two jobs/gpu_steploop_check.sh two
    part simulate_two jobs/gpu_simulate_check.sh mpi2 two ;;
esac
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}"
  exit 1
fi
echo "all passed"
