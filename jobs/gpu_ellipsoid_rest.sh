#!/usr/bin/env bash
# simulate (#32) on ellipsoids at rest density, one H100 (about 4 minutes):
#   BIN=dir OUT=dir [N=4194304] [SETTLE=4000] [STEPS=120] jobs/gpu_ellipsoid_rest.sh
# The issue's ellipsoid figure is for "a granular pour at rest density (about 6 contacts per body)".
# A pour's lattice leaves randomly turned ellipsoids apart, and a random pack at six contacts a body
# is not at rest: its overlaps push it apart, a rebuild most steps (BENCHMARKS §24: 45.9 steps/s).
# So the pack is first brought to rest: N ellipsoids (aspect <= 1:4, semi-axes U[Rhigh/4, Rhigh],
# Rhigh 0.005 m) placed at random at six contacts a body (`generate --kind ellipsoids
# --contacts-per-body 6`), in a closed box one Rhigh beyond the cube of their centres, relax for
# SETTLE steps with restitution 0.1 (CUDA, fp32, the defaults otherwise); the last frame is a scene
# with velocities. The figure is then STEPS whole steps from that frame with the default material
# (restitution 0.5), the same box: steps/s from log.csv (the first log block left out) and a short
# --stage-times run (the box PAD wider: below), each with the bodies in the generator's random order
# (--order file) and sorted by cell (--order auto, the default: cells). Target: 3·10^8 ellipsoid-steps/s at 2^22 (71.5 steps/s).
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
N=${N:-4194304}; SETTLE=${SETTLE:-4000}; STEPS=${STEPS:-120}; CPB=${CPB:-6}; STAGES=${STAGES:-1}  # BACKEND=cpu: a check of the script without a GPU
W=${SCRATCH:-/dev/shm}/cg_erest; rm -rf "$W"; mkdir -p "$W" "$OUT"
log() { echo "$*" | tee -a "$OUT/summary.txt"; }
log "# $(date -u +%FT%TZ) $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1); N=$N CPB=$CPB SETTLE=$SETTLE STEPS=$STEPS"
timeout 120 "$CG" generate "$W/e.h5" --kind ellipsoids -n "$N" --rhigh 0.005 --max-aspect 4 \
  --contacts-per-body "$CPB" --seed 5 -q || { log "generate failed"; exit 1; }
# the cube of the centres: [0, box_edge]^3 (the generator's attribute)
E=$(h5dump -a /box_edge "$W/e.h5" 2>/dev/null | awk '/\(0\)/ { print $2 }')
[ -n "$E" ] || E=$(python3 -c "import h5py; print(h5py.File('$W/e.h5','r').attrs['box_edge'])")
BOX=$(awk -v e="$E" 'BEGIN { r = 0.005; printf "box:%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", -r, -r, -r, e + r, e + r, e + r }')
# the runs from the settled frame: the box a little wider (PAD on each side, default half the smallest
# semi-axis), since the settled pack presses some bodies into the walls deeper than simulate lets a run
# start (half the body's smallest semi-axis)
PAD=${PAD:-0.000625}
BOX2=$(awk -v e="$E" -v p="$PAD" 'BEGIN { r = 0.005 + p; printf "box:%.9g,%.9g,%.9g,%.9g,%.9g,%.9g", -r, -r, -r, e + r, e + r, e + r }')
log "box edge $E, walls $BOX (settling), $BOX2 (the runs)"
t0=$(date +%s.%N)
timeout 420 "$CG" simulate "$W/e.h5" -o "$W/settle" --steps "$SETTLE" --output-every "$SETTLE" \
  --log-every $((SETTLE / 20)) --backend "${BACKEND:-cuda}" --precision fp32 --no-plot --walls "$BOX" --restitution 0.1 \
  >"$OUT/settle.txt" 2>&1 || log "settle rc=$?"
log "settle: $(awk -v t0="$t0" 'BEGIN { "date +%s.%N" | getline t; printf "%.1f s", t - t0 }')"
cp "$W/settle/log.csv" "$OUT/settle_log.csv" 2>/dev/null
tail -4 "$OUT/settle_log.csv" | tee -a "$OUT/summary.txt"
FRAME=$(ls "$W"/settle/frame_*.h5 2>/dev/null | sort -V | tail -1)
[ -n "$FRAME" ] || { log "no settled frame"; exit 1; }
rm -f "$W/e.h5"
bench() {  # FRAME LABEL [simulate options]: STEPS whole steps from FRAME, steps/s from log.csv
  local frame=$1 label=$2
  shift 2
  rm -rf "$W/bench"
  timeout 300 "$CG" simulate "$frame" -o "$W/bench" --steps "$STEPS" --output-every "$STEPS" \
    --log-every $((STEPS / 6)) --backend "${BACKEND:-cuda}" --precision fp32 --no-plot --walls "$BOX2" "$@" \
    >"$OUT/bench_$label.txt" 2>&1 || log "bench $label rc=$?"
  cp "$W/bench/log.csv" "$OUT/bench_${label}_log.csv" 2>/dev/null
  awk -F, -v n="$N" -v t="$label" 'NR > 1 && $1 !~ /^#/ && $7 > 0 { k++; if (k > 1) { s += $7; m++; c = $5 } }
    END { if (m) printf "%s: %.1f steps/s = %.3g body-steps/s, %.2f contacts a body (last row)\n", t, m / s, n * m / s, 2 * c / n }' \
    "$W/bench/log.csv" | tee -a "$OUT/summary.txt"
  grep -E "candidate lists|last step" "$OUT/bench_$label.txt" | tee -a "$OUT/summary.txt"
  rm -rf "$W/bench"
}
# the settled frame in the generator's random order (--order file) and sorted by cell (the default)
bench "$FRAME" file --order file
bench "$FRAME" cells
# MORTON=1: also sorted along a Z-order curve of the cells (CONTACTGRID_SIMULATE_ORDER_KEY=morton)
[ "${MORTON:-0}" = 1 ] && (export CONTACTGRID_SIMULATE_ORDER_KEY=morton; bench "$FRAME" cells_morton)
# SKIN_CUT0=1: also with a skin's list of inflated bounding spheres alone (CONTACTGRID_SKIN_CUT=0, the
# former list and check: turns do not count), the default being the list cut by the centre line
[ "${SKIN_CUT0:-0}" = 1 ] && (export CONTACTGRID_SKIN_CUT=0; bench "$FRAME" cells_skin_cut0)
stages() {  # FRAME LABEL [simulate options]: 30 steps with --stage-times
  [ "$STAGES" = 1 ] && [ -f "$1" ] || return 0
  local frame=$1 label=$2
  shift 2
  timeout 200 "$CG" simulate "$frame" -o "$W/stages" --steps 30 --output-every 30 --backend "${BACKEND:-cuda}" \
    --precision fp32 --no-plot --walls "$BOX2" --stage-times "$@" >"$OUT/stages_$label.txt" 2>&1 ||
    log "stages $label rc=$?"
  log "$label:"
  grep -E "stage times|within detect|candidate lists" "$OUT/stages_$label.txt" | tee -a "$OUT/summary.txt"
  rm -rf "$W/stages"
}
stages "$FRAME" file --order file
stages "$FRAME" cells
rm -rf "$W"
