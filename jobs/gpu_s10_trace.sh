#!/usr/bin/env bash
# Where a rebuild's time goes under mpirun (#31), a 2-GPU host (~3 min): the 2^25 drifting scene of
# jobs/gpu_ranks_check.sh at np 1 and np 2 with CONTACTGRID_STEP_TRACE=1, each rank's layout and
# building-step lines kept in $OUT/trace.np{1,2}.txt beside the summaries.
#   BIN=dir OUT=dir [N=33554432] [STEPS=16] [QUICK=1: np 1 and np 2 alone] jobs/gpu_s10_trace.sh
# Runs: np 1, np 2 (defaults: the migration's merge beside the detection), np 2 with
# CONTACTGRID_STEP_MERGE=layout (beside the layout, threads split), and with
# CONTACTGRID_STEP_MERGE_TEAM=whole too (the session's first main).
# Expect: np 2's layout ~150 ms and its building detection ~118 ms against an engine-stage sum of ~60
# (BENCHMARKS §28); the trace names the parts.
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; W=${WORK:-/tmp/cgwork}
mkdir -p "$OUT" "$W"
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt
CG="$BIN/contactgrid"; N=${N:-33554432}; STEPS=${STEPS:-16}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
MPI=(mpirun --bind-to none --allow-run-as-root)
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } | tee "$OUT/device.txt"
if [ -x "$BIN/contactgrid_mpi_tests" ]; then  # the CUDA moving-step cases at np 2 first
  timeout 150 "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no \
    --gtest_filter='MovingSteps.Cuda*:StepLoop.*Cuda*' >"$OUT/mpi_tests.np2.log" 2>&1
  echo "mpi tests np 2 (MovingSteps.Cuda*, StepLoop.*Cuda*): rc=$?"
  grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$OUT/mpi_tests.np2.log" | sort | uniq -c | head
fi
timeout 90 "$CG" generate "$W/s.h5" -n "$N" --seed 25 --contacts-per-body 6 -q || echo "generate failed"
# run TAG NP [ENV…]
run() {
  local tag=$1 np=$2; shift 2
  echo "== $tag (np $np${*:+, $*})"
  timeout 150 env CONTACTGRID_STEP_TRACE=1 "$@" "${MPI[@]}" -np "$np" "$CG" detect "$W/s.h5" -o "$W/c.h5" \
    --backend cuda --precision fp32 --steps "$STEPS" --drift 0.01 --skin auto >"$OUT/run.$tag.log" 2>&1
  echo "rc=$?"
  rm -f "$W/c.h5"
  grep '^trace' "$OUT/run.$tag.log" | sort -k5,5n -k3,3n >"$OUT/trace.$tag.txt"
  sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/run.$tag.log" | grep -E 'resident steps|rebuild|halo  |step  |candidate lists|merge wait|migrate'
  grep 'layout:' "$OUT/trace.$tag.txt" | sed -n 3,6p
}
run np1 1
run np2 2
if [ "${QUICK:-0}" != 1 ]; then
  run np2_beside_layout 2 CONTACTGRID_STEP_MERGE=layout
  run np2_former 2 CONTACTGRID_STEP_MERGE=layout CONTACTGRID_STEP_MERGE_TEAM=whole
fi
echo "last step pair hashes (one value expected):"; grep -ho "pair hash [0-9a-f]*" "$OUT"/run.*.log | sort | uniq -c
