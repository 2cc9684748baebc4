#!/usr/bin/env bash
# End to end: contactgrid simulate under mpirun. A pour under a tilted gravity (bodies falling through
# the slabs' cuts onto the floor of an open box, then sliding along it against a side wall in lasting
# contact: walls, friction, the tangential springs carried by the bodies that change rank) at 1-4
# ranks writes the same frames, contacts and energies as -np 1, bit for bit (every dataset's bytes),
# with each rank's bodies resident (the default: the ghosts' halo overlapping the forces; also
# CONTACTGRID_SIMULATE_OVERLAP=off) and on the host (CONTACTGRID_SIMULATE_RANKS=host), and
# -np 1 writes the files of the run without mpirun; the log rows and frames summed where the rows are
# (the default) and gathered on rank 0 (CONTACTGRID_SIMULATE_OUTPUT=gather) are the same. Dropping
# the springs of the bodies that change rank makes the 3-rank frames differ (checked by hand when the
# test was written).
# Usage: mpi_simulate.sh CONTACTGRID MPIEXEC WORKDIR
set -euo pipefail
CG=$1; MPIEXEC=$2; W=$3
PY=/usr/bin/python3
rm -rf "$W"; mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
"$CG" generate "$W/pour.h5" --kind pour -n 400 --seed 5 -q
"$CG" generate "$W/pell.h5" --kind pour-ellipsoids -n 150 --seed 6 -q
opts=(--steps 1500 --output-every 500 --log-every 100 --gravity -4 0 -9.81 --restitution 0.3 --friction 0.5
  --rolling-friction 0.05 --write-contacts --backend cpu --threads 1 --no-plot)
run() {  # SCENE NP TAG [OPTION...]; more than one rank: some bodies changed rank
  "$MPIEXEC" -np "$2" --oversubscribe --allow-run-as-root "$CG" simulate "$W/$1.h5" -o "$W/$3" "${opts[@]}" \
    "${@:4}" >"$W/$3.out"
  local moved
  moved=$(grep -oE 'bodies that changed rank [0-9]+' "$W/$3.out" | grep -oE '[0-9]+$')
  if [ "$2" -gt 1 ] && ! [ "${moved:-0}" -gt 0 ]; then echo "$3: no body changed rank"; exit 1; fi
}
same() {  # DIR1 DIR2 [frames only]: every dataset's bytes, and the log's energies and contacts
  "$PY" "$(dirname "$0")/same_run.py" "$@"
}
for scene in pour pell; do
  run "$scene" 1 "$scene.np1"
  for np in 2 3 4; do
    run "$scene" "$np" "$scene.np$np"
    same "$W/$scene.np1" "$W/$scene.np$np"
  done
  # the run moved bodies across the cuts, touched the floor and kept springs: not a trivial run
  "$PY" - "$W/$scene.np1" <<'PYEOF'
import sys, h5py, numpy as np, glob
d = sys.argv[1]
frames = sorted(glob.glob(d + "/frame_*.h5"))
contacts = sorted(glob.glob(d + "/contacts_*.h5"))
def z(path):
    with h5py.File(path, "r") as f:
        return np.concatenate([f[g]["position"][:, 2] for g in ("spheres", "ellipsoids") if g in f and "position" in f[g]])
z0, z1 = z(frames[0]), z(frames[-1])
assert (z0 - z1).max() > 0.5 * (z0.max() - z0.min()) / 4, "the bodies hardly fell"
with h5py.File(contacts[-1], "r") as f:
    age = f["contacts/age"][:]
assert len(age) > 0 and (age > 5).sum() > 0, "no lasting contacts (no tangential history) in the last step"
print(f"{d}: fell {(z0 - z1).max():.3g}, {len(age)} contacts at the end, {(age > 5).sum()} older than 5 steps")
PYEOF
done
# fp32 detection: the same at 1 and 3 ranks
run pour 1 pour.fp32.np1 --precision fp32
run pour 3 pour.fp32.np3 --precision fp32
same "$W/pour.fp32.np1" "$W/pour.fp32.np3"
# the log rows and frames through every rank's rows on rank 0 (CONTACTGRID_SIMULATE_OUTPUT=gather, the
# former path) against the sums where the rows are (the default): the same files
CONTACTGRID_SIMULATE_OUTPUT=gather run pour 1 pour.gather.np1
same "$W/pour.np1" "$W/pour.gather.np1"
CONTACTGRID_SIMULATE_OUTPUT=gather run pell 3 pell.gather.np3
same "$W/pell.np1" "$W/pell.gather.np3"
grep -q 'wall time .* steps .* log rows .* frames' "$W/pour.np3.out" || { echo "no wall time split in the summary"; exit 1; }
# the ghosts' former exchange (CONTACTGRID_SIMULATE_GHOSTS=records): the same files
CONTACTGRID_SIMULATE_GHOSTS=records run pell 3 pell.records.np3
same "$W/pell.np1" "$W/pell.records.np3"
# the halo at each step's start, nothing overlapped (CONTACTGRID_SIMULATE_OVERLAP=off, the former
# path): the same files as the overlapped default
CONTACTGRID_SIMULATE_OVERLAP=off run pour 3 pour.nolap.np3
same "$W/pour.np1" "$W/pour.nolap.np3"
CONTACTGRID_SIMULATE_OVERLAP=off run pell 4 pell.nolap.np4
same "$W/pell.np1" "$W/pell.nolap.np4"
# the halo's records in full (CONTACTGRID_SIMULATE_HALO_BYTES=full: 176 bytes a sphere, not 120)
CONTACTGRID_SIMULATE_HALO_BYTES=full run pour 2 pour.full.np2
same "$W/pour.np1" "$W/pour.full.np2"
# --stage-times: each rank's step phases in the summary, and the same files (the device waited for only)
run pour 2 pour.timed.np2 --stage-times
same "$W/pour.np1" "$W/pour.timed.np2"
grep -qE 'rank 1: halo [0-9.]+ \(hidden [0-9.]+, waited -?[0-9.]+\), frame [0-9.]+, relayout [0-9.]+, forces [0-9.]+ \([0-9]+ steps, [0-9]+ overlapped; halo [0-9]+ rows sent a step, 120 B a row\)' "$W/pour.timed.np2.out" ||
  { echo "no step phases of rank 1 under --stage-times"; exit 1; }
# each rank's forces on the host (CONTACTGRID_SIMULATE_RANKS=host): the same files
CONTACTGRID_SIMULATE_RANKS=host run pour 2 pour.host.np2
same "$W/pour.np1" "$W/pour.host.np2"
# without mpirun: the one-rank engine path writes the same files and energies
"$CG" simulate "$W/pour.h5" -o "$W/pour.plain" "${opts[@]}" -q
same "$W/pour.np1" "$W/pour.plain"
echo "simulate under mpirun: every rank count wrote the one-rank run's frames, contacts and energies"
