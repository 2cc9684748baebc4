#!/usr/bin/env bash
# The eighth session's device checks of the lead's work (#37: where a file job's one-time costs go):
#   filejob    2^24 spheres and ellipsoids, fp32, page cache → page cache: the stage table and the
#              process's wall time, three runs each, with the device made ready while the scene is read
#              (kernels/device_warm_up.hpp, the default) and without (CONTACTGRID_DEVICE_WARM_UP=0: the
#              context made after the read, each kernel loaded at its first launch inside the stages)
#   suite      the whole unit suite with its CUDA cases (and its command-line cases on this binary)
#   BIN=dir OUT=dir [PARTS="filejob suite"] jobs/gpu_s8_check.sh
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
mkdir -p "$OUT"
failed=()
PARTS=" ${PARTS:-filejob suite} "
export BIN CG_BINARY=$(realpath "$CG") CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpiexec)
wants() { [[ $PARTS == *" $1 "* ]]; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name --format=csv,noheader; git log --oneline -1 2>/dev/null;
  echo "THP: $(cat /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null)"; } | tee "$OUT/device.txt"

stage_table() { sed -n '/contactgrid detect:/p;/^  stage/,/^  total/p'; }

if wants filejob; then
  log "== #37 file jobs: one-time costs of a new process"
  timeout 120 "$BIN/contactgrid_tests" --gtest_filter='DeviceWarmUp*' >"$OUT/unit_warm_up.log" 2>&1 || failed+=(unit_warm_up)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_warm_up.log"
  dir=/dev/shm/cg_filejob
  mkdir -p "$dir"
  { "$CG" generate "$dir/s24.h5" -n 16777216 --seed 7 -q &&
    "$CG" generate "$dir/e24.h5" --kind ellipsoids -n 16777216 --seed 7 -q; } || failed+=(generate)
  for scene in s24 e24; do
    for warm in 0 1; do
      for run in 1 2 3; do
        echo "== $scene warm-up $warm run $run"
        /usr/bin/time -f "wall %e s, max RSS %M KiB" env CONTACTGRID_DEVICE_WARM_UP=$warm \
          "$CG" detect "$dir/$scene.h5" -o "$dir/c_${scene}_$warm.h5" --backend cuda --precision fp32 -v \
          >"$OUT/run.txt" 2>&1 || failed+=("filejob_$scene")
        stage_table <"$OUT/run.txt"; grep -E "^wall|made ready" "$OUT/run.txt"
      done
    done
    "$CG" compare "$dir/c_${scene}_0.h5" "$dir/c_${scene}_1.h5" | tail -1 || failed+=("compare_$scene")
  done >"$OUT/filejob.log" 2>&1
  rm -f "$OUT/run.txt"
  cat "$OUT/filejob.log"
  rm -rf "$dir"
fi

if wants suite; then
  log "== the whole unit suite"
  timeout 420 "$BIN/contactgrid_tests" >"$OUT/unit_suite.log" 2>&1 || failed+=(suite)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_suite.log" | head -40
  xz -T4 -f "$OUT/unit_suite.log"
fi

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}"
  exit 1
fi
