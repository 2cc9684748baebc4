#!/usr/bin/env bash
# The wave's GPU checks in three device calls (each under the device's 10-minute limit), every check
# one engineer's script run as written:
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh a     one GPU: the whole unit suite with its CUDA cases,
#                                                 the broad phases (#34), runaway scenes (#35), the
#                                                 host path table (#37)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh b     one GPU: contact identity and simulate (#31 §4, #32),
#                                                 bodies that move on one GPU (#31)
#   BIN=dir OUT=dir jobs/gpu_wave5_check.sh two   two GPUs: bodies that move at np 2 (#31)
# BIN holds the CUDA build's contactgrid, contactgrid_tests, contactgrid_mpi_tests and
# contactgrid_cuda_bench. Each part writes under $OUT/<part>/; the script exits non-zero naming every
# script that failed.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}
export BIN
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
host_path() {
  "$BIN/contactgrid_cuda_bench" 20 24 2 10 auto spheres >"$OUT/bench.md" 2>&1 || return 1
  sed -n '/Host arrays/,$p' "$OUT/bench.md"
}

{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } 2>&1 | tee "$OUT/device.txt"
case ${1:-a} in
  a)
    part unit unit
    part broadphase jobs/gpu_broadphase_check.sh
    part faults jobs/gpu_faults_check.sh
    part hostpath host_path ;;
  b)
    part simulate jobs/gpu_simulate_check.sh
    part steploop jobs/gpu_steploop_check.sh one ;;
  two)
    part steploop_two jobs/gpu_steploop_check.sh two ;;
esac
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}"
  exit 1
fi
echo "all passed"
