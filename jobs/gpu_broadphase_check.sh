#!/usr/bin/env bash
# The broad phases (issue #34) on one GPU, one mode a call (each under 4 minutes on an H100):
#   check    the unit tests of the broad phases with their CUDA cases (none may skip, none may fail:
#            LevelsCpuCuda, OrderCpuCuda, the resident bodies' levels, the levels' pair tests linear
#            in N); CPU = CUDA byte for byte, every scene family at 2^13 (grid, levels, sweep, brute;
#            fp32 and fp64) and mpirun np 2 with CUDA (intruders, log-uniform)
#   compare  CPU = CUDA byte for byte at 2^18: every family, grid, levels and sweep in fp32, levels in
#            fp64 (the CUDA runs four at a time on the one GPU)
#   table    the H100 table (bench-broad, fp32): every family at 2^18, 2^20, 2^22 and 2^24, grid,
#            levels, sweep and auto; a run predicted above 6 s (warm-up and 3 repetitions) is skipped,
#            shown as >t; the /uniform per-contact column and auto's pick against the best (the last
#            line: on how many rows auto is within 10 % of the best)
#   small    the same at 2^13 … 2^16 with brute
#   steps    (under 3 minutes) the unit cases of every broad phase's pair estimate on CUDA; the
#            resident steps' halo by radius with CUDA: the MPI tests of mixed
#            sizes crossing the cuts at np 1 and 2 (every step = the CPU's one-rank detection from
#            scratch), `detect --steps --drift` on 64 intruders among grains, CUDA np 2 = CPU np 1 byte
#            for byte; then the uniform and bimodal rows at 2^22 and 2^24 (grid, levels, auto: auto's
#            one-level pick on the device, the levels' fill pass), and the per-kernel durations (ncu)
#            of one levels detection of bimodal 1:10 and of uniform at 2^22 (where the levels' time goes)
#   cells    (under 3 minutes) the levels' cells sized by the grid's cost model against the former
#            smallest edges (CONTACTGRID_LEVELS_CELLS=smallest): the unit cases of BroadPhase*, Levels*,
#            AutoBroadPhase*, PairEstimate* with CUDA (none may skip); bimodal 1:10 and log-uniform
#            1:1000 at 2^20, the CPU's levels, CUDA levels (both cell rules), CUDA grid and mpirun np 2
#            CUDA levels = the CPU's grid byte for byte; then the 2^24 rows, fp32, with every run's stage times: before
#            (smallest cells) uniform, bimodal 1:10 and 1:100 with levels; after (tuned) those and
#            log-uniform 1:1000 and 64 intruders (§24's other targets) with levels, auto and auto's pick
#   BIN=dir OUT=results-dir jobs/gpu_broadphase_check.sh check|compare|table|small|steps|cells   (default: check)
# BIN holds the CUDA build's contactgrid, contactgrid_tests and (steps) contactgrid_mpi_tests. Everything lands in
# $OUT/broadphase_<mode>.tgz (logs, compare table, the tables as text and CSV); the summary is printed.
# Exits non-zero naming every failed check (the last lines of the output).
set -u
cd "$(dirname "$0")/.." || exit 2
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
MODE=${1:-check}
BIN=${BIN:-.devbin}; OUT=${OUT:-/tmp/out}
mkdir -p "$OUT"; W=${WORK:-/tmp/cgbroad}; R="$W/results"; rm -rf "$R"; mkdir -p "$R"
CG="$BIN/contactgrid"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
failed=()
fail() { failed+=("$1"); echo "FAILED: $1"; }
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
pack() { tar czf "$OUT/broadphase_$MODE.tgz" -C "$W" results; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$R/device.txt"
cat "$R/device.txt"

# name  generate-arguments
families=(
  "uniform|--kind uniform"
  "bimodal10|--kind bimodal --rhigh 1 --ratio 10 --large-fraction 0.1"
  "bimodal100|--kind bimodal --rhigh 1 --ratio 100 --large-fraction 0.1"
  "loguniform1000|--kind polydisperse --rhigh 1 --ratio 1000"
  "intruders64|--kind intruders --rhigh 100 --ratio 100 --intruders 64"
  "intruder1|--kind intruders --rhigh 1 --ratio 100 --intruders 1"
  "mixed|--kind mixed --max-aspect 4"
)

# compare LG "fp32:grid fp32:levels ..." PARALLEL: each family's scene and CPU references (auto) made
# in parallel, then its CUDA runs (PARALLEL families at a time on the GPU), each compared byte for byte
compare() {
  local lg=$1 runs=$2 parallel=$3
  for entry in "${families[@]}"; do
    name=${entry%%|*}; args=${entry#*|}
    (
      scene="$W/$name.$lg.h5"
      # shellcheck disable=SC2086
      "$CG" generate "$scene" -n $((1 << lg)) --seed 34 $args -q >"$W/$name.$lg.gen.log" 2>&1 || exit 1
      for prec in fp32 fp64; do
        "$CG" detect "$scene" -o "$W/$name.$lg.cpu.$prec.h5" --backend cpu --threads 2 --precision $prec -q \
          >"$W/$name.$lg.cpu.$prec.log" 2>&1
      done
    ) &
  done
  wait
  local running=0
  for entry in "${families[@]}"; do
    name=${entry%%|*}
    (
      scene="$W/$name.$lg.h5"
      res="$W/$name.$lg.compare.txt"; : >"$res"
      [ -f "$scene" ] || { echo "FAIL generate $name 2^$lg" >>"$res"; exit 0; }
      for run in $runs; do
        prec=${run%%:*}; bp=${run#*:}
        ref="$W/$name.$lg.cpu.$prec.h5"; got="$W/$name.$lg.cuda.$bp.$prec.h5"
        [ -f "$ref" ] || { echo "FAIL detect cpu $name 2^$lg $prec" >>"$res"; continue; }
        if ! "$CG" detect "$scene" -o "$got" --backend cuda --precision "$prec" --broad-phase "$bp" -q \
          >"$W/$name.$lg.$bp.$prec.log" 2>&1; then
          echo "FAIL detect cuda $name 2^$lg $prec $bp" >>"$res"; continue
        fi
        if "$CG" compare "$ref" "$got" >>"$W/$name.$lg.$bp.$prec.log" 2>&1; then r=IDENTICAL; else r=DIFFERENT; fi
        printf '%-15s 2^%-3s %-5s %-7s %s\n' "$name" "$lg" "$prec" "$bp" "$r" >>"$res"
        rm -f "$got"
      done
    ) &
    running=$((running + 1))
    if [ "$running" -ge "$parallel" ]; then wait -n; running=$((running - 1)); fi
  done
  wait
  for entry in "${families[@]}"; do
    name=${entry%%|*}; res="$W/$name.$lg.compare.txt"
    [ -f "$res" ] || { fail "no comparison of $name 2^$lg"; continue; }
    grep -v '^FAIL' "$res" >>"$R/compare.txt"
    while read -r line; do fail "${line#FAIL }"; done < <(grep '^FAIL' "$res")
    while read -r line; do fail "cpu/cuda $line"; done < <(grep DIFFERENT "$res")
    cat "$W/$name.$lg".*.log >>"$R/compare.log" 2>/dev/null
  done
}

case $MODE in
  check)
    log "1. unit tests of the broad phases (CUDA cases must run, not skip)"
    timeout 150 "$BIN/contactgrid_tests" \
      --gtest_filter='BroadPhaseTest/cuda.*:LevelsCpuCuda.*:OrderCpuCuda.*:LevelsDeviceFlow.*:LevelsPlan.*:SweepKeys.*:BoxRadius.*:AutoBroadPhase.*' \
      >"$R/tests.log" 2>&1 || fail "unit tests (tests.log)"
    grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]|Failure|Expected|Which is|actual' "$R/tests.log" | head -40
    grep -q 'BroadPhaseTest/cuda' "$R/tests.log" || fail "no CUDA case of BroadPhaseTest ran"
    grep -E '^\[  SKIPPED \] (BroadPhaseTest/cuda|LevelsCpuCuda|OrderCpuCuda)' "$R/tests.log" &&
      fail "CUDA cases skipped (no GPU seen?)"
    pack
    log "2. CPU = CUDA byte for byte, every scene family at 2^13, every broad phase, fp32 and fp64"
    compare 13 "fp32:grid fp32:levels fp32:sweep fp32:brute fp64:grid fp64:levels fp64:sweep fp64:brute" 4
    for name in intruders64 loguniform1000; do
      got="$W/$name.np2.h5"
      if mpirun --bind-to none -np 2 "$CG" detect "$W/$name.13.h5" -o "$got" --backend cuda --precision fp64 -q \
        >>"$R/compare.log" 2>&1 && "$CG" compare "$W/$name.13.cpu.fp64.h5" "$got" >>"$R/compare.log" 2>&1; then
        echo "np2 cuda $name 2^13: IDENTICAL" | tee -a "$R/compare.txt"
      else
        fail "np2 cuda $name 2^13 against the CPU's np1"
      fi
    done
    echo "$(grep -c IDENTICAL "$R/compare.txt") identical, $(grep -c DIFFERENT "$R/compare.txt") different"
    ;;
  compare)
    log "CPU = CUDA byte for byte, every scene family at 2^18: grid, levels, sweep fp32; levels fp64"
    compare 18 "fp32:grid fp32:levels fp32:sweep fp64:levels" 4
    echo "$(grep -c IDENTICAL "$R/compare.txt") identical, $(grep -c DIFFERENT "$R/compare.txt") different"
    ;;
  table | small)
    if [ "$MODE" = table ]; then
      range=(--lo 18 --hi 24 --step 2 --brute-hi 0 --sweep-hi 24); limit=200
    else
      range=(--lo 13 --hi 16 --step 1 --brute-hi 16 --sweep-hi 16); limit=100
    fi
    log "the H100 table, fp32 (${range[*]})"
    timeout $limit "$CG" bench-broad --backend cuda --precision fp32 "${range[@]}" --repetitions 3 \
      --limit 6 --budget 10 --csv "$R/broad_h100_$MODE.csv" >"$R/broad_h100_$MODE.txt" 2>&1 ||
      fail "bench-broad $MODE (broad_h100_$MODE.txt)"
    cat "$R/broad_h100_$MODE.txt"
    ;;
  steps)
    log "0. unit tests: every broad phase's pair estimate and refusal on CUDA (levels, sweep too), auto's rule"
    timeout 120 "$BIN/contactgrid_tests" --gtest_color=no \
      --gtest_filter='PairEstimateTest/cuda.*:PairEstimate.*:AutoBroadPhase.*:StepPlan.*:LevelsCpuCuda.*' \
      >"$R/tests_steps.log" 2>&1 || fail "unit tests (tests_steps.log)"
    grep -E '^\[  (PASSED|FAILED|SKIPPED) |Failure' "$R/tests_steps.log" | head -20
    grep -q '^\[  SKIPPED \] PairEstimateTest/cuda' "$R/tests_steps.log" && fail "CUDA estimate cases skipped"
    log "1. MPI tests: mixed sizes crossing the cuts, CUDA steps = the CPU from scratch (np 1, 2)"
    for np in 1 2; do
      timeout 120 mpirun --bind-to none -np $np "$BIN/contactgrid_mpi_tests" --gtest_color=no \
        --gtest_filter='MovingSteps.CudaMixedSizes*:MovingSteps.MixedSizes*:StepLoop.HaloByRadius*' \
        >"$R/mpi_steps.np$np.log" 2>&1 || fail "mpi tests np $np (mpi_steps.np$np.log)"
      grep -E '^\[  (PASSED|FAILED|SKIPPED) |Failure' "$R/mpi_steps.np$np.log" | sort | uniq -c | head -12
      grep -q '^\[  SKIPPED \] MovingSteps.CudaMixedSizes' "$R/mpi_steps.np$np.log" &&
        fail "np $np: the CUDA case skipped (no GPU seen?)"
    done
    log "2. detect --steps --drift, 64 intruders r = 3 among r = 0.3 grains (2^18): CUDA np 2 = CPU np 1"
    scene="$W/intruders.h5"
    "$CG" generate "$scene" -n $((1 << 18)) --seed 35 --kind intruders --rlow 0.3 --rhigh 3 --intruders 64 \
      --contacts-per-body 1 -q >"$R/steps_cli.log" 2>&1 || fail "generate the intruder scene"
    opts=(--precision fp64 --fields full --steps 6 --drift 0.05 --skin 0.2)
    "$CG" detect "$scene" -o "$W/steps.cpu.h5" --backend cpu "${opts[@]}" >>"$R/steps_cli.log" 2>&1 ||
      fail "detect --steps cpu np 1 (steps_cli.log)"
    timeout 120 mpirun --bind-to none -np 2 "$CG" detect "$scene" -o "$W/steps.cuda.h5" --backend cuda \
      "${opts[@]}" >>"$R/steps_cli.log" 2>&1 || fail "detect --steps cuda np 2 (steps_cli.log)"
    if "$CG" compare "$W/steps.cpu.h5" "$W/steps.cuda.h5" >>"$R/steps_cli.log" 2>&1; then
      echo "steps, intruders 2^18, CUDA np 2 against CPU np 1: IDENTICAL"
    else
      fail "steps, intruders 2^18: CUDA np 2 differs from CPU np 1"
    fi
    grep -iE 'halo|ghost|steps' "$R/steps_cli.log" | head -12
    log "3. the uniform and bimodal rows at 2^22 and 2^24 (fp32; grid, levels, auto)"
    timeout 100 "$CG" bench-broad --backend cuda --precision fp32 --families uniform,bimodal10,bimodal100 \
      --lo 22 --hi 24 --step 2 --brute-hi 0 --sweep-hi 0 --repetitions 3 --limit 6 --budget 10 \
      --csv "$R/broad_h100_steps.csv" >"$R/broad_h100_steps.txt" 2>&1 || fail "bench-broad (broad_h100_steps.txt)"
    cat "$R/broad_h100_steps.txt"
    log "4. where the levels' time goes: per-kernel durations (ncu) of one detect, bimodal 1:10 and uniform, 2^22"
    NCU=$(command -v ncu || ls /opt/nvidia/nsight-compute/*/ncu 2>/dev/null | head -1)
    for fam in "bimodal10|--kind bimodal --rhigh 1 --ratio 10 --large-fraction 0.1" "uniform|--kind uniform"; do
      name=${fam%%|*}; args=${fam#*|}
      # shellcheck disable=SC2086
      "$CG" generate "$W/$name.22.h5" -n $((1 << 22)) --seed 34 $args -q || { fail "generate $name 2^22"; continue; }
      [ -n "$NCU" ] || { echo "no ncu: step 4 skipped"; break; }
      timeout 60 "$NCU" --clock-control none --metrics gpu__time_duration.sum --csv --log-file "$R/ncu_$name.csv" \
        "$CG" detect "$W/$name.22.h5" -o "$W/$name.22.out.h5" --backend cuda --precision fp32 --broad-phase levels \
        -v >"$R/ncu_$name.out" 2>&1 || echo "ncu $name rc=$?"
      echo "== $name 2^22, levels: ms per kernel"
      python3 jobs/ncu_sum.py "$R/ncu_$name.csv" 16 | tee "$R/ncu_$name.sum.txt"
    done
    ;;
  cells)
    log "0. unit tests with their CUDA cases: BroadPhase*, Levels*, AutoBroadPhase*, PairEstimate*"
    timeout 150 "$BIN/contactgrid_tests" --gtest_color=no \
      --gtest_filter='BroadPhase*:Levels*:AutoBroadPhase*:PairEstimate*' >"$R/tests_cells.log" 2>&1 ||
      fail "unit tests (tests_cells.log)"
    grep -E '^\[  (PASSED|FAILED|SKIPPED) |Failure' "$R/tests_cells.log" | head -20
    grep -E '^\[  SKIPPED \] (BroadPhaseTest/cuda|LevelsCpuCuda|PairEstimateTest/cuda)' "$R/tests_cells.log" &&
      fail "CUDA cases skipped (no GPU seen?)"
    log "1. byte identity at 2^20: CUDA levels (tuned and smallest cells), grid, np 2 = the CPU"
    for fam in "bimodal10|--kind bimodal --rhigh 1 --ratio 10 --large-fraction 0.1" \
      "loguniform1000|--kind polydisperse --rhigh 1 --ratio 1000"; do
      name=${fam%%|*}; args=${fam#*|}; scene="$W/$name.20.h5"; ref="$W/$name.20.cpu.h5"
      # shellcheck disable=SC2086
      "$CG" generate "$scene" -n $((1 << 20)) --seed 34 $args -q >>"$R/cells_identity.log" 2>&1 ||
        { fail "generate $name 2^20"; continue; }
      "$CG" detect "$scene" -o "$ref" --backend cpu --precision fp32 --broad-phase grid -q \
        >>"$R/cells_identity.log" 2>&1 || { fail "detect cpu $name"; continue; }
      for run in "tuned cpu levels 1" "tuned cuda levels 1" "smallest cuda levels 1" "tuned cuda grid 1" \
        "tuned cuda levels 2"; do
        read -r cells be bp np <<<"$run"; got="$W/$name.20.$cells.$be.$bp.np$np.h5"
        if CONTACTGRID_LEVELS_CELLS=$cells timeout 60 mpirun --bind-to none -np "$np" "$CG" detect "$scene" \
          -o "$got" --backend "$be" --precision fp32 --broad-phase "$bp" -q >>"$R/cells_identity.log" 2>&1 &&
          "$CG" compare "$ref" "$got" >>"$R/cells_identity.log" 2>&1; then
          echo "$name 2^20 $be $bp cells=$cells np $np: IDENTICAL to the CPU grid" | tee -a "$R/compare.txt"
        else
          fail "$name 2^20 $be $bp cells=$cells np $np differs from the CPU grid (cells_identity.log)"
        fi
        rm -f "$got"
      done
    done
    log "2. the 2^24 rows, fp32: before (CONTACTGRID_LEVELS_CELLS=smallest) and after (tuned)"
    bench() {  # label cells families phases
      CONTACTGRID_LEVELS_CELLS=$2 timeout 100 "$CG" bench-broad --backend cuda --precision fp32 --families "$3" \
        --broad-phases "$4" --lo 24 --hi 24 --repetitions 3 --stage-times --csv "$R/cells_$1.csv" \
        >"$R/cells_$1.txt" 2>&1 || fail "bench-broad $1 (cells_$1.txt)"
      echo "== $1 (levels cells: $2)"; cat "$R/cells_$1.txt"
    }
    bench before smallest uniform,bimodal10,bimodal100 levels
    bench after tuned uniform,bimodal10,bimodal100,loguniform1000,intruders64 levels,auto
    echo "targets (time per contact against uniform, /unif/c): bimodal 1:10 and 1:100 <= 1.5, log-uniform <= 1.5,"
    echo "intruders64 <= 2; the grid runs where auto picks it (bimodal 1:100 and intruders64 take 6.5 s and"
    echo "more than 18 s a call with the grid at 2^24: §22, §24)"
    ;;
  *)
    echo "usage: BIN=dir OUT=dir $0 check|compare|table|small|steps|cells" >&2
    exit 2
    ;;
esac
pack
log "done ($MODE)"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED CHECK: %s\n' "${failed[@]}"
  exit 1
fi
echo "ALL BROAD-PHASE CHECKS PASSED ($MODE)"
