#!/usr/bin/env bash
# The seventh session's device check of the lead's change (#34): the levels' pair estimate with the
# pairs across levels (CUDA = CPU estimate, the pile refused), and what the estimate costs where
# detect makes it (bench-broad --estimate) against the library's default (no estimate):
# and the session's merged branches' checks:
#   suite      the whole unit suite with its CUDA cases (and its command-line cases on this binary)
#   steploop   jobs/gpu_steploop_check.sh quick (#31: the in-place build and the one-kernel narrow)
#   BIN=dir OUT=dir [PARTS="unit levels suite steploop"] jobs/gpu_s7_check.sh
#   (BIN: the CUDA build's contactgrid, contactgrid_tests, contactgrid_mpi_tests; PARTS: default all)
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
mkdir -p "$OUT"
failed=()
PARTS=" ${PARTS:-unit levels suite steploop} "
export BIN CG_BINARY=$(realpath "$CG") CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpiexec)
wants() { [[ $PARTS == *" $1 "* ]]; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name --format=csv,noheader; git log --oneline -1 2>/dev/null; } | tee "$OUT/device.txt"

if wants unit; then
  log "== unit: the pair estimate and the broad phases, CUDA and CPU"
  timeout 200 "$BIN/contactgrid_tests" --gtest_filter='PairEstimate*:*Levels*:BroadPhase*:AutoBroadPhase*' \
    >"$OUT/unit_levels.log" 2>&1 || failed+=(unit_levels)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_levels.log"
fi

if wants levels; then
  log "== #34 the levels' estimate at 2^24 fp32: without (the library's default) and with (detect's)"
  for est in none estimate; do
    flag=(); [ $est = estimate ] && flag=(--estimate)
    timeout 200 "$CG" bench-broad --backend cuda --precision fp32 --families uniform,bimodal10,bimodal100,loguniform1000 \
      --broad-phases levels --lo 24 --hi 24 --repetitions 5 "${flag[@]}" >"$OUT/levels_$est.txt" 2>&1 ||
      failed+=("levels_$est")
    echo "-- $est"; cat "$OUT/levels_$est.txt"
  done
fi

if wants suite; then
  log "== the whole unit suite"
  timeout 420 "$BIN/contactgrid_tests" >"$OUT/unit_suite.log" 2>&1 || failed+=(suite)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_suite.log" | head -40
  xz -T4 -f "$OUT/unit_suite.log"
fi

if wants steploop; then
  log "== #31 steploop"
  mkdir -p "$OUT/steploop"
  OUT="$OUT/steploop" timeout 300 jobs/gpu_steploop_check.sh quick >"$OUT/steploop.log" 2>&1 || failed+=(steploop)
  tail -60 "$OUT/steploop.log"
  mv "$OUT"/steploop/*.tgz "$OUT/" 2>/dev/null; rm -rf "$OUT/steploop"
fi

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}"
  exit 1
fi
