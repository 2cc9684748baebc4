#!/usr/bin/env bash
# The sixth session's short device check (one call; the session's device time was about 8 minutes):
# the CPU = CUDA cases the merge touched, then before / after of each branch's new default at one size:
#   #31  2^24 spheres fp32, 6 contacts a body, drift 0.01, skin auto, 40 steps: the kept candidates in
#        cell order (default) and in (a, b) order (CONTACTGRID_STEP_ORDER=file); a fresh detection a step
#   #32  simulate on pours at 6 contacts a body, 2^20 (300 steps) and 2^24 (30 steps): the defaults and
#        the former path (CONTACTGRID_DEM_SEGMENTS=cub CONTACTGRID_DEM_STORE=all CONTACTGRID_DEM_BLOCKS=1),
#        steps/s from log.csv and the energies of both the same bytes
#   #34  bench-broad 2^24 fp32 levels: uniform, bimodal 1:10 and 1:100 with the levels' cost-model cells
#        (default) and the smallest cells (CONTACTGRID_LEVELS_CELLS=smallest)
#   BIN=dir OUT=dir [PARTS="unit steps sim broad"] jobs/gpu_s6_check.sh
#   (BIN: the CUDA build's contactgrid and contactgrid_tests; PARTS: the parts to run, default all)
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
W=${SCRATCH:-/dev/shm}/cg_s6
mkdir -p "$W" "$OUT"
failed=()
PARTS=" ${PARTS:-unit steps sim broad} "
wants() { [[ $PARTS == *" $1 "* ]]; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name --format=csv,noheader; git log --oneline -1 2>/dev/null; } | tee "$OUT/device.txt"

if wants unit; then
log "== unit: the cases the merge touched"
timeout 120 "$BIN/contactgrid_tests" \
  --gtest_filter='CudaBackendTest*:CudaNarrowTest*:HostPath*:HostCellList*:HostStagesTest*:EngineSkinCuda*' \
  >"$OUT/unit.log" 2>&1 || failed+=(unit)
grep -E '^\[  (PASSED|FAILED) |^\[==========\]' "$OUT/unit.log"
fi

if wants steps; then
log "== #31 moving steps"
timeout 60 "$CG" generate "$W/s24.h5" -n 16777216 --seed 24 --contacts-per-body 6 -q || failed+=(steps_generate)
steps() {  # TAG SKIN STEPS [ENV...]
  local tag=$1 skin=$2 n=$3; shift 3
  timeout 90 env "$@" "$CG" detect "$W/s24.h5" -o "$W/steps.h5" --backend cuda --precision fp32 --steps "$n" \
    --drift 0.01 --skin "$skin" >"$OUT/steps_$tag.log" 2>&1 || failed+=("steps_$tag")
  echo "-- $tag"; grep -E 'mean step|building|candidate lists|contacts on the last step' "$OUT/steps_$tag.log"
}
steps fresh 0 6
steps cell auto 40
steps file auto 40 CONTACTGRID_STEP_ORDER=file
rm -f "$W/s24.h5" "$W/steps.h5"
fi

if wants sim; then
log "== #32 simulate"
BEFORE=(CONTACTGRID_DEM_SEGMENTS=cub CONTACTGRID_DEM_STORE=all CONTACTGRID_DEM_BLOCKS=1)
sim() {  # NAME STEPS LABEL [ENV...]
  local name=$1 n=$2 label=$3; shift 3
  local run="$W/$name.$label.run"
  rm -rf "$run"
  timeout 120 env "$@" "$CG" simulate "$W/$name.h5" -o "$run" --steps "$n" --output-every "$n" \
    --log-every $((n / 6)) --backend cuda --precision fp32 --no-plot >"$OUT/sim_$name.$label.log" 2>&1 ||
    failed+=("simulate_$name.$label")
  cp "$run/log.csv" "$OUT/sim_$name.$label.log.csv" 2>/dev/null
  awk -F, -v t="$name $label" 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } }
    END { if (k) printf "%s: %.1f steps/s\n", t, k / s }' "$run/log.csv" | tee -a "$OUT/sim_table.txt"
}
for lg in 20 24; do
  n=$((1 << lg)); steps_n=$([ $lg = 20 ] && echo 300 || echo 30)
  timeout 90 "$CG" generate "$W/p$lg.h5" --kind pour -n $n --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 \
    --seed 5 -q || failed+=("simulate_generate_$lg")
  sim "p$lg" $steps_n after
  sim "p$lg" $steps_n before "${BEFORE[@]}"
  cmp <(cut -d, -f1-6 "$W/p$lg.after.run/log.csv") <(cut -d, -f1-6 "$W/p$lg.before.run/log.csv") ||
    failed+=("simulate_p${lg}_energies_differ")
  rm -rf "$W/p$lg.h5" "$W"/p$lg.*.run
done
fi

if wants broad; then
log "== #34 levels cells, 2^24"
for cells in tuned smallest; do
  timeout 150 env CONTACTGRID_LEVELS_CELLS=$cells "$CG" bench-broad --backend cuda --precision fp32 \
    --families uniform,bimodal10,bimodal100 --broad-phases levels --lo 24 --hi 24 --repetitions 3 \
    >"$OUT/broad_$cells.txt" 2>&1 || failed+=("broad_$cells")
  echo "-- levels cells: $cells"; cat "$OUT/broad_$cells.txt"
done
fi
rm -rf "$W"
if [ ${#failed[@]} -gt 0 ]; then echo "FAILED: ${failed[*]}"; exit 1; fi
echo "all passed"
