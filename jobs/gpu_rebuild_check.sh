#!/usr/bin/env bash
# A rebuild against a fresh detection (issue #31, Performance: a build of the skin's kept candidates
# <= 1.0x a fresh detection), one H100, about 4 minutes:
#   BIN=dir OUT=dir [N=16777216] [STEPS=40] [ROUNDS=2] [PROFILE=1] [KIND=uniform|ellipsoids] [UNIT=1]
#   jobs/gpu_rebuild_check.sh
# (a dry run of the script without a GPU: BACKEND=cpu N=65536 PROFILE=0; its CUDA cases then fail)
# BIN holds the CUDA build's contactgrid and contactgrid_tests (and contactgrid_mpi_tests, whose
# MovingSteps.Cuda* and StepLoop.*Cuda* cases run at np 2 where it is there). It runs, in one call:
#  1. the CUDA skin cases (the build's in-place list, its second walk when the candidates outgrow their
#     room, the first build's room from the last pair count; every step = the CPU's fresh detection)
#     with the defaults and again under CONTACTGRID_STEP_REBUILD=fill (the former path);
#  2. N spheres fp32 at 6 contacts a body (`generate --seed 24 --contacts-per-body 6`), `detect --steps
#     STEPS --drift 0.01 --skin auto --backend cuda --precision fp32` (1 % of r_max a step) for each of
#     VARIANTS (default: "now" the defaults, "lev" `--broad-phase levels` — what auto ran for a skin
#     auto before it kept the grid: builds not in cell order, reuses selecting from the (a, b) list —
#     and "fill" CONTACTGRID_STEP_REBUILD=fill), alternated ROUNDS times, and once a fresh detection a
#     step (--skin 0, 6 steps; auto's broad phase, and the grid's); every run with CONTACTGRID_STEP_TRACE=1, whose "build:" lines give each
#     building step's pairs / order / narrow seconds, skin, entries, pair tests, candidates and walks
#     of the cells (2: its candidates outgrew their room);
#  3. the last step's /contacts of each of the first round's runs byte-identical (`contactgrid compare`)
#     to a plain detect of the final scene (--final-scene); every run's pair hash the same;
#  4. PROFILE=1 (default where ncu exists): each kernel's duration in a short run (12 steps, the
#     defaults) under Nsight Compute, summed by name — the GPU time of a build's kernels against its
#     stage times (PROFILE=0 skips it: ~1-2 minutes).
# Table (ms; medians over the steps): fresh = a fresh detection a step, build = the summary's
# detection of a building step (it counts step 0 too: skin auto starts with a fresh skin-0 call),
# lists built = the median over the builds of kept lists alone (the trace's lines), reuse = a step
# that reused them, mean = the mean step, mean detection = the same less the frame (the drift's motion
# of the bodies, not the detection's); then each run's building step's stages and its per-build
# trace lines.
# What to expect (BENCHMARKS §32): at 2^24 auto once gave a skin-auto run the one-level levels walk
# (picked for fresh device calls from 2^21 bodies), so none of its builds ran in cell order ("lev"
# shows that path: fill walks, the (a, b) select of every reuse); "now" keeps the grid, so its builds
# write the kept list in cell order and its reuses run the cell-order narrow (cell_narrow_kernel).
# Look at "reuse" (the narrow over the kept list) and the "build:" lines ("walks 2": the candidates
# outgrew their room).
# (The tuner picks its skins from measured times, so paths may build at other steps and skins.)
# Exits non-zero naming each failed check.
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; CG=$BIN/contactgrid
BACKEND=${BACKEND:-cuda}; N=${N:-16777216}; STEPS=${STEPS:-40}; ROUNDS=${ROUNDS:-2}; KIND=${KIND:-uniform}
W=${SCRATCH:-/dev/shm}/cg_rebuild
mkdir -p "$W" "$OUT"
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version --format=csv,noheader; git log --oneline -1 2>/dev/null; } |
  tee "$OUT/device.txt"
gtest_ok() {  # LOG: passed, nothing failed, no CUDA case skipped
  grep -q '^\[  PASSED  \]' "$1" && ! grep -q '^\[  FAILED  \]' "$1" && ! grep -q 'no CUDA device' "$1"
}

if [ "${UNIT:-1}" = 1 ]; then  # UNIT=0: the cases were run already in this call
log "== 1. CUDA skin cases, defaults and CONTACTGRID_STEP_REBUILD=fill"
FILTER='EngineSkinCuda*:EngineSkinTest/cuda*:KeptRoom*:CudaBackendTest*'
timeout 120 "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter="$FILTER" >"$OUT/unit.log" 2>&1
gtest_ok "$OUT/unit.log" || failed+=(unit)
timeout 90 env CONTACTGRID_STEP_REBUILD=fill "$BIN/contactgrid_tests" --gtest_color=no \
  --gtest_filter='EngineSkinCuda*:EngineSkinTest/cuda*' >"$OUT/unit_fill.log" 2>&1
gtest_ok "$OUT/unit_fill.log" || failed+=(unit_fill)
for f in unit unit_fill; do
  echo "$f: $(grep -hE '^\[  (PASSED|FAILED)  \] [0-9]+ test' "$OUT/$f.log" | tr '\n' ' ')skipped $(grep -cE '^\[  SKIPPED \] .*\(' "$OUT/$f.log")"
done
if [ -x "$BIN/contactgrid_mpi_tests" ]; then  # the step loop's CUDA cases (cell-order builds) at np 2
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
  timeout 150 mpirun --bind-to none --allow-run-as-root -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no \
    --gtest_filter='MovingSteps.Cuda*:StepLoop.*Cuda*' >"$OUT/mpi_tests.np2.log" 2>&1 || failed+=(mpi_tests_np2)
  echo "mpi tests np 2 (MovingSteps.Cuda*, StepLoop.*Cuda*): $(grep -cE '^\[       OK' "$OUT/mpi_tests.np2.log") ok lines, $(tail -1 "$OUT/mpi_tests.np2.log")"
fi

fi

log "== 2. $N bodies ($KIND) fp32, 6 contacts a body, drift 0.01, skin auto, $STEPS steps"
timeout 90 "$CG" generate "$W/s.h5" -n "$N" --seed 24 --contacts-per-body 6 --kind "$KIND" -q ||
  failed+=(generate)
# the compared paths, TAG=SETTING: environment variables (NAME=VALUE[,NAME=VALUE…]), or broad=B for
# `--broad-phase B`
# (broad=levels: what auto ran for `--skin auto` before it kept the grid; its builds are not in cell
# order and its reuses select from the (a, b) list)
VARIANTS=${VARIANTS:-"now=- lev=broad=levels fill=CONTACTGRID_STEP_REBUILD=fill"}
run() {  # TAG SKIN STEPS [SETTING]: one drifting run, its log in $OUT/steps_TAG.log, its contacts $W/TAG.h5
  local tag=$1 skin=$2 n=$3 setting=${4:--} envs=() args=()
  case $setting in
    -) ;;
    broad=*) args=(--broad-phase "${setting#broad=}") ;;
    *) IFS=, read -ra envs <<<"$setting" ;;  # NAME=VALUE[,NAME=VALUE…]
  esac
  timeout 120 env CONTACTGRID_STEP_TRACE=1 "${envs[@]}" "$CG" detect "$W/s.h5" -o "$W/$tag.h5" --backend "$BACKEND" \
    --precision fp32 --steps "$n" --drift 0.01 --skin "$skin" "${args[@]}" ${FINAL:+--final-scene "$FINAL"} \
    >"$OUT/steps_$tag.log" 2>&1 || failed+=("steps_$tag")
}
tags=()
for r in $(seq 1 "$ROUNDS"); do
  for v in $VARIANTS; do tags+=("${v%%=*}$r"); done
done
run fresh 0 6
run fresh_grid 0 6 broad=grid  # the grid's fresh detection: auto picks the levels for it (one size class)
rm -f "$W/fresh.h5" "$W/fresh_grid.h5"
for r in $(seq 1 "$ROUNDS"); do
  first=
  for v in $VARIANTS; do
    tag=${v%%=*}$r
    if [ "$r" = 1 ] && [ -z "$first" ]; then
      FINAL="$W/final.h5" run "$tag" auto "$STEPS" "${v#*=}"
      first=$tag
    else
      run "$tag" auto "$STEPS" "${v#*=}"
    fi
  done
  if [ "$r" = 1 ]; then
    log "== 3. the last step's contacts: every path = a plain detect of the final scene"
    timeout 90 "$CG" detect "$W/final.h5" -o "$W/plain.h5" --backend "$BACKEND" --precision fp32 -q ||
      failed+=(plain_detect)
    : >"$OUT/compare.log"
    for v in $VARIANTS; do
      "$CG" compare "$W/${v%%=*}1.h5" "$W/plain.h5" >>"$OUT/compare.log" 2>&1 || failed+=("${v%%=*}_vs_plain")
    done
    cat "$OUT/compare.log"
    rm -f "$W/plain.h5" "$W/final.h5"
  fi
  for v in $VARIANTS; do rm -f "$W/${v%%=*}$r.h5"; done
done
hashes=$(for t in "${tags[@]}"; do grep -ho 'pair hash [0-9a-f]*' "$OUT/steps_$t.log"; done | sort -u | wc -l)
echo "last-step pair hashes over the skin runs: $hashes distinct (1 expected)"
[ "$hashes" = 1 ] || failed+=(pair_hashes)

field() {  # TAG WHAT: a figure of a run's summary in ms
  local f=$OUT/steps_$1.log
  case $2 in
    mean) sed -nE 's/.*mean step ([0-9.e+-]+) s.*/\1/p' "$f" ;;
    detect) sed -nE 's/.*without the frame ([0-9.e+-]+) s.*/\1/p' "$f" ;;
    build) sed -nE 's/.*detection ([0-9.e+-]+) s building.*/\1/p' "$f" ;;
    reuse) sed -nE 's/.*building, ([0-9.e+-]+) s reusing.*/\1/p' "$f" ;;
  esac | head -1 | awk '{ printf "%.2f", $1 * 1000 }'
}
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "-" }'; }
# the median detection of the builds of kept lists alone (the trace's build lines; the summary's
# "building" median also counts step 0, skin auto's fresh skin-0 call)
lists_build() {
  grep -E '^trace .* build:' "$OUT/steps_$1.log" | sed -E 's/.* build: interior ([0-9.e+-]+) .*/\1/' | sort -g |
    awk '{ v[NR] = $1 } END { if (NR) printf "%.2f", 1000 * (NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2) }'
}
lists() { sed -nE 's/.*candidate lists: ([0-9]+) builds, ([0-9]+) reuses, skin ([0-9.e+-]+).*/\1\/\2, skin \3/p' "$OUT/steps_$1.log"; }
{
  fr=$(field fresh build)
  printf '| run | fresh | build | lists built | reuse | mean | mean detection | build/fresh | lists built/fresh | mean/fresh | mean detection/fresh | builds/reuses |\n'
  printf '|---|---|---|---|---|---|---|---|---|---|---|---|\n'
  for t in "${tags[@]}"; do
    printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$fr" "$(field "$t" build)" \
      "$(lists_build "$t")" "$(field "$t" reuse)" "$(field "$t" mean)" "$(field "$t" detect)" \
      "$(ratio "$(field "$t" build)" "$fr")" "$(ratio "$(lists_build "$t")" "$fr")" \
      "$(ratio "$(field "$t" mean)" "$fr")" "$(ratio "$(field "$t" detect)" "$fr")" "$(lists "$t")"
  done
  echo "fresh with the grid (--broad-phase grid): $(field fresh_grid build) ms ($(ratio "$(field fresh_grid build)" "$fr")x auto's)"
  for t in fresh fresh_grid; do
    echo "-- $t: a step's stages (median)"
    sed -nE '/^  interior/,/^  boundary/p' "$OUT/steps_$t.log" | grep -v boundary
  done
  for t in "${tags[@]}"; do
    echo "-- $t: a building step's stages (median), then each build (s)"
    grep -E "building step's stages" "$OUT/steps_$t.log"
    grep -E '^trace .* build:' "$OUT/steps_$t.log" |
      sed -E 's/.* build: interior ([0-9.]+) .* pairs/  detect \1 pairs/; s/ contacts [0-9]+//'
  done
} | tee "$OUT/table.md"

NCU=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
if [ "${PROFILE:-1}" = 1 ] && [ -n "$NCU" ]; then
  log "== 4. kernels of a 12-step run under ncu (durations summed by name; the defaults)"
  for p in now; do
    timeout 120 "$NCU" --clock-control none --metrics gpu__time_duration.sum --launch-count 800 --csv \
      --log-file "$OUT/ncu_$p.csv" "$CG" detect "$W/s.h5" -o "$W/ncu.h5" --backend "$BACKEND" --precision fp32 \
      --steps 12 --drift 0.01 --skin auto >"$OUT/ncu_$p.out" 2>&1 || echo "ncu $p rc=$? (not a failure)"
    rm -f "$W/ncu.h5"
    python3 jobs/ncu_sum.py "$OUT/ncu_$p.csv" 24 | tee "$OUT/ncu_$p.sum.txt"
  done
fi
rm -rf "$W"
log "done"
if [ ${#failed[@]} -gt 0 ]; then echo "FAILED: ${failed[*]}"; exit 1; fi
echo "all checks passed"
