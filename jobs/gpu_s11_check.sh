#!/usr/bin/env bash
# The eleventh session's device checks of the lead's work (#32: the run's bodies sorted by cell):
#   pours    simulate on pours at six contacts a body (generate --kind pour --pour-spacing 1.97, a
#            lattice written x fastest), fp32, CUDA, whole steps (steps/s from log.csv, the first block
#            left out): 2^20 (300 steps) and 2^24 (60 steps), each with --order file and the default
#            (cells), alternated; the frames of the two orders agree to rounding only, so none is
#            compared; --stage-times of each at 2^24
#   erest    jobs/gpu_ellipsoid_rest.sh: 2^22 ellipsoids brought to rest, --order file and cells
#   mpi      tests/cli/mpi_simulate_cuda.sh: np 1 and 2 on this GPU write the CPU's one-rank files
#   suite    the whole unit suite with its CUDA cases
#   BIN=dir OUT=dir [PARTS="pours erest mpi suite"] jobs/gpu_s11_check.sh
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
mkdir -p "$OUT"
failed=()
PARTS=" ${PARTS:-pours erest mpi suite} "
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
wants() { [[ $PARTS == *" $1 "* ]]; }
log() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$OUT/summary.txt"; }
{ date -u; nvidia-smi --query-gpu=name --format=csv,noheader; } | tee "$OUT/device.txt"
steps_per_second() {
  awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.2f", k / s }' "$1/log.csv"
}

if wants pours; then
  W=${SCRATCH:-/dev/shm}/cgs11; rm -rf "$W"; mkdir -p "$W"
  for lg in 20 24; do
    n=$((1 << lg)); steps=$([ $lg = 20 ] && echo 300 || echo 60)
    timeout 120 "$CG" generate "$W/p.h5" --kind pour -n $n --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 \
      --seed 5 -q || failed+=("generate $lg")
    for round in $(seq 1 "${ROUNDS:-2}"); do
      # cells_morton: the cells along a Z-order curve (CONTACTGRID_SIMULATE_ORDER_KEY=morton)
      for order in file cells cells_morton; do
        rm -rf "$W/r"
        key=rows; [ $order = cells_morton ] && key=morton
        CONTACTGRID_SIMULATE_ORDER_KEY=$key timeout 200 "$CG" simulate "$W/p.h5" -o "$W/r" --steps $steps \
          --output-every $steps --log-every $((steps / 6)) --backend cuda --precision fp32 --no-plot \
          --order ${order%_morton} >"$OUT/pour${lg}_${order}_$round.txt" 2>&1 || failed+=("pour $lg $order")
        log "pour 2^$lg --order $order (round $round): $(steps_per_second "$W/r") steps/s"
      done
    done
    if [ $lg = 24 ]; then
      for order in file cells; do
        rm -rf "$W/r"
        timeout 200 "$CG" simulate "$W/p.h5" -o "$W/r" --steps 30 --output-every 30 --backend cuda \
          --precision fp32 --no-plot --order $order --stage-times >"$OUT/pour24_${order}_stages.txt" 2>&1 ||
          failed+=("pour 24 stages $order")
        log "pour 2^24 --order $order: $(grep 'stage times' "$OUT/pour24_${order}_stages.txt")"
      done
    fi
    rm -rf "$W/r" "$W/p.h5"
  done
  rm -rf "$W"
fi

if wants erest; then
  BIN=$BIN OUT=$OUT/erest MORTON=${MORTON:-1} jobs/gpu_ellipsoid_rest.sh >/dev/null 2>&1 || failed+=(erest)
  rm -f "$OUT/erest/settle_log.csv"
  sed 's/^/  /' "$OUT/erest/summary.txt" | tee -a "$OUT/summary.txt"
fi

if wants mpi; then
  PYTHON=$(command -v python3) timeout 300 tests/cli/mpi_simulate_cuda.sh "$CG" "$(command -v mpiexec)" \
    "${SCRATCH:-/dev/shm}/cgs11_mpi" >"$OUT/mpi_simulate_cuda.txt" 2>&1 || failed+=(mpi_simulate_cuda)
  log "mpi_simulate_cuda: $(tail -1 "$OUT/mpi_simulate_cuda.txt")"
fi

if wants suite; then
  timeout 420 "$BIN/contactgrid_tests" >"$OUT/unit_suite.log" 2>&1 || failed+=(suite)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$OUT/unit_suite.log" | head -40 | tee -a "$OUT/summary.txt"
  xz -T4 -f "$OUT/unit_suite.log"
fi

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}" | tee -a "$OUT/summary.txt"
  exit 1
fi
