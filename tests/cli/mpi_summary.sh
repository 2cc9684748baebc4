#!/usr/bin/env bash
# What detect prints about ranks (issue #36): under mpirun with every rank reading every row the stage
# table shows the ghost selection where it happens ("select", no halo row); reading own rows it shows
# redistribute and halo; one rank prints no MPI-only line, not even with -v (the merge line). Then
# jobs/mpirun_local.sh from another working directory, with more ranks than cores: it finds the
# binary (CONTACTGRID, or the build beside it when that is the binary under test) and adds
# --oversubscribe, saying so.
# Usage: mpi_summary.sh CONTACTGRID MPIEXEC WORKDIR
set -euo pipefail
CG=$1; MPIEXEC=$2; W=$3
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
rm -rf "$W"; mkdir -p "$W"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
fail() { echo "FAIL: $*"; exit 1; }
"$CG" generate "$W/s.h5" -n 4000 --seed 2 -q
run=("$MPIEXEC" --oversubscribe --allow-run-as-root -np 2 "$CG" detect "$W/s.h5" --backend cpu --threads 1)

"${run[@]}" -o "$W/all.h5" --read all -v >"$W/all.txt"
grep -q "^  select " "$W/all.txt" || fail "--read all: no select row"
! grep -q -e '^  halo ' -e '^  redistribute ' "$W/all.txt" || fail "--read all: halo or redistribute row"
grep -q 'merge: .* from 2 rank(s)' "$W/all.txt" || fail "--read all -v: no merge line"

"${run[@]}" -o "$W/own.h5" --read own >"$W/own.txt"
grep -q '^  redistribute ' "$W/own.txt" && grep -q '^  halo ' "$W/own.txt" || fail "--read own: rows missing"
! grep -q '^  select ' "$W/own.txt" || fail "--read own: a select row"

"$CG" detect "$W/s.h5" -o "$W/one.h5" --backend cpu -v >"$W/one.txt"
! grep -q -e merge -e redistribute -e halo -e gather -e select -e 'over ranks' "$W/one.txt" \
  || fail "one rank printed an MPI-only line: $(cat "$W/one.txt")"

# mpirun_local.sh, started from the work directory, 3 ranks on however many cores (2 in CI: 3 > 2).
script=$here/../../jobs/mpirun_local.sh
default_bin=$(cd "$here/../.." && pwd)/build/src/contactgrid
env_bin=(env CONTACTGRID="$CG")
[[ $(realpath "$CG") == $(realpath -m "$default_bin") ]] && env_bin=(env -u CONTACTGRID)
cores=$(nproc)
(cd "$W" && "${env_bin[@]}" NP=$((cores + 1)) THREADS=1 "$script" s.h5 local.h5 -q) >"$W/local.txt" 2>&1 \
  || { cat "$W/local.txt"; fail "mpirun_local.sh"; }
grep -q 'adding --oversubscribe' "$W/local.txt" || fail "mpirun_local.sh said nothing of --oversubscribe"
"$CG" compare "$W/one.h5" "$W/local.h5"
echo "OK"
