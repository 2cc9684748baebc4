#!/usr/bin/env bash
# End to end: `mpirun -np P contactgrid detect` writes the same /contacts bytes as the one-rank run,
# for P = 2, 3, 4 (and 8 oversubscribed), on a uniform and a polydisperse scene, fp64 and fp32, with
# the defaults (every rank reads every row, all ranks being on one node; rank 0 gathers and writes)
# and, at P = 3, each rank reading its own rows and each rank writing its id_a range; then an
# ellipsoid and a mixed scene (P = 2, 3, 4, own rows, id_a ranges) and the resident steps on it (with
# --spin: turning ellipsoids);
# --precision auto picks the same mode on 1 and 3 ranks.
# Usage: mpi_identical.sh CONTACTGRID MPIEXEC WORKDIR
set -euo pipefail
CG=$1; MPIEXEC=$2; W=$3
rm -rf "$W"; mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
"$CG" generate "$W/u.h5" -n 20000 --seed 5 -q
"$CG" generate "$W/p.h5" -n 20000 --seed 6 --kind polydisperse --rlow 0.01 --rhigh 1 -q
# SCENE PREC NP…: the one-rank file, then each NP (every rank reads every row), then np 3 reading own
# rows and np 3 writing id_a ranges: every /contacts byte-identical to the one-rank run's.
identical_across_ranks() {
  local scene=$1 prec=$2; shift 2
  local run=("$MPIEXEC" --oversubscribe --allow-run-as-root)
  local opts=(--backend cpu --precision "$prec" --fields full --threads 1 -q)
  "$CG" detect "$W/$scene.h5" -o "$W/$scene.$prec.1.h5" --backend cpu --precision "$prec" --fields full -q
  for np in "$@"; do
    "${run[@]}" -np "$np" "$CG" detect "$W/$scene.h5" -o "$W/$scene.$prec.$np.h5" "${opts[@]}"
    "$CG" compare "$W/$scene.$prec.1.h5" "$W/$scene.$prec.$np.h5"
  done
  "${run[@]}" -np 3 "$CG" detect "$W/$scene.h5" -o "$W/$scene.$prec.own.h5" "${opts[@]}" --read own
  "$CG" compare "$W/$scene.$prec.1.h5" "$W/$scene.$prec.own.h5"
  "${run[@]}" -np 3 "$CG" detect "$W/$scene.h5" -o "$W/$scene.$prec.ranks.h5" "${opts[@]}" --write ranks
  "$CG" compare "$W/$scene.$prec.1.h5" "$W/$scene.$prec.ranks.h5"
}
for scene in u p; do
  for prec in fp64 fp32; do identical_across_ranks $scene $prec 2 3 4 8; done
done
# --precision auto chooses from the all-gathered bounds: one rank and three (reading their own rows)
# pick the same mode (the summary's line) and write the same bytes. SCENE EXPECTED [--accuracy …]
same_auto_pick() {
  local scene=$1 want=$2; shift 2
  "$CG" detect "$W/$scene.h5" -o "$W/$scene.auto.1.h5" --backend cpu "$@" >"$W/auto.1.txt"
  "$MPIEXEC" -np 3 --oversubscribe --allow-run-as-root "$CG" detect "$W/$scene.h5" -o "$W/$scene.auto.3.h5" \
    --backend cpu --threads 1 --read own "$@" >"$W/auto.3.txt"
  local one three
  one=$(grep -o 'precision auto: [a-z0-9]*' "$W/auto.1.txt"); three=$(grep -o 'precision auto: [a-z0-9]*' "$W/auto.3.txt")
  [ "$one" = "precision auto: $want" ] && [ "$three" = "$one" ] ||
    { echo "auto on $scene $*: np 1 '$one', np 3 '$three', expected $want"; exit 1; }
  "$CG" compare "$W/$scene.auto.1.h5" "$W/$scene.auto.3.h5"
}
same_auto_pick u mixed
same_auto_pick u fp32 --accuracy 1e-2,0.1
same_auto_pick p mixed --accuracy 1e-2,0.1  # r_min 0.01: fp32's r_max·θ32 is 0.042·r_min
# ellipsoid and mixed scenes: the shape rows move with their bodies (distribute, halo)
"$CG" generate "$W/e.h5" -n 3000 --seed 7 --kind ellipsoids --rlow 0.3 --rhigh 1 -q
"$CG" generate "$W/m.h5" -n 4000 --seed 8 --kind mixed --ellipsoid-fraction 0.4 --rlow 0.3 --rhigh 1 \
  --contacts-per-body 1 -q
for scene in e m; do
  for prec in fp64 fp32; do identical_across_ranks $scene $prec 2 3 4; done
done
"$MPIEXEC" -np 3 --oversubscribe --allow-run-as-root "$CG" detect "$W/m.h5" -o "$W/m.ranks.h5" --backend cpu \
  --precision fp64 --fields full --threads 1 --read own --write ranks -q
"$CG" compare "$W/m.fp64.1.h5" "$W/m.ranks.h5"
# the resident steps on the mixed scene: every step finds the file's contacts (checked by the run:
# count and pairs' hash, else exit 1) at np 1, 2 and 3 (own rows, a skin), the file as without --steps
for np in 1 2 3; do
  extra=(); [ "$np" -eq 3 ] && extra=(--read own --skin 0.05)
  "$MPIEXEC" -np "$np" --oversubscribe --allow-run-as-root "$CG" detect "$W/m.h5" -o "$W/steps.$np.h5" \
    --backend cpu --precision fp64 --fields full --threads 1 --steps 2 "${extra[@]}" >"$W/steps.txt"
  grep -q "contacts per step (= the file's)" "$W/steps.txt" || { cat "$W/steps.txt"; exit 1; }
  "$CG" compare "$W/m.fp64.1.h5" "$W/steps.$np.h5"
done
# --spin: the ellipsoids turn in the steps, the ghosts' orientations come through the halo, and the
# last step equals the turned bodies detected from scratch (checked by the run, else exit 8); the file
# is the run's
"$MPIEXEC" -np 3 --oversubscribe --allow-run-as-root "$CG" detect "$W/m.h5" -o "$W/spin.h5" --backend cpu \
  --precision fp64 --fields full --threads 1 --read own --steps 3 --spin 0.3 >"$W/spin.txt"
grep -q "contacts on the last step (= the turned bodies detected from scratch)" "$W/spin.txt" ||
  { cat "$W/spin.txt"; exit 1; }
"$CG" compare "$W/m.fp64.1.h5" "$W/spin.h5"
# an error on one rank ends the whole job with one message and no output
if "$MPIEXEC" -np 3 --oversubscribe --allow-run-as-root "$CG" detect "$W/missing.h5" -o "$W/x.h5" 2>"$W/err"; then
  echo "a missing scene must fail"; exit 1
fi
grep -q "missing.h5" "$W/err" || { cat "$W/err"; exit 1; }
[ ! -e "$W/x.h5" ] || { echo "output left behind"; exit 1; }
echo "mpi_identical: OK"
