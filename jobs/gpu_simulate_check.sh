#!/usr/bin/env bash
# Contact identity (#31 §4) and contactgrid simulate (#32) on one GPU, in one call (about 5 minutes):
#   1. unit cases with their CUDA halves: the history against its brute-force oracle on the device
#      (Thrust's and the hand-written search), the physics cases on the CUDA backend (restitution,
#      Hertz, energy, oblique impact, static friction, ellipsoid at rest), CPU = CUDA bit for bit
#      (library and CLI: frames and contacts with history);
#   2. the performance of whole steps (contact detection with history + forces + integration) on a
#      pour at a settled pack's contact count (generate --kind pour --pour-spacing 1.97: six
#      neighbours each), fp32, CUDA: 2^20 and 2^24 spheres, 2^22 ellipsoids; steps/s from the run's
#      summary, and the history stage with Thrust's lower_bound and with the hand kernel at 2^20.
# Prints a compact table; exits non-zero naming every failed check.
#   BIN=dir-with-the-CUDA-build's-binaries OUT=results-dir jobs/gpu_simulate_check.sh
# (BIN holds contactgrid and contactgrid_tests; run from the repository root; .devrt/env.sh, when
# present, supplies the runtime libraries.)
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgsim}; mkdir -p "$W"
CG="$BIN/contactgrid"
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; git rev-parse --short HEAD 2>/dev/null; } \
  >"$OUT/device.txt" 2>&1
cat "$OUT/device.txt"

log "1. unit: history, physics on CUDA, CPU = CUDA (library and CLI)"
filter='EngineHistory*:StepHistory*:HistoryFiles*:DemDamping*:DemPhysics/cuda.*:DemBackends*:SimulateCli*:SimulateWalls*'
"$BIN/contactgrid_tests" --gtest_filter="$filter" >"$OUT/unit.log" 2>&1 || failed+=("unit tests ($filter)")
grep -E '^\[  (PASSED|FAILED) |^\[  SKIPPED|^\[       OK \].*(cuda|Cuda|CUDA|Device)' "$OUT/unit.log" | head -40
if grep -q '^\[  SKIPPED \].*cuda' "$OUT/unit.log"; then failed+=("CUDA cases skipped: no GPU seen by the tests"); fi

log "2. steps/s: pours at a settled pack's contact count, fp32, CUDA"
bench() {  # name kind count steps rlow spacing [env]
  local name=$1 kind=$2 n=$3 steps=$4 rlow=$5 spacing=$6 env=${7:-}
  "$CG" generate "$W/$name.h5" --kind "$kind" -n "$n" --rlow "$rlow" --rhigh 0.005 --pour-spacing "$spacing" --seed 5 -q ||
    { failed+=("generate $name"); return; }
  rm -rf "$W/$name.run"
  if ! env $env "$CG" simulate "$W/$name.h5" -o "$W/$name.run" --steps "$steps" --output-every "$steps" \
      --log-every $((steps / 6)) --backend cuda --precision fp32 --no-plot >"$OUT/$name.log" 2>&1; then
    failed+=("simulate $name"); tail -3 "$OUT/$name.log"; return
  fi
  # steps/s: log.csv's seconds_per_step (the steps alone, no frame or log writing), the first block
  # (warm-up) left out; the summary's "last step: C contacts/body; its detection (ms): stage t ..."
  local sps cpb hist
  cp "$W/$name.run/log.csv" "$OUT/$name.log.csv"
  sps=$(awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.1f", k / s }' "$W/$name.run/log.csv")
  cpb=$(grep -oE '[0-9.]+ contacts/body' "$OUT/$name.log" | head -1 | cut -d' ' -f1)
  hist=$(grep -oE ' history [0-9.]+' "$OUT/$name.log" | head -1 | awk '{print $2}')
  printf '| %-22s | %9s | %6s | %8s | %9s | %7s |\n' "$name" "$n" "$steps" "$sps" "$cpb" "${hist:--}" >>"$OUT/table.md"
}
printf '| %-22s | %9s | %6s | %8s | %9s | %7s |\n' run bodies steps steps/s contacts/b "hist ms" >"$OUT/table.md"
echo '|---|---|---|---|---|---|' >>"$OUT/table.md"
# spheres: radii 4.95-5 mm at spacing 9.85 mm, each pressed on its six neighbours; ellipsoids: semi-axes
# 3.5-5 mm at spacing 9 mm (contacts where long axes meet: about half a contact per body)
bench spheres_2e20 pour $((1 << 20)) 300 0.00495 1.97
bench spheres_2e20_kernel pour $((1 << 20)) 300 0.00495 1.97 CONTACTGRID_CUDA_HISTORY=kernel
bench ellipsoids_2e22 pour-ellipsoids $((1 << 22)) 60 0.0035 1.8
bench spheres_2e24 pour $((1 << 24)) 60 0.00495 1.97
cat "$OUT/table.md"
for name in spheres_2e20 spheres_2e20_kernel; do
  [ -f "$OUT/$name.log" ] && grep -q 'backend cuda' "$OUT/$name.log" || failed+=("$name did not run on the CUDA backend")
done

if [ ${#failed[@]} -gt 0 ]; then
  log "FAILED:"; printf '  - %s\n' "${failed[@]}"; exit 1
fi
log "all checks passed"
