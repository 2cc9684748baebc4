#!/usr/bin/env bash
# Contact identity (#31 part 4) and contactgrid simulate (#32) on one GPU: the unit cases that compare
# the CUDA backend with the CPU bit for bit (history: Thrust's and the hand-written search; the
# granular dynamics: bodies, contacts with history, energies), a CLI run on both backends whose frames
# must be byte-identical, the history stage's time with either search, and simulate's steps/s at
# 2^20 and 2^24 bodies (fp32, a pour settled first; the summary's line).
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_simulate_check.sh
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgwork}; mkdir -p "$W"
CG="$BIN/contactgrid"
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
log "unit: history and dynamics, CPU = CUDA"
"$BIN/contactgrid_tests" --gtest_filter='EngineHistory*:StepHistory*:Dem*' 2>&1 | grep -E '^\[  (PASSED|FAILED) |Failure|SKIPPED' | head -20
log "CLI: a pour of spheres and one of ellipsoids on both backends, frames byte-identical"
for kind in pour pour-ellipsoids; do
  "$CG" generate "$W/$kind.h5" --kind $kind -n 20000 --rlow 0.004 --rhigh 0.005 --seed 7 -q
  for b in cpu cuda; do
    rm -rf "$W/$kind.$b"
    "$CG" simulate "$W/$kind.h5" -o "$W/$kind.$b" --steps 2000 --output-every 1000 --write-contacts --backend $b \
      --precision fp32 --no-plot -q
  done
  for f in frame_00002000.h5 contacts_00002000.h5; do
    if cmp -s <(h5dump -d /spheres/position "$W/$kind.cpu/$f" 2>/dev/null; h5dump -d /ellipsoids/orientation "$W/$kind.cpu/$f" 2>/dev/null; h5dump -d /contacts/previous_row "$W/$kind.cpu/$f" 2>/dev/null) \
              <(h5dump -d /spheres/position "$W/$kind.cuda/$f" 2>/dev/null; h5dump -d /ellipsoids/orientation "$W/$kind.cuda/$f" 2>/dev/null; h5dump -d /contacts/previous_row "$W/$kind.cuda/$f" 2>/dev/null); then
      echo "$kind $f: IDENTICAL"
    else
      echo "$kind $f: DIFFERENT"
    fi
  done
done
log "steps/s: pours of 2^20 and 2^24 spheres (fp32, CUDA), settled 4000 steps, then 500 steps timed"
for e in 20 24; do
  "$CG" generate "$W/p$e.h5" --kind pour -n $((1 << e)) --rlow 0.004 --rhigh 0.005 --seed $e -q
  rm -rf "$W/s$e" "$W/t$e" "$W/t$e.kernel"
  "$CG" simulate "$W/p$e.h5" -o "$W/s$e" --steps 4000 --output-every 4000 --backend cuda --precision fp32 --no-plot -q
  for search in thrust kernel; do
    dir="$W/t$e"; [ $search = kernel ] && dir="$W/t$e.kernel"
    echo "=== 2^$e history search $search"
    CONTACTGRID_CUDA_HISTORY=$search "$CG" simulate "$W/s$e/frame_00004000.h5" -o "$dir" --steps 500 \
      --output-every 500 --backend cuda --precision fp32 --no-plot
  done
done 2>&1 | tee "$OUT/simulate_perf.log" | grep -E '===|steps/s|history|contacts/body'
log "done"
