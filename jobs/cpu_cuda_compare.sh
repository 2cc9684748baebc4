# Sourced by the GPU check scripts (gpu_narrow_check.sh, gpu_shapes_check.sh): CLI CPU vs CUDA
# byte-identical /contacts. Needs CG (the contactgrid binary).
#   compare_cuda SCENE PREC TAG [VAR=value ...]
# detects SCENE.h5 in precision PREC on the CPU backend once (SCENE.cpu.PREC.h5, kept for the next
# calls) and on the CUDA backend with the variables set (under `mpirun -np $MPIRUN_NP` when that is
# set), with $DETECT_ARGS (e.g. --fields full) on both — the same for every call on one scene and
# precision, whose CPU file is reused — and prints "compare TAG: " and compare's verdict.
compare_cuda() {
  local scene=$1 prec=$2 tag=$3
  shift 3
  local ref="$scene.cpu.$prec.h5" out="$scene.cuda.h5" launch=()
  [ -f "$ref" ] || "$CG" detect "$scene.h5" -o "$ref" --backend cpu --precision "$prec" ${DETECT_ARGS:-} -q
  [ -n "${MPIRUN_NP:-}" ] && launch=(mpirun --bind-to none -np "$MPIRUN_NP")
  rm -f "$out"
  env "$@" "${launch[@]}" "$CG" detect "$scene.h5" -o "$out" --backend cuda --precision "$prec" ${DETECT_ARGS:-} -q
  echo "compare $tag: $("$CG" compare "$ref" "$out" 2>&1 | tail -1)"
}
