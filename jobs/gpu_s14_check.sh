#!/usr/bin/env bash
# The fourteenth session's GPU checks (issue #31), from the repository root on the device:
#   PART=unit|eranks OUT=dir jobs/gpu_s14_check.sh   (binaries: .devbin/n.tar.xz)
#   unit    the CUDA row-list cases (EngineRowLists*, with the high-priority engine's) and the skin
#           cases; at np 2 the CUDA moving-step cases. Expect every case PASSED (CPU cases run too)
#   eranks  (2 GPUs) 2^24 ellipsoids (aspect <= 1:4), drift 0.01, skin auto, STEPS (40) steps, np 1 and
#           np 2: the mean step, a reuse, a build, halo and rebuild parts per step; both runs' last
#           step the same pair hash. #31 asks np 2 >= 1.8x np 1
#   density `bench-broad --backend cuda --precision fp32` of uniform spheres, grid against levels (the
#           one-level levels that auto picks for fresh device calls of 2^21+ bodies of one size class),
#           2^20 to 2^24, at 0.4 (the generator's) to 6 (granular rest) contacts a body: where the grid
#           overtakes the levels (at 6 a body the grid was 0.93x the levels' time at 2^24, BENCHMARKS §32)
set -u
cd "$(dirname "$0")/.."
[ -d .devbin/n ] || tar xJf .devbin/n.tar.xz -C .devbin
source .devrt/env.sh .devrt >/dev/null 2>&1
B=$(realpath .devbin/n); OUT=${OUT:-/tmp/out}; PART=${PART:-unit}
export GTEST_COLOR=no OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
export CG_BINARY=$B/contactgrid CG_SOURCE_DIR=$PWD CG_MPIEXEC=$(command -v mpirun)
mkdir -p "$OUT"
case $PART in
unit)
  timeout 240 "$B/contactgrid_tests" --gtest_filter='EngineRowLists*:EngineSkin*' >"$OUT/unit.log" 2>&1
  echo "-- unit (rc $?)"; grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$OUT/unit.log"; grep -E '^\[  FAILED  \]' "$OUT/unit.log" | head
  timeout 200 mpirun --bind-to none -np 2 "$B/contactgrid_mpi_tests" --gtest_filter='MovingSteps.Cuda*:StepLoop.*Cuda*' \
    >"$OUT/mpi2.log" 2>&1
  echo "-- np 2 moving steps (rc $?)"; grep -cE '^\[       OK \]' "$OUT/mpi2.log"; grep -E '^\[  (PASSED|FAILED) ' "$OUT/mpi2.log" ;;
eranks)
  N=${N:-16777216}; S=${STEPS:-40}
  timeout 120 "$B/contactgrid" generate /dev/shm/e.h5 -n "$N" --seed 24 --contacts-per-body 6 --kind ellipsoids -q
  for run in np1:1 np2:2; do
    IFS=: read -r tag np <<<"$run"
    timeout 240 mpirun --bind-to none -np "$np" "$B/contactgrid" detect /dev/shm/e.h5 -o /dev/shm/ec.h5 \
      --backend cuda --precision fp32 --steps "$S" --drift 0.01 --skin auto >"$OUT/eranks_$tag.log" 2>&1
    echo "-- $tag (rc $?)"; sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/eranks_$tag.log" | grep -vE '^    (plan|pack) '
    rm -f /dev/shm/ec.h5
  done
  rm -f /dev/shm/e.h5 ;;
density)
  for d in ${DENSITIES:-0.4 1 2 3 4 6}; do
    echo "-- $d contacts a body"
    timeout 150 "$B/contactgrid" bench-broad --backend cuda --precision fp32 --families uniform \
      --broad-phases grid,levels,auto --lo 20 --hi 24 --step 2 --repetitions 5 --contacts-per-body "$d" \
      --csv "$OUT/density_$d.csv" 2>&1 | grep -E '^(uniform|family)'
  done ;;
esac
