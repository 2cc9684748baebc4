#!/usr/bin/env bash
# End to end on the GPU: contactgrid simulate under mpirun with each rank's bodies resident on its
# device (--backend cuda) writes the CPU's one-rank frames, contacts and energies, bit for bit, at 1
# and 2 ranks (2 ranks share one GPU where there is one), fp64 and fp32, spheres and ellipsoids, the
# ghosts' halo overlapping the forces (the default) and not (CONTACTGRID_SIMULATE_OVERLAP=off); so
# does the host path (CONTACTGRID_SIMULATE_RANKS=host), and so do the log rows and frames gathered on
# rank 0 (CONTACTGRID_SIMULATE_OUTPUT=gather; the default sums them where the rows are). Exit 77
# (skipped, visibly) without a GPU.
# Usage: mpi_simulate_cuda.sh CONTACTGRID MPIEXEC WORKDIR
set -euo pipefail
CG=$1; MPIEXEC=$2; W=$3
PY=${PYTHON:-/usr/bin/python3}  # (a python3 with h5py and NumPy)
rm -rf "$W"; mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
"$CG" generate "$W/pour.h5" --kind pour -n 400 --seed 5 -q
"$CG" generate "$W/pell.h5" --kind pour-ellipsoids -n 150 --seed 6 -q
if ! "$CG" simulate "$W/pour.h5" -o "$W/probe" --steps 1 --backend cuda --no-plot -q >"$W/probe.out" 2>&1; then
  echo "SKIPPED: no GPU for --backend cuda here: $(head -c 300 "$W/probe.out")"
  exit 77
fi
opts=(--steps 1500 --output-every 500 --log-every 100 --gravity -4 0 -9.81 --restitution 0.3 --friction 0.5
  --rolling-friction 0.05 --write-contacts --threads 1 --no-plot)
run() {  # SCENE NP TAG BACKEND [OPTION...]
  "$MPIEXEC" -np "$2" --oversubscribe --allow-run-as-root "$CG" simulate "$W/$1.h5" -o "$W/$3" "${opts[@]}" \
    --backend "$4" "${@:5}" >"$W/$3.out"
  grep -q "backend $4" "$W/$3.out" || { echo "$3: not on backend $4"; exit 1; }
}
same() { "$PY" "$(dirname "$0")/same_run.py" "$@"; }
for scene in pour pell; do
  run "$scene" 1 "$scene.cpu.np1" cpu
  for np in 1 2; do
    run "$scene" "$np" "$scene.cuda.np$np" cuda
    same "$W/$scene.cpu.np1" "$W/$scene.cuda.np$np"
  done
done
run pour 1 pour.fp32.cpu.np1 cpu --precision fp32
run pour 2 pour.fp32.cuda.np2 cuda --precision fp32
same "$W/pour.fp32.cpu.np1" "$W/pour.fp32.cuda.np2"
CONTACTGRID_SIMULATE_OUTPUT=gather run pour 2 pour.gather.cuda.np2 cuda
same "$W/pour.cpu.np1" "$W/pour.gather.cuda.np2"
CONTACTGRID_SIMULATE_RANKS=host run pour 2 pour.host.cuda.np2 cuda
same "$W/pour.cpu.np1" "$W/pour.host.cuda.np2"
# the halo at each step's start, nothing overlapped, every field of the records (the former path)
CONTACTGRID_SIMULATE_OVERLAP=off CONTACTGRID_SIMULATE_HALO_BYTES=full run pell 2 pell.nolap.cuda.np2 cuda
same "$W/pell.cpu.np1" "$W/pell.nolap.cuda.np2"
echo "simulate under mpirun on the GPU: the CPU's files at 1 and 2 ranks, resident and on the host"
