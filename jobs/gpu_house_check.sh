#!/usr/bin/env bash
# The fourteenth session's house-keeping check on one GPU (a pure move: nothing may change). The CUDA
# backend's translation unit (kernels/cuda/cuda_backend.cu) now includes its class and sequence
# (backend_class.cuh), its copies (backend_copies.cuh: history, download_contacts, pinning) and its
# resident calls (backend_resident.cuh: resident bodies, splice, extent, row lists), and the narrow stage
# is narrow.cuh (spheres, the rejecting path) + narrow_shapes.cuh (the ellipsoid passes, WarpRuns). This
# runs, from the repository root on the device,
#   BIN=<dir with contactgrid_tests and contactgrid> OUT=dir jobs/gpu_house_check.sh
#   cuda    contactgrid_tests --gtest_filter='*Cuda*:*cuda*' (every CUDA case: CPU = CUDA bytes of the
#           engine, narrow, shapes, skin, history, resident, row lists, DEM); none may fail or skip
#   moved   the split test files' suites (Ellipsoid*, CentreCut*, Hdf5Io*, Dem*), CUDA cases included
# Expect (H100 or H200): both lines "failed 0 skipped 0" and "ok" at the end; a skipped CUDA case means
# the process saw no GPU (the check then fails). About 2-4 minutes; each run has a 280 s timeout.
set -u
cd "$(dirname "$0")/.."
BIN=$(realpath -m "${BIN:-build/tests}")
OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1
  git log -1 --format='commit %h %s' 2>/dev/null; } | tee "$OUT/device.txt"
[ -x "$BIN/contactgrid_tests" ] || { echo "no $BIN/contactgrid_tests (set BIN)"; exit 2; }
# the CLI cases run the contactgrid beside the tests (else the build tree's path, absent on the device)
export CG_BINARY=${CG_BINARY:-$BIN/contactgrid} CG_SOURCE_DIR=${CG_SOURCE_DIR:-$PWD}
export CG_MPIEXEC=${CG_MPIEXEC:-$(command -v mpirun)} GTEST_COLOR=no

run() {  # run <tag> <gtest filter>: the counts of one run, in one line
  local tag=$1 filter=$2 rc
  timeout 280 "$BIN/contactgrid_tests" --gtest_filter="$filter" >"$OUT/$tag.log" 2>&1
  rc=$?
  local passed failed_n skipped
  passed=$(grep -c '^\[       OK \]' "$OUT/$tag.log")
  failed_n=$(grep -c '^\[  FAILED  \] .*(' "$OUT/$tag.log")
  # (cases that skip on a GPU machine by design: the no-GPU message, and a mixed-precision walk
  # that needs no device)
  skipped=$(grep '^\[  SKIPPED \] .*(' "$OUT/$tag.log" | grep -cvE 'CudaBackendWithoutGpu|MixedPrecisionWalk')
  printf '%-6s rc %-3s passed %-5s failed %-3s skipped %-3s  %s\n' "$tag" "$rc" "$passed" "$failed_n" \
    "$skipped" "$filter"
  grep '^\[  FAILED  \] .*(' "$OUT/$tag.log" | head -10
  grep '^\[  SKIPPED \] .*(' "$OUT/$tag.log" | head -5
  [ "$rc" -eq 0 ] && [ "$failed_n" -eq 0 ] && [ "$skipped" -eq 0 ] && [ "$passed" -gt 0 ] || failed+=("$tag")
}

log "contactgrid_tests (each line: the run's counts)"
run cuda '*Cuda*:*cuda*'
run moved 'Ellipsoid*:CentreCut*:Hdf5Io*:Dem*'
if [ ${#failed[@]} -eq 0 ]; then
  log "ok"
else
  log "FAILED: ${failed[*]} (logs in $OUT)"
  exit 1
fi
