#!/usr/bin/env bash
# End to end: bodies that move (detect --steps N --drift V). At every rank count (1-4, every rank
# reading every row or its own rows) and every skin (none, fixed, auto), -o receives the last step's
# contacts and --final-scene the last step's bodies, and a plain detect of that scene writes the same
# /contacts bytes; the last step's contacts are the same for every rank count. Spheres, a mixed
# scene whose ellipsoids also turn (--spin), and eight intruders ten times the grains' radius (the
# halo by radius: each intruder to every slab it reaches, the grains' halos small).
# Usage: moving_steps.sh CONTACTGRID MPIEXEC WORKDIR
set -euo pipefail
CG=$1; MPIEXEC=$2; W=$3
rm -rf "$W"; mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
"$CG" generate "$W/u.h5" -n 4000 --seed 21 --contacts-per-body 1 -q
"$CG" generate "$W/m.h5" -n 2000 --seed 22 --kind mixed --ellipsoid-fraction 0.4 --rlow 0.3 --rhigh 0.6 \
  --contacts-per-body 1 -q
"$CG" generate "$W/b.h5" -n 3000 --seed 23 --kind intruders --rlow 0.3 --rhigh 3 --intruders 8 \
  --contacts-per-body 1 -q
# SCENE NP SKIN READ EXTRA…: the steps, then the plain run of the final scene; both files compared.
drift_and_compare() {
  local scene=$1 np=$2 skin=$3 read=$4; shift 4
  local tag="$scene.$np.$skin.$read"
  local opts=(--backend cpu --precision fp64 --fields full --threads 1 -q)
  "$MPIEXEC" -np "$np" --oversubscribe --allow-run-as-root "$CG" detect "$W/$scene.h5" -o "$W/$tag.last.h5" \
    "${opts[@]}" --read "$read" --steps 8 --drift 0.12 --skin "$skin" --final-scene "$W/$tag.final.h5" "$@"
  "$CG" detect "$W/$tag.final.h5" -o "$W/$tag.plain.h5" "${opts[@]}"
  "$CG" compare "$W/$tag.last.h5" "$W/$tag.plain.h5"
  "$CG" compare "$W/$scene.1.0.all.last.h5" "$W/$tag.last.h5"
}
for skin in 0 0.2 auto; do
  for np in 1 2 3 4; do drift_and_compare u "$np" "$skin" all; done
  drift_and_compare u 3 "$skin" own
done
drift_and_compare b 1 0 all
for np in 2 3 4; do drift_and_compare b "$np" 0.2 own; done
drift_and_compare b 3 auto all
drift_and_compare m 1 0 all --spin 0.2
for np in 2 3; do drift_and_compare m "$np" 0.2 own --spin 0.2; done
drift_and_compare m 4 auto all --spin 0.2
# the drift changed the contacts: the last step's file is not the scene's
"$CG" detect "$W/u.h5" -o "$W/u.file.h5" --backend cpu --precision fp64 --fields full -q
if "$CG" compare "$W/u.file.h5" "$W/u.1.0.all.last.h5" >/dev/null; then
  echo "the drift did not change the contacts"; exit 1
fi
echo "moving steps: every rank count and skin wrote the final scene's contacts"
