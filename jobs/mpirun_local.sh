#!/usr/bin/env bash
# One machine, several ranks: CPU ranks (default) or one rank per GPU.
#
#   jobs/mpirun_local.sh SCENE.h5 OUT.h5 [more contactgrid detect options]
#   NP=4 jobs/mpirun_local.sh SCENE.h5 OUT.h5      (4 ranks; on fewer cores it adds --oversubscribe)
#
# Environment:
#   CONTACTGRID   the binary (default: the build beside this script, ../build/src/contactgrid, found
#                 from any working directory; else contactgrid on PATH)
#   MODE          cpu (default) | gpu
#   NP            ranks (cpu default: 2, or 1 on a one-core machine; gpu default: number of GPUs).
#                 More ranks than cores need mpirun's --oversubscribe: added for you, with a note
#   THREADS       CPU threads per rank (cpu default: cores / NP)
#   MPIRUN_ARGS   extra mpirun arguments (e.g. "--oversubscribe", "--host a,b")
#
# GPU mode: rank r uses GPU (node-local rank) % (GPUs visible), chosen by contactgrid itself, so no
# CUDA_VISIBLE_DEVICES juggling is needed. Debian's Open MPI is not CUDA-aware; none is required
# (ranks exchange host arrays).
set -euo pipefail

if [[ $# -lt 2 ]]; then
  sed -n '2,20p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
scene=$1
out=$2
shift 2

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
bin=${CONTACTGRID:-}
if [[ -z $bin ]]; then
  if [[ -x $here/../build/src/contactgrid ]]; then bin=$here/../build/src/contactgrid
  elif command -v contactgrid >/dev/null; then bin=$(command -v contactgrid)
  else
    echo "mpirun_local.sh: no contactgrid: neither $here/../build/src/contactgrid (jobs/build.sh makes it)" \
         "nor one on PATH; set CONTACTGRID to the binary" >&2
    exit 2
  fi
fi
[[ -x $bin ]] || { echo "mpirun_local.sh: CONTACTGRID=$bin is not an executable" >&2; exit 2; }

mode=${MODE:-cpu}
cores=$(nproc)
args=()
case $mode in
  cpu)
    np=${NP:-$(( cores >= 2 ? 2 : 1 ))}
    threads=${THREADS:-$(( cores / np > 0 ? cores / np : 1 ))}
    args=(--backend cpu --threads "$threads")
    export OMP_NUM_THREADS=$threads
    ;;
  gpu)
    gpus=$(nvidia-smi -L 2>/dev/null | wc -l || true)
    [[ ${gpus:-0} -gt 0 ]] || { echo "mpirun_local.sh: MODE=gpu but nvidia-smi lists no GPU" >&2; exit 2; }
    np=${NP:-$gpus}
    args=(--backend cuda)
    ;;
  *) echo "mpirun_local.sh: MODE must be cpu or gpu, not '$mode'" >&2; exit 2 ;;
esac

root_flag=()
[[ $(id -u) -eq 0 ]] && root_flag=(--allow-run-as-root)  # containers run as root

# Open MPI refuses more ranks than cores (slots) unless told to oversubscribe.
over=()
if (( np > cores )) && [[ " ${MPIRUN_ARGS:-} " != *" --oversubscribe "* ]]; then
  echo "mpirun_local.sh: $np ranks on $cores cores: adding --oversubscribe" >&2
  over=(--oversubscribe)
fi

# --bind-to none: each rank runs its own OpenMP threads; binding every rank to one core would
# serialise them.
set -x
# shellcheck disable=SC2086  # MPIRUN_ARGS is a list of words on purpose
exec mpirun -np "$np" --bind-to none "${root_flag[@]}" "${over[@]}" ${MPIRUN_ARGS:-} \
  "$bin" detect "$scene" -o "$out" "${args[@]}" "$@"
