#!/usr/bin/env bash
# contactgrid simulate (#32) on the GPU, in one call per part (the default parts: under 3 minutes on one H100):
#   unit      the physics cases on the CUDA backend (restitution, Hertz, energy, oblique impact, static
#             friction, ellipsoid at rest), DemBackends.* (CPU = CUDA bit for bit: library and CLI
#             frames and contacts with history, energies summed three levels deep, runs of several
#             lengths; the same bits from the contact stage's two ways, the body index's two ways,
#             the per-body sort of the rows by B and CUB's, the terms stored only where read and all
#             of them), DemSum.*, Simulate*, the history's device cases
#   beverloo  the hopper discharge against Beverloo's law (jobs/beverloo.sh: three orifices, the
#             exponent fitted; 2.5 ± 0.2), CUDA
#   perf      whole steps (detection with history + forces + integration, no output) on a pour at a
#             settled pack's contact count (generate --kind pour --pour-spacing 1.97: six neighbours
#             each), fp32, CUDA: 2^20 and 2^24 spheres, 2^22 ellipsoids (a random pack at 6 contacts a body, aspect <= 1:4);
#             steps/s from log.csv (issue: 1 500 steps/s at 2^20, 2·10^9 sphere-steps/s at 2^24, 3·10^8
#             ellipsoid-steps/s at 2^22); then short runs with --stage-times: where a step's time goes
#             (per stage, and the engine's stages within detect; the energies' time a call). Spheres
#             run twice, "after" (the defaults) and "before" (CONTACTGRID_DEM_SEGMENTS=cub
#             CONTACTGRID_DEM_STORE=all CONTACTGRID_DEM_BLOCKS=1: CUB's segmented sort of the rows by
#             B, every contact term stored in double every step, the force kernels' registers
#             uncapped), and the two runs' frames and energies must be the same bytes; stage times
#             also with the registers uncapped (1 block an SM) and capped for 3 (2^24: FULL=1; the
#             default: 2). Ellipsoids (2^22) and the
#             contact stage's sums as A (CONTACTGRID_DEM_TERMS=sums) only with FULL=1.
#   one       (the default; under 3 minutes on one H100) simulate under mpirun with each rank's bodies
#             resident on its GPU: the rank interface's unit cases (DemRows/cuda.*: log_terms too),
#             DemBackends.*, RankSums.*; tests/cli/mpi_simulate_cuda.sh (the CPU's one-rank files, bit
#             for bit, from --backend cuda at -np 1 and 2 on this GPU, resident and host, the log rows
#             summed where the rows are and gathered); a 2^20 pour (fp32, 300 steps, a log row every
#             50, the last frame) without mpirun and under mpirun -np 1, "after" (the default: a log row
#             summed on the device) and "before" (CONTACTGRID_SIMULATE_OUTPUT=gather: every rank's
#             rows to rank 0 for each log row and frame): steps/s, the command's wall time and the
#             run's split (start, steps, relayout, log rows, frames: the summary's "wall time" line);
#             the three runs' files the same bytes
#   mpi2      (a host with 2 GPUs, its own call) simulate under mpirun -np 2 --backend cuda writes the
#             frames, contacts and energies of -np 1 and of the CPU backend, bit for bit
#   two       (a host with 2 GPUs, its own call; under 3 minutes) a pour of N2 spheres (default 2^23,
#             fp32, STEPS2 = 30 steps, a log row every 15, the first and last frames) under mpirun -np 1
#             and -np 2 --backend cuda, each after (the default: each rank's chunk sums of the log row)
#             and before (CONTACTGRID_SIMULATE_OUTPUT=gather): steps/s, the command's wall time and
#             the split as in one; the four runs' files the same bytes. FULL=1: also np 2 with a 4x
#             wider halo (CONTACTGRID_SIMULATE_HALO=4) and np 2 on the host (CONTACTGRID_SIMULATE_RANKS=host,
#             STEPS_HOST steps). (Issue: np 2 >= 1.8x np 1 at 2^25: N2=33554432.)
# Default: one. unit perf beverloo on request. Writes $OUT/simulate_<part>.tar.gz
# (each part's logs), $OUT/table.md, $OUT/stages.txt and $OUT/summary.txt; exits non-zero naming every
# failed check.
#   BIN=dir-with-the-CUDA-build's-binaries OUT=results-dir jobs/gpu_simulate_check.sh [PART ...]
# (BIN holds contactgrid and contactgrid_tests; run from the repository root; .devrt/env.sh, when
# present, supplies the runtime libraries.)
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgsim}; mkdir -p "$W"
BIN=$(cd "$BIN" && pwd)
CG="$BIN/contactgrid"
PY=$(command -v python3)  # (the device: python3 on PATH has NumPy and h5py)
parts=("$@"); [ ${#parts[@]} -eq 0 ] && parts=(one)
BEFORE=(CONTACTGRID_DEM_SEGMENTS=cub CONTACTGRID_DEM_STORE=all CONTACTGRID_DEM_BLOCKS=1)  # the path before this session's
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$OUT/summary.txt"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; git rev-parse --short HEAD 2>/dev/null; } \
  >"$OUT/device.txt" 2>&1
cat "$OUT/device.txt"

part_unit() {
  local d=$1
  local filter='DemPhysics/cuda.*:DemBackends*:DemSum*:Simulate*:DemDamping*:EngineHistory*:StepHistory*'
  "$BIN/contactgrid_tests" --gtest_filter="$filter" >"$d/unit.log" 2>&1 || failed+=("unit: $filter")
  grep -E '^\[  (PASSED|FAILED) |^\[  SKIPPED' "$d/unit.log" | head -30 | tee -a "$OUT/summary.txt"
  if grep -q '^\[  SKIPPED \].*cuda' "$d/unit.log"; then failed+=("unit: CUDA cases skipped (no GPU seen)"); fi
}

part_beverloo() {
  local d=$1
  # (the device: python3 on PATH has NumPy and h5py, its /usr/bin/python3 may not)
  BIN="$BIN" OUT="$W/beverloo" BACKEND=cuda PYTHON=$(command -v python3) jobs/beverloo.sh >"$d/beverloo.log" 2>&1 ||
    failed+=("beverloo: exponent outside 2.5 ± 0.2, a bed too low, or a run failed (see beverloo.log)")
  cp "$W/beverloo/beverloo.json" "$d/" 2>/dev/null
  tail -8 "$d/beverloo.log" | tee -a "$OUT/summary.txt"
}

part_perf() {
  local d=$1
  scene() {  # name kind count [extra generate options]
    local name=$1 kind=$2 n=$3; shift 3
    local rlow=(--rlow 0.00495)  # --max-aspect sets the smallest semi-axis itself (generate refuses both)
    [[ " $* " == *" --max-aspect "* ]] && rlow=()
    "$CG" generate "$W/$name.h5" --kind "$kind" -n "$n" "${rlow[@]}" --rhigh 0.005 --pour-spacing 1.97 --seed 5 -q "$@" ||
      { failed+=("perf: generate $name"); return 1; }
  }
  bench() {  # name count steps [label environment...]: the run stays in $W/$name.$label.run
    local name=$1 n=$2 steps=$3 label=${4:-after}; shift 3; [ $# -gt 0 ] && shift
    local run="$W/$name.$label.run"
    rm -rf "$run"
    if ! env "$@" "$CG" simulate "$W/$name.h5" -o "$run" --steps "$steps" --output-every "$steps" \
        --log-every $((steps / 6)) --backend cuda --precision fp32 --no-plot >"$d/$name.$label.log" 2>&1; then
      failed+=("perf: simulate $name ($label)"); tail -3 "$d/$name.$label.log"; return
    fi
    grep -q 'backend cuda' "$d/$name.$label.log" || failed+=("perf: $name did not run on the CUDA backend")
    cp "$run/log.csv" "$d/$name.$label.log.csv"
    # steps/s: log.csv's seconds_per_step (the steps alone), the first block (warm-up) left out
    local sps cpb
    sps=$(awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.1f", k / s }' "$run/log.csv")
    cpb=$(grep -oE '[0-9.]+ contacts/body' "$d/$name.$label.log" | head -1 | cut -d' ' -f1)
    printf '| %-22s | %9s | %6s | %8s | %10.3g | %9s |\n' "$name ($label)" "$n" "$steps" "$sps" \
      "$(awk -v s="$sps" -v n="$n" 'BEGIN { print s * n }')" "$cpb" >>"$OUT/table.md"
  }
  same_frames() {  # name: the after and before runs' frames and energies (log.csv), the same bytes
    local name=$1
    cmp <(cut -d, -f1-6 "$W/$name.after.run/log.csv") <(cut -d, -f1-6 "$W/$name.before.run/log.csv") \
      >"$d/$name.same.log" 2>&1 || failed+=("perf: $name's energies (log.csv) differ between the after and before paths")
    python3 - "$W/$name.after.run" "$W/$name.before.run" >>"$d/$name.same.log" 2>&1 <<'PYEOF' ||
import sys, glob, os, h5py
def datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()].tobytes()) if isinstance(o, h5py.Dataset) else None)
    return out
a, b = sys.argv[1], sys.argv[2]
names = sorted(os.path.basename(p) for p in glob.glob(a + "/frame_*.h5"))
assert names, "no frames"
for n in names:
    assert datasets(os.path.join(a, n)) == datasets(os.path.join(b, n)), f"{n} differs"
print(f"{len(names)} frames the same bytes, after and before; log.csv's energies too")
PYEOF
      failed+=("perf: $name's frames differ between the after and before paths ($name.same.log)")
    cat "$d/$name.same.log" | tee -a "$OUT/summary.txt"
    rm -rf "$W/$name.after.run" "$W/$name.before.run"
  }
  stages() {  # name steps label [environment]
    local name=$1 steps=$2 label=$3; shift 3
    rm -rf "$W/$name.st.run"
    if ! env "$@" "$CG" simulate "$W/$name.h5" -o "$W/$name.st.run" --steps "$steps" --output-every "$steps" \
        --backend cuda --precision fp32 --no-plot --stage-times >"$d/$name.$label.stages.log" 2>&1; then
      failed+=("perf: simulate $name --stage-times ($label)"); tail -3 "$d/$name.$label.stages.log"; return
    fi
    grep -q 'stage times' "$d/$name.$label.stages.log" || failed+=("perf: $name printed no stage times")
    { echo "$name ($label):"; grep -E 'steps/s|stage times|within detect|energ' "$d/$name.$label.stages.log"; } \
      >>"$OUT/stages.txt"
    rm -rf "$W/$name.st.run"
  }
  printf '| %-22s | %9s | %6s | %8s | %10s | %9s |\n' run bodies steps steps/s body-st/s contacts/b >"$OUT/table.md"
  echo '|---|---|---|---|---|---|' >>"$OUT/table.md"
  : >"$OUT/stages.txt"
  local n20=${N20:-$((1 << 20))} n24=${N24:-$((1 << 24))}  # (smaller: a dry run of this script)
  if scene spheres_2e20 pour "$n20"; then
    bench spheres_2e20 "$n20" 300 after
    bench spheres_2e20 "$n20" 300 before "${BEFORE[@]}"
    same_frames spheres_2e20
    stages spheres_2e20 120 after
    stages spheres_2e20 120 before "${BEFORE[@]}"
    stages spheres_2e20 120 after-blocks1 CONTACTGRID_DEM_BLOCKS=1
    stages spheres_2e20 120 after-blocks3 CONTACTGRID_DEM_BLOCKS=3
    [ "${FULL:-0}" = 1 ] && stages spheres_2e20 120 a-sums CONTACTGRID_DEM_TERMS=sums
    rm -f "$W/spheres_2e20.h5"
  fi
  # ellipsoids: a pour's lattice leaves randomly turned ellipsoids apart (0.4 contacts a body at the
  # smallest spacing), so a random pack at six contacts a body, which stays above five a body while
  # its overlaps push it apart (a rebuild most steps: the harder case)
  if [ "${FULL:-0}" = 1 ]; then
    if "$CG" generate "$W/ellipsoids_2e22.h5" --kind ellipsoids -n $((1 << 22)) --rhigh 0.005 --max-aspect 4 \
        --contacts-per-body 6 --seed 5 -q; then
      bench ellipsoids_2e22 $((1 << 22)) 60
      rm -rf "$W/ellipsoids_2e22.after.run"
      stages ellipsoids_2e22 30 after
      rm -f "$W/ellipsoids_2e22.h5"
    else
      failed+=("perf: generate ellipsoids_2e22")
    fi
  fi
  if scene spheres_2e24 pour "$n24"; then
    bench spheres_2e24 "$n24" 60 after
    bench spheres_2e24 "$n24" 60 before "${BEFORE[@]}"
    same_frames spheres_2e24
    stages spheres_2e24 30 after
    stages spheres_2e24 30 before "${BEFORE[@]}"
    stages spheres_2e24 30 after-blocks1 CONTACTGRID_DEM_BLOCKS=1
    [ "${FULL:-0}" = 1 ] && stages spheres_2e24 30 after-blocks3 CONTACTGRID_DEM_BLOCKS=3
    [ "${FULL:-0}" = 1 ] && stages spheres_2e24 30 a-sums CONTACTGRID_DEM_TERMS=sums
    rm -f "$W/spheres_2e24.h5"
  fi
  cat "$OUT/table.md" "$OUT/stages.txt" | tee -a "$OUT/summary.txt"
}

part_two() {
  local d=$1 n=${N2:-$((1 << 23))} steps=${STEPS2:-30} host_steps=${STEPS_HOST:-3}
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1 \
    OMPI_MCA_btl_vader_single_copy_mechanism=cma  # the image presets none: host copies 1.3-2.5x slower
  local gpus; gpus=$(nvidia-smi -L 2>/dev/null | wc -l)
  [ "$gpus" -ge 2 ] || { failed+=("two: needs 2 GPUs, $gpus seen"); return; }
  "$CG" generate "$W/t.h5" --kind pour -n "$n" --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 --seed 5 -q ||
    { failed+=("two: generate"); return; }
  run_two() {  # TAG NP STEPS [ENV...]
    local tag=$1 np=$2 k=$3; shift 3
    rm -rf "$W/t.$tag.run"
    if ! timed "$d/$tag.log" env "$@" mpirun --bind-to none -np "$np" "$CG" simulate "$W/t.h5" -o "$W/t.$tag.run" \
        --steps "$k" --output-every "$k" --log-every $((k / 2 > 0 ? k / 2 : 1)) --backend cuda --precision fp32 \
        --no-plot; then
      failed+=("two: $tag run"); tail -3 "$d/$tag.log"; return
    fi
    cp "$W/t.$tag.run/log.csv" "$d/$tag.log.csv"
    report "two: $n spheres, $tag" "$W/t.$tag.run" "$d/$tag.log"
  }
  same_two() {  # TAG1 TAG2
    "$PY" tests/cli/same_run.py "$W/t.$1.run" "$W/t.$2.run" >>"$d/compare.log" 2>&1 ||
      failed+=("two: $2's frames or energies differ from $1's (compare.log)")
  }
  run_two np1 1 "$steps"
  run_two np1.before 1 "$steps" CONTACTGRID_SIMULATE_OUTPUT=gather
  same_two np1 np1.before
  rm -rf "$W/t.np1.before.run"
  run_two np2 2 "$steps"
  same_two np1 np2
  rm -rf "$W/t.np1.run"
  run_two np2.before 2 "$steps" CONTACTGRID_SIMULATE_OUTPUT=gather
  same_two np2 np2.before
  rm -rf "$W/t.np2.before.run"
  if [ "${FULL:-0}" = 1 ]; then
    run_two np2.halo4 2 "$steps" CONTACTGRID_SIMULATE_HALO=4
    same_two np2 np2.halo4
    rm -rf "$W/t.np2.halo4.run"
    run_two np2.host 2 "$host_steps" CONTACTGRID_SIMULATE_RANKS=host
    rm -rf "$W/t.np2.host.run"
  fi
  cat "$d/compare.log" | tee -a "$OUT/summary.txt"
  rm -rf "$W/t.np2.run" "$W/t.h5"
  local a b
  a=$(steps_per_second_of "$d/np1.log.csv"); b=$(steps_per_second_of "$d/np2.log.csv")
  log "two: np 2 / np 1 = $(awk -v a="$a" -v b="$b" 'BEGIN { if (a > 0) printf "%.2f", b / a }') (issue: >= 1.8 at 2^25)"
}

# timed LOG COMMAND...: the command's output into LOG, then its wall seconds ("command wall S s")
timed() {
  local log=$1; shift
  local t0 rc
  t0=$(date +%s.%N)
  "$@" >"$log" 2>&1
  rc=$?
  echo "command wall $(awk -v a="$t0" -v b="$(date +%s.%N)" 'BEGIN { printf "%.2f", b - a }') s" >>"$log"
  return $rc
}

# report LABEL RUNDIR LOG: steps/s (log.csv), the command's wall time and the run's split (summary)
report() {
  local label=$1 run=$2 out=$3
  log "$label: $(steps_per_second "$run") steps/s; $(grep -o 'command wall [0-9.]* s' "$out");$(grep -o ' wall time .*' "$out" | head -1)"
}

steps_per_second_of() {  # a log.csv
  awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.2f", k / s }' "$1"
}
# steps/s of a run directory: log.csv's seconds_per_step (the steps alone), the first block left out
steps_per_second() { steps_per_second_of "$1/log.csv"; }

part_one() {
  local d=$1
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
  local filter='DemRows*:DemBackends*:RankSums*'
  "$BIN/contactgrid_tests" --gtest_filter="$filter" >"$d/unit.log" 2>&1 || failed+=("one: unit $filter")
  grep -E '^\[  (PASSED|FAILED) |^\[  SKIPPED' "$d/unit.log" | head -20 | tee -a "$OUT/summary.txt"
  if grep -q '^\[  SKIPPED \]' "$d/unit.log"; then failed+=("one: CUDA cases skipped (no GPU seen)"); fi
  PYTHON="$PY" timeout 150 tests/cli/mpi_simulate_cuda.sh "$CG" "$(command -v mpirun)" \
    "$W/cli_cuda" >"$d/cli_cuda.log" 2>&1
  local rc=$?
  tail -3 "$d/cli_cuda.log" | tee -a "$OUT/summary.txt"
  [ $rc -eq 0 ] || failed+=("one: mpi_simulate_cuda.sh (rc $rc: 77 = skipped, no GPU)")
  rm -rf "$W/cli_cuda"
  local n=$((1 << 20))
  "$CG" generate "$W/p20.h5" --kind pour -n $n --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 --seed 5 -q ||
    { failed+=("one: generate"); return; }
  local common=(--steps 300 --log-every 50 --output-every 300 --backend cuda --precision fp32 --no-plot)
  rm -rf "$W"/p20.*.run
  timed "$d/p20.plain.log" "$CG" simulate "$W/p20.h5" -o "$W/p20.plain.run" "${common[@]}" ||
    failed+=("one: 2^20 without mpirun")
  timed "$d/p20.np1.log" mpirun --bind-to none -np 1 "$CG" simulate "$W/p20.h5" -o "$W/p20.np1.run" "${common[@]}" ||
    failed+=("one: 2^20 np 1 (after)")
  timed "$d/p20.np1.before.log" env CONTACTGRID_SIMULATE_OUTPUT=gather mpirun --bind-to none -np 1 "$CG" simulate \
    "$W/p20.h5" -o "$W/p20.np1.before.run" "${common[@]}" || failed+=("one: 2^20 np 1 (before)")
  local run
  for run in plain np1 np1.before; do
    cp "$W/p20.$run.run/log.csv" "$d/p20.$run.log.csv" 2>/dev/null
    report "one: 2^20 pour fp32 $run" "$W/p20.$run.run" "$d/p20.$run.log"
  done
  "$PY" tests/cli/same_run.py "$W/p20.plain.run" "$W/p20.np1.run" >>"$d/compare.log" 2>&1 ||
    failed+=("one: 2^20 np 1's files differ from the run without mpirun's")
  "$PY" tests/cli/same_run.py "$W/p20.np1.run" "$W/p20.np1.before.run" >>"$d/compare.log" 2>&1 ||
    failed+=("one: 2^20 np 1's files differ after and before")
  cat "$d/compare.log" | tee -a "$OUT/summary.txt"
  rm -rf "$W"/p20.*
}

part_mpi2() {
  local d=$1
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
  local gpus; gpus=$(nvidia-smi -L 2>/dev/null | wc -l)
  [ "$gpus" -ge 2 ] || { failed+=("mpi2: needs 2 GPUs, $gpus seen"); return; }
  "$CG" generate "$W/m2.h5" --kind pour -n 60000 --seed 5 -q
  local opts=(--steps 600 --output-every 200 --log-every 100 --gravity -4 0 -9.81 --restitution 0.3 --friction 0.5
    --write-contacts --no-plot)
  rm -rf "$W"/m2.*run
  mpirun -np 2 "$CG" simulate "$W/m2.h5" -o "$W/m2.np2.run" "${opts[@]}" --backend cuda >"$d/np2.log" 2>&1 ||
    failed+=("mpi2: np 2 cuda run")
  mpirun -np 1 "$CG" simulate "$W/m2.h5" -o "$W/m2.np1.run" "${opts[@]}" --backend cuda >"$d/np1.log" 2>&1 ||
    failed+=("mpi2: np 1 cuda run")
  mpirun -np 1 "$CG" simulate "$W/m2.h5" -o "$W/m2.cpu.run" "${opts[@]}" --backend cpu >"$d/cpu.log" 2>&1 ||
    failed+=("mpi2: np 1 cpu run")
  python3 - "$W/m2.np1.run" "$W/m2.np2.run" "$W/m2.cpu.run" >"$d/compare.log" 2>&1 <<'PYEOF' ||
import sys, glob, os, h5py
ref = sys.argv[1]
def datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()].tobytes()) if isinstance(o, h5py.Dataset) else None)
    return out
names = sorted(os.path.basename(p) for p in glob.glob(ref + "/*.h5"))
assert names, "no frames"
for other in sys.argv[2:]:
    for n in names:
        a, b = datasets(os.path.join(ref, n)), datasets(os.path.join(other, n))
        assert a == b, f"{other}/{n} differs from {ref}/{n}"
    print(f"{other}: {len(names)} files the same as {ref}")
PYEOF
    failed+=("mpi2: frames or contacts differ (compare.log)")
  cat "$d/compare.log" | tee -a "$OUT/summary.txt"
  grep -h 'steps/s' "$d"/np*.log | tee -a "$OUT/summary.txt"
}

for part in "${parts[@]}"; do
  d="$W/logs_$part"; rm -rf "$d"; mkdir -p "$d"
  log "part $part"
  case $part in
    unit | beverloo | perf | one | mpi2 | two) "part_$part" "$d" ;;
    *) failed+=("unknown part $part") ;;
  esac
  tar -czf "$OUT/simulate_$part.tar.gz" -C "$W" "logs_$part"
done

if [ ${#failed[@]} -gt 0 ]; then
  log "FAILED:"; printf '  - %s\n' "${failed[@]}" | tee -a "$OUT/summary.txt"; exit 1
fi
log "all checks passed"
