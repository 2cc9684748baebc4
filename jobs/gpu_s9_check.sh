#!/usr/bin/env bash
# The ninth session's device checks of the lead's work (#32: simulate under mpirun on two GPUs):
#   simtwo     (a host with 2 GPUs) a pour of N spheres (default 2^25, fp32, STEPS = 40 steps, a log
#              row every STEPS/2, the first and last frames) under mpirun -np 1 and -np 2 --backend cuda:
#              steps/s (log.csv: the steps alone), the command's wall time and the run's split (start,
#              steps, log rows, frames); np 1 and np 2 must write the same files; each rank's step
#              phases (--stage-times: halo, frame, relayout, forces) at np 1 and 2; then, where nsys
#              exists, np 2 for NSYS_STEPS steps under Nsight Systems (CUDA + MPI + OS runtime): where a
#              rank's step goes (kernels, copies, MPI waits), rank 0's summary tables
#   suite      the whole unit suite with its CUDA cases
#   BIN=dir OUT=dir [PARTS="simtwo"] [N=...] [STEPS=...] jobs/gpu_s9_check.sh
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
PY=${PY:-python3}
mkdir -p "$OUT"
failed=()
PARTS=" ${PARTS:-simtwo} "
export BIN CG_BINARY=$(realpath "$CG") CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpiexec)
# cma: the image presets none, whose copies between ranks' host memory are 1.3-2.5x slower
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 \
  OMPI_MCA_btl_vader_single_copy_mechanism=cma
wants() { [[ $PARTS == *" $1 "* ]]; }
log() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$OUT/summary.txt"; }
{ date -u; nvidia-smi --query-gpu=name --format=csv,noheader; } | tee "$OUT/device.txt"

# steps/s of a run directory: log.csv's seconds_per_step (the steps alone), the first block left out
steps_per_second() {
  awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.2f", k / s }' "$1/log.csv"
}

if wants simtwo; then
  W=/tmp/cgs9; rm -rf "$W"; mkdir -p "$W"
  n=${N:-$((1 << 25))} steps=${STEPS:-40}
  gpus=$(nvidia-smi -L 2>/dev/null | wc -l)
  if [ "$gpus" -lt 2 ]; then
    failed+=("simtwo: needs 2 GPUs, $gpus seen")
  else
    "$CG" generate "$W/t.h5" --kind pour -n "$n" --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 --seed 5 -q ||
      failed+=("simtwo: generate")
    for np in 1 2; do
      t0=$(date +%s.%N)
      timeout 240 mpirun --bind-to none -np $np "$CG" simulate "$W/t.h5" -o "$W/np$np.run" --steps "$steps" \
        --output-every "$steps" --log-every $((steps / 2)) --backend cuda --precision fp32 --no-plot \
        >"$OUT/simtwo_np$np.log" 2>&1 || failed+=("simtwo: np $np run")
      wall=$(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.2f", b - a }')
      log "simtwo: $n spheres np $np: $(steps_per_second "$W/np$np.run") steps/s; command wall $wall s;$(grep -o ' wall time .*' "$OUT/simtwo_np$np.log" | head -1)"
      cp "$W/np$np.run/log.csv" "$OUT/simtwo_np$np.csv" 2>/dev/null
    done
    "$PY" tests/cli/same_run.py "$W/np1.run" "$W/np2.run" 2>&1 | tee -a "$OUT/summary.txt" ||
      failed+=("simtwo: np 2's files differ from np 1's")
    a=$(steps_per_second "$W/np1.run"); b=$(steps_per_second "$W/np2.run")
    log "simtwo: np 2 / np 1 = $(awk -v a="$a" -v b="$b" 'BEGIN { if (a > 0) printf "%.2f", b / a }') (issue: >= 1.8 at 2^25)"
    rm -rf "$W"/np*.run
    # where each rank's step goes: --stage-times (the device waited for at each step's end)
    for np in 1 2; do
      timeout 200 mpirun --bind-to none -np $np "$CG" simulate "$W/t.h5" -o "$W/timed$np.run" --steps 20 \
        --output-every 20 --log-every 20 --backend cuda --precision fp32 --no-plot --stage-times \
        >"$OUT/simtwo_timed_np$np.log" 2>&1 || failed+=("simtwo: np $np --stage-times run")
      { echo "np $np --stage-times:"; grep -A3 'step phases' "$OUT/simtwo_timed_np$np.log"; } | tee -a "$OUT/summary.txt"
      rm -rf "$W/timed$np.run"
    done
    if command -v nsys >/dev/null 2>&1; then
      k=${NSYS_STEPS:-10}
      timeout 240 mpirun --bind-to none -np 2 nsys profile --trace=cuda,mpi,osrt --mpi-impl=openmpi \
        --sample=none --cpuctxsw=none -o "$W/np2_rank%q{OMPI_COMM_WORLD_RANK}" -f true \
        "$CG" simulate "$W/t.h5" -o "$W/nsys.run" --steps "$k" --output-every "$k" --log-every "$k" \
        --backend cuda --precision fp32 --no-plot >"$W/nsys_run.log" 2>&1 || failed+=("simtwo: nsys run")
      for r in 0 1; do
        nsys stats --report cuda_gpu_kern_sum,cuda_gpu_mem_time_sum,cuda_api_sum,mpi_event_sum,osrt_sum \
          --format csv -o "$W/stats_r$r" "$W/np2_rank$r.nsys-rep" >/dev/null 2>&1
        for f in "$W"/stats_r${r}_*.csv; do echo "== $f"; head -25 "$f"; done
      done >"$OUT/simtwo_nsys.txt" 2>&1
      tail -5 "$W/nsys_run.log" >>"$OUT/simtwo_nsys.txt"
    else
      log "simtwo: no nsys on this machine: no profile"
    fi
  fi
  rm -rf "$W"
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
