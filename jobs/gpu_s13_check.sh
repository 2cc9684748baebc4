#!/usr/bin/env bash
# The thirteenth session's GPU checks (issue #31), from the repository root on the device:
#   PART=narrow|ellipsoids|ranks OUT=dir jobs/gpu_s13_check.sh   (binaries: .devbin/n.tar.xz)
#   narrow      2^24 spheres at 6 contacts a body, drift 0.01, skin auto, 200 steps, the defaults
#               (jobs/gpu_rebuild_check.sh); BENCHMARKS §33 has the forms of cell_narrow_kernel that
#               this part compared (none faster; not kept)
#   ellipsoids  the same check on 2^24 ellipsoids (aspect <= 1:4), 60 steps, the defaults
#   ranks       (2 GPUs) 2^26 spheres, drift 0.01, skin auto, 100 steps: np 1, np 2, np 2 with engine B
#               at the default priority (CONTACTGRID_STEP_PRIORITY=same); each run's last step the same
#               pair hash. Expect np 2's "halo unpack" to drop with the priority (its scatter no longer
#               waits for engine A's grid)
set -u
cd "$(dirname "$0")/.."
[ -d .devbin/n ] || tar xJf .devbin/n.tar.xz -C .devbin
source .devrt/env.sh .devrt >/dev/null 2>&1
B=$(realpath .devbin/n); OUT=${OUT:-/tmp/out}; PART=${PART:-narrow}
mkdir -p "$OUT"
case $PART in
narrow)
  SCRATCH=/dev/shm UNIT=1 STEPS=${STEPS:-200} ROUNDS=${ROUNDS:-1} PROFILE=0 VARIANTS="now=-" BIN=$B \
    OUT=$OUT/narrow timeout 400 jobs/gpu_rebuild_check.sh 2>&1 | grep -vE '^  detect ' ;;
ellipsoids)
  SCRATCH=/dev/shm KIND=ellipsoids UNIT=0 STEPS=${STEPS:-60} ROUNDS=1 PROFILE=0 VARIANTS="now=-" BIN=$B \
    OUT=$OUT/ellipsoids timeout 540 jobs/gpu_rebuild_check.sh 2>&1 | tail -25 ;;
ranks)
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
  N=${N:-67108864}; S=${STEPS:-100}
  timeout 120 "$B/contactgrid" generate /dev/shm/r.h5 -n "$N" --seed 24 --contacts-per-body 6 -q
  for run in np1:1:- np2:2:- np2same:2:CONTACTGRID_STEP_PRIORITY=same; do
    IFS=: read -r tag np setting <<<"$run"
    envs=(); [ "$setting" != - ] && envs=(-x "$setting")
    timeout 200 mpirun --bind-to none --allow-run-as-root -np "$np" "${envs[@]}" "$B/contactgrid" detect /dev/shm/r.h5 \
      -o /dev/shm/rc.h5 --backend cuda --precision fp32 --steps "$S" --drift 0.01 --skin auto >"$OUT/ranks_$tag.log" 2>&1
    echo "-- $tag (rc $?)"; sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/ranks_$tag.log" | grep -vE '^    (plan|pack|skin) '
    rm -f /dev/shm/rc.h5
  done
  rm -f /dev/shm/r.h5 ;;
esac
