#!/usr/bin/env bash
# The sixteenth session's GPU checks (issue #31: the rebuild under mpirun), from the repository root on
# a 2-GPU device host (binaries: .devbin/n.tar.xz, the change; .devbin/old.tar.xz, the main before it):
#   PART=ranks|ranks2|eranks|mpitests|layout OUT=dir [N=…] [STEPS=…] jobs/gpu_s16_check.sh
#   ranks   N spheres at 6 contacts a body, drift 0.01, skin auto, STEPS steps, CONTACTGRID_STEP_TRACE=1:
#           np 1 (the change), np 2 before, np 2 the change, np 2 the change with plain copies in the
#           migration's merge (CONTACTGRID_SPLICE_COPY=memcpy); every run's last step the same pair
#           hash. Expect np 2's "merge wait" to drop (streaming stores, 24-byte sphere poses) and the
#           layout's merge_rows and plan to shrink (merge in parts, role storage kept).
#   ranks2  the same scene: np 1, np 2, np 2 with CONTACTGRID_STEP_MERGE_TEAM=whole. Call 3 ran it
#           on a build whose merge beside the detection left two threads to the engines (not kept:
#           the whole share was faster, BENCHMARKS §36); on main both runs are the same path.
#   eranks  2^24 ellipsoids (aspect <= 1:4) at 6 contacts a body, drift 0.01, skin auto, 40 steps:
#           np 1, np 2 before, np 2 the change (BENCHMARKS §34's runs)
#   mpitests  the CUDA cases of contactgrid_mpi_tests at np 2
#   layout  a layout lasting two of the engines' skins (call 4: the default then, 1 now) or three
#           (CONTACTGRID_STEP_LAYOUT_SKIN=3): the sphere scene at np 1, np 2, np 2 k=3, then the
#           ellipsoid scene at np 1 and np 2 (40 steps). Expect np 2's skin near np 1's and fewer
#           rebuilds (layouts) than builds.
# (Calls 2 and 3 named the trace files trace_TAG.txt and trace2_TAG.txt.)
set -u
cd "$(dirname "$0")/.."
for b in n old; do [ -d ".devbin/$b" ] || [ ! -f ".devbin/$b.tar.xz" ] || tar xJf ".devbin/$b.tar.xz" -C .devbin; done
source .devrt/env.sh .devrt >/dev/null 2>&1
OUT=${OUT:-/tmp/out}; PART=${PART:-ranks}
mkdir -p "$OUT"
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; nproc; } | tee "$OUT/device.txt"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
# ranks_runs PREFIX RUN…: the sphere scene's runs (RUN = tag:np:binaries:setting or -), each rank's
# trace lines kept in $OUT/trace_PREFIX_tag.txt beside the summaries
ranks_runs() {
  local prefix=$1; shift
  local N=${N:-67108864} S=${STEPS:-100}
  timeout 120 .devbin/n/contactgrid generate /dev/shm/r.h5 -n "$N" --seed 24 --contacts-per-body 6 -q
  for run in "$@"; do
    IFS=: read -r tag np bin setting <<<"$run"
    envs=(-x CONTACTGRID_STEP_TRACE=1); [ "$setting" != - ] && envs+=(-x "$setting")
    timeout 240 mpirun --bind-to none --allow-run-as-root -np "$np" "${envs[@]}" ".devbin/$bin/contactgrid" detect \
      /dev/shm/r.h5 -o /dev/shm/rc.h5 --backend cuda --precision fp32 --steps "$S" --drift 0.01 --skin auto \
      >"$OUT/${prefix}_$tag.log" 2>&1
    echo "-- $tag (rc $?)"
    grep '^trace' "$OUT/${prefix}_$tag.log" | sort -k5,5n -k3,3n >"$OUT/trace_${prefix}_$tag.txt"
    sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/${prefix}_$tag.log" | grep -vE '^    (plan|pack|skin) '
    rm -f /dev/shm/rc.h5
  done
  rm -f /dev/shm/r.h5
}
case $PART in
ranks) ranks_runs ranks np1:1:n:- np2old:2:old:- np2:2:n:- np2memcpy:2:n:CONTACTGRID_SPLICE_COPY=memcpy ;;
ranks2) ranks_runs ranks2 np1:1:n:- np2:2:n:- np2whole:2:n:CONTACTGRID_STEP_MERGE_TEAM=whole ;;
layout)
  ranks_runs layout np1:1:n:- np2:2:n:CONTACTGRID_STEP_LAYOUT_SKIN=2 np2k3:2:n:CONTACTGRID_STEP_LAYOUT_SKIN=3
  PART=eranks ERUNS="np1:1:n np2:2:n" "$0" ;;
eranks)
  N=${N:-16777216}; S=${STEPS:-40}
  timeout 120 .devbin/n/contactgrid generate /dev/shm/e.h5 -n "$N" --seed 24 --contacts-per-body 6 --kind ellipsoids -q
  for run in ${ERUNS:-np1:1:n np2old:2:old np2:2:n}; do
    IFS=: read -r tag np bin <<<"$run"
    timeout 240 mpirun --bind-to none --allow-run-as-root -np "$np" ".devbin/$bin/contactgrid" detect /dev/shm/e.h5 \
      -o /dev/shm/ec.h5 --backend cuda --precision fp32 --steps "$S" --drift 0.01 --skin auto \
      >"$OUT/eranks_$tag.log" 2>&1
    echo "-- $tag (rc $?)"
    sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/eranks_$tag.log" | grep -vE '^    (plan|pack) '
    rm -f /dev/shm/ec.h5
  done
  rm -f /dev/shm/e.h5 ;;
mpitests)
  timeout 200 mpirun --bind-to none --allow-run-as-root -np 2 .devbin/n/contactgrid_mpi_tests --gtest_color=no \
    --gtest_filter='*Cuda*:*cuda*' >"$OUT/mpi_tests_np2.log" 2>&1
  echo "mpi tests np 2, CUDA cases: rc $?"
  grep -E '^\[  (PASSED|FAILED|SKIPPED) ' "$OUT/mpi_tests_np2.log" | sort | uniq -c ;;
esac
