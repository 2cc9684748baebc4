#!/usr/bin/env bash
# Bodies that move (issue #31) on the GPU: the step loop's CUDA tests, the CLI's drifting steps against
# a plain detection of the final scene, and the issue's Performance figures as one compact table.
#   BIN=dir OUT=dir jobs/gpu_steploop_check.sh [quick]
#                                                    one H100 (< 3 min), the default: the CUDA cases of
#                                                    the cell-order build and narrow (each former path
#                                                    under its knob too), the MPI moving steps on CUDA
#                                                    at np 1 and 2, then 2^24 spheres fp32, drift 1 %,
#                                                    skin auto: fresh, after (defaults; its last step
#                                                    = a plain detect of the final scene), before
#                                                    (CONTACTGRID_STEP_BUILD=copy CONTACTGRID_STEP_NARROW=
#                                                    select), each knob alone, and the cell narrow at
#                                                    2 candidates a thread (CONTACTGRID_STEP_NARROW_
#                                                    ITEMS=2; default 4); one table of fresh /
#                                                    build / reuse / mean ms and each run's building
#                                                    step's stages; logs in $OUT/steploop.tgz
#   BIN=dir OUT=dir jobs/gpu_steploop_check.sh one   one H100 (< 3 min): tests, CLI, 2^24 spheres,
#                                                    fp32, 6 contacts per body, drift 1 % of r_max per
#                                                    step, skin auto: the kept candidates in cell order
#                                                    (default) and in (a, b) order of the input indices
#                                                    (CONTACTGRID_STEP_ORDER=file)
#   BIN=dir OUT=dir jobs/gpu_steploop_check.sh migrate
#                                                    a 2-GPU host (< 3 min): the rebuild under mpirun
#                                                    (#31): the splice's CUDA cases, the MPI moving steps
#                                                    at np 2 with engine A's rows spliced in place
#                                                    (default) and set whole (CONTACTGRID_STEP_MIGRATE=
#                                                    whole), then 2^25 spheres, fp32, 6 contacts per body,
#                                                    drift 1 %, skin auto, 16 steps: np 1, np 2 after,
#                                                    np 2 before (the knob); per step migrate / layout /
#                                                    halo / mean, np1/np2, and the last step's pair hash
#                                                    equal in all three runs
#   BIN=dir OUT=dir jobs/gpu_steploop_check.sh two   a 2-GPU host (~4 min): the MPI tests at np 2, then
#                                                    2^26 spheres and 2^24 ellipsoids at np 1 and np 2
#                                                    (one rank per GPU): per-step migration, halo and
#                                                    rebuild, and the np 2 / np 1 speed-up
# BIN holds the CUDA build's contactgrid, contactgrid_tests and contactgrid_mpi_tests. Every check
# runs whatever an earlier one did; the script exits non-zero naming each failed check.
# Columns: fresh = a detection from scratch per step (--skin 0: every step builds), mean = the mean
# step with skin auto (frame + migrate + rebuild + detection, reuses and rebuilds together), build =
# the detection of a step that built its candidate lists, reuse = one that reused them, layout = the
# rebuild's check and layout (ghost set, rows), frame = the moved bodies' bounds and largest
# displacement (every step; engine A's resident_extent: on the device, a few values read back) over
# the ranks, migrate = rebalance + migration, halo = the ghost refresh; all in
# ms, medians over the steps of the maxima over ranks. Targets (#31): mean/fresh <= 0.20, (build +
# layout)/fresh <= 1.0; np 2 / np 1 >= 1.8.
# A dry run of the script itself on a machine without a GPU: BACKEND=cpu SCALE=8 (2^8 times fewer
# bodies; the CUDA test checks then fail, as they must there).
set -u
MODE=${1:-quick}
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; W=${WORK:-/tmp/cgwork}
mkdir -p "$OUT" "$W"
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt  # (its argument: else it takes this script's)
CG="$BIN/contactgrid"
BACKEND=${BACKEND:-cuda}; SCALE=${SCALE:-0}
N24=$((16777216 >> SCALE)); N26=$((67108864 >> SCALE))
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
MPI=(mpirun --bind-to none --allow-run-as-root)
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
failed=()
check() {  # NAME COMMAND…: runs it, records the failure by name
  local name=$1; shift
  if "$@"; then echo "  ok    $name"; else echo "  FAIL  $name"; failed+=("$name"); fi
}
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$OUT/device.txt"
cat "$OUT/device.txt"

# gtest: passed, nothing failed, and no CUDA case skipped (the device has a GPU)
gtest_ok() {  # LOG
  grep -q '^\[  PASSED  \]' "$1" && ! grep -q '^\[  FAILED  \]' "$1" && ! grep -q 'no CUDA device' "$1"
}

# steps SCENE NP SKIN STEPS TAG: one drifting run; its summary in $OUT/TAG.log (FINAL_SCENE=FILE: the
# last step's bodies written there too; KEEP=1: its contact file $W/TAG.h5 kept)
steps() {
  local scene=$1 np=$2 skin=$3 n=$4 tag=$5 final=()
  [ -n "${FINAL_SCENE:-}" ] && final=(--final-scene "$FINAL_SCENE")
  "${MPI[@]}" -np "$np" "$CG" detect "$W/$scene.h5" -o "$W/$tag.h5" --backend "$BACKEND" --precision fp32 \
    --steps "$n" --drift 0.01 --skin "$skin" "${final[@]}" >"$OUT/$tag.log" 2>&1
  local rc=$?
  [ -n "${KEEP:-}" ] || rm -f "$W/$tag.h5"
  return $rc
}
# field TAG WHAT: a figure of a run's summary in ms (WHAT: fresh|mean|build|reuse|layout|migrate|halo|frame)
field() {
  local f=$OUT/$1.log
  case $2 in
    mean) sed -nE 's/.*mean step ([0-9.e+-]+) s.*/\1/p' "$f" ;;
    fresh | build) sed -nE 's/.*detection ([0-9.e+-]+) s building.*/\1/p' "$f" ;;
    reuse) sed -nE 's/.*building, ([0-9.e+-]+) s reusing.*/\1/p' "$f" ;;
    layout) sed -nE 's/^  rebuild +([0-9.e+-]+).*/\1/p' "$f" ;;
    migrate) sed -nE 's/^  migrate +([0-9.e+-]+).*/\1/p' "$f" ;;
    halo) sed -nE 's/^  halo +([0-9.e+-]+).*/\1/p' "$f" ;;
    frame) sed -nE 's/^  frame +([0-9.e+-]+).*/\1/p' "$f" ;;
  esac | head -1 | awk '{ printf "%.3f", $1 * 1000 }'
}
lists() { sed -nE 's/.*candidate lists: ([0-9]+) builds, ([0-9]+) reuses, skin ([0-9.e+-]+).*/\1\/\2 skin \3/p' "$OUT/$1.log"; }
same() { "$CG" compare "$1" "$2" >>"$OUT/compare.log" 2>&1; }  # byte-identical /contacts
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "-" }'; }

table_one() {  # SCENE…: fresh and auto runs at np 1
  printf '| scene | fresh | mean | build | reuse | layout | frame | builds/reuses | mean/fresh | (build+layout)/fresh |\n'
  printf '|---|---|---|---|---|---|---|---|---|---|\n'
  for sc in "$@"; do
    local fr mean build
    fr=$(field "$sc.fresh" fresh); mean=$(field "$sc.auto" mean); build=$(field "$sc.auto" build)
    printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$sc" "$fr" "$mean" "$build" \
      "$(field "$sc.auto" reuse)" "$(field "$sc.auto" layout)" "$(field "$sc.auto" frame)" "$(lists "$sc.auto")" \
      "$(ratio "$mean" "$fr")" \
      "$(ratio "$(awk -v a="$build" -v b="$(field "$sc.auto" layout)" 'BEGIN { print a + b }')" "$fr")"
  done
}

case $MODE in
  quick)
    Q=$W/quick; mkdir -p "$Q"
    log "CUDA cases: skin (both orders, the in-place build, the cell narrow), narrow, backend, broad phases"
    timeout 150 "$BIN/contactgrid_tests" --gtest_color=no \
      --gtest_filter='EngineSkin*:KeptRoom*:CudaNarrowTest*:CudaBackendTest*:BroadPhase*:*Resident*' \
      >"$Q/tests.log" 2>&1
    check "contactgrid_tests (skin, narrow, backend, broad phases)" gtest_ok "$Q/tests.log"
    grep -E '^\[  (PASSED|FAILED) ' "$Q/tests.log"
    # the former paths, each under its knob (the walk's input indices mapped after it, CUB's select), and
    # the cell narrow at 2 candidates a thread
    for knob in CONTACTGRID_STEP_BUILD=copy CONTACTGRID_STEP_NARROW=select CONTACTGRID_STEP_NARROW_ITEMS=2; do
      timeout 60 env "$knob" "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter='EngineSkinCuda*:EngineSkinTest/cuda*' \
        >"$Q/tests.$knob.log" 2>&1
      check "contactgrid_tests (CUDA skin cases), $knob" gtest_ok "$Q/tests.$knob.log"
    done
    for np in 1 2; do
      timeout 90 "${MPI[@]}" -np $np "$BIN/contactgrid_mpi_tests" --gtest_color=no \
        --gtest_filter='MovingSteps.Cuda*:StepLoop.*' >"$Q/mpi_tests.np$np.log" 2>&1
      check "contactgrid_mpi_tests MovingSteps.Cuda*, StepLoop np $np" gtest_ok "$Q/mpi_tests.np$np.log"
    done

    log "bench: 2^24 spheres, fp32, 6 contacts per body, drift 0.01 (1 % of r_max) per step, skin auto, 40 steps"
    timeout 90 "$CG" generate "$W/s24.h5" -n $N24 --seed 24 --contacts-per-body 6 -q
    check "bench s24 fresh" steps s24 1 0 6 s24.fresh
    FINAL_SCENE="$W/s24.final.h5" KEEP=1 check "bench s24 after (defaults)" steps s24 1 auto 40 s24.after
    timeout 60 "$CG" detect "$W/s24.final.h5" -o "$W/s24.plain.h5" --backend "$BACKEND" --precision fp32 -q
    check "s24 after: last step = plain detect of the final scene" same "$W/s24.after.h5" "$W/s24.plain.h5"
    rm -f "$W/s24.after.h5" "$W/s24.plain.h5" "$W/s24.final.h5"
    CONTACTGRID_STEP_BUILD=copy CONTACTGRID_STEP_NARROW=select check "bench s24 before (both knobs)" \
      steps s24 1 auto 40 s24.before
    CONTACTGRID_STEP_BUILD=copy check "bench s24 build copy alone" steps s24 1 auto 40 s24.build_copy
    CONTACTGRID_STEP_NARROW=select check "bench s24 narrow select alone" steps s24 1 auto 40 s24.narrow_select
    CONTACTGRID_STEP_NARROW_ITEMS=2 check "bench s24 cell narrow, 2 candidates a thread" \
      steps s24 1 auto 40 s24.items2
    check "s24: every run's last step has the same contacts" \
      bash -c "grep -h 'contacts on the last step' '$OUT'/s24.{after,before,build_copy,narrow_select,items2}.log | sed -E 's/.*, ([0-9]+) contacts on the last step.*/\1/' | uniq | wc -l | grep -qx 1"
    {
      printf '| run (2^24 spheres) | fresh | build | reuse | mean | mean/fresh | build/fresh | builds/reuses, skin |\n'
      printf '|---|---|---|---|---|---|---|---|\n'
      fr=$(field s24.fresh fresh)
      for t in after before build_copy narrow_select items2; do
        printf '| %s | %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$fr" "$(field s24.$t build)" \
          "$(field s24.$t reuse)" "$(field s24.$t mean)" "$(ratio "$(field s24.$t mean)" "$fr")" \
          "$(ratio "$(field s24.$t build)" "$fr")" "$(lists s24.$t)"
      done
      for t in fresh after before build_copy narrow_select items2; do
        echo "-- $t: a reusing step's stages (median), then a building step's"
        sed -nE '/^  interior/,/^  boundary/p' "$OUT/s24.$t.log" | grep -v boundary
        grep -E "building step's stages" "$OUT/s24.$t.log"
      done
    } | tee "$OUT/table.md"
    cat "$OUT/device.txt" "$OUT/table.md" >"$Q/summary.txt"
    cp "$OUT"/*.log "$Q/" 2>/dev/null
    tar czf "$OUT/steploop.tgz" -C "$W" quick && rm -f "$OUT"/*.log
    rm -rf "$Q" "$W/s24.h5"
    ;;
  one)
    log "CUDA tests of the step loop (skin, tuner, resident engines, narrow paths; MPI moving steps np 1, 2)"
    "$BIN/contactgrid_tests" --gtest_color=no \
      --gtest_filter='*Skin*:*Resident*:*Tuner*:StepBodies.*:StepPlan*:CudaNarrowTest*:EngineTest*:BroadPhaseTest*' \
      >"$OUT/tests.log" 2>&1
    check "contactgrid_tests (skin, resident, narrow, order)" gtest_ok "$OUT/tests.log"
    # the rejecting narrow's count → scan → fill path (CONTACTGRID_CUDA_NARROW=two-pass) against the same tests
    CONTACTGRID_CUDA_NARROW=two-pass "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter='*Skin*:*Resident*' \
      >"$OUT/tests.two_pass.log" 2>&1
    check "contactgrid_tests (skin, resident), two-pass narrow" gtest_ok "$OUT/tests.two_pass.log"
    # the kept candidates' two orders: (a, b) of the input indices, and the cell order of bodies
    # renumbered even where they fit in L2 (a cell order that is not the input order)
    CONTACTGRID_STEP_ORDER=file "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter='*Skin*:*Resident*' \
      >"$OUT/tests.file_order.log" 2>&1
    check "contactgrid_tests (skin, resident), CONTACTGRID_STEP_ORDER=file" gtest_ok "$OUT/tests.file_order.log"
    CONTACTGRID_CUDA_RENUMBER=1 "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter='*Skin*:*Resident*' \
      >"$OUT/tests.renumber.log" 2>&1
    check "contactgrid_tests (skin, resident), CONTACTGRID_CUDA_RENUMBER=1" gtest_ok "$OUT/tests.renumber.log"
    CONTACTGRID_CUDA_RENUMBER=1 "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no \
      --gtest_filter='MovingSteps.*:StepLoop.*' >"$OUT/mpi_tests.renumber.np2.log" 2>&1
    check "contactgrid_mpi_tests MovingSteps np 2, CONTACTGRID_CUDA_RENUMBER=1" gtest_ok "$OUT/mpi_tests.renumber.np2.log"
    for np in 1 2; do
      "${MPI[@]}" -np $np "$BIN/contactgrid_mpi_tests" --gtest_color=no --gtest_filter='MovingSteps.*:StepLoop.*' \
        >"$OUT/mpi_tests.np$np.log" 2>&1
      check "contactgrid_mpi_tests MovingSteps np $np" gtest_ok "$OUT/mpi_tests.np$np.log"
    done

    log "CLI: drifting steps on cuda, skin auto, -o = plain detect of --final-scene (cuda and cpu), np 1 and 2"
    "$CG" generate "$W/u.h5" -n $((200000 >> SCALE)) --seed 21 --contacts-per-body 6 -q
    "$CG" generate "$W/m.h5" -n $((100000 >> SCALE)) --seed 22 --kind mixed --ellipsoid-fraction 0.4 --rlow 0.3 --rhigh 0.6 \
      --contacts-per-body 1 -q
    for sc in u m; do
      for np in 1 2; do
        t=$sc.np$np.auto
        spin=(); [ $sc = m ] && spin=(--spin 0.2)
        prec=fp64; [ $sc = u ] && prec=fp32  # fp32 spheres: the one-pass narrow of the steps
        "${MPI[@]}" -np $np "$CG" detect "$W/$sc.h5" -o "$W/$t.last.h5" --backend "$BACKEND" --precision $prec \
          --steps 12 --drift 0.01 --skin auto "${spin[@]}" --final-scene "$W/$t.final.h5" >"$OUT/cli.$t.log" 2>&1
        "$CG" detect "$W/$t.final.h5" -o "$W/$t.plain.h5" --backend "$BACKEND" --precision $prec -q
        check "cli $t: last step = $BACKEND detect of the final scene" same "$W/$t.last.h5" "$W/$t.plain.h5"
        "$CG" detect "$W/$t.final.h5" -o "$W/$t.cpu.h5" --backend cpu --precision $prec -q
        check "cli $t: last step = cpu detect of the final scene" same "$W/$t.last.h5" "$W/$t.cpu.h5"
      done
    done

    log "bench: 2^24 spheres, fp32, 6 contacts per body, drift 0.01 (1 % of r_max) per step"
    "$CG" generate "$W/s24.h5" -n $N24 --seed 24 --contacts-per-body 6 -q
    check "bench s24 fresh" steps s24 1 0 6 s24.fresh
    # the cell order (default), its last step against a plain detection of the final scene
    FINAL_SCENE="$W/s24.final.h5" KEEP=1 check "bench s24 auto" steps s24 1 auto 40 s24.auto
    "$CG" detect "$W/s24.final.h5" -o "$W/s24.plain.h5" --backend "$BACKEND" --precision fp32 -q
    check "s24 auto (cell order): last step = plain detect of the final scene" same "$W/s24.auto.h5" "$W/s24.plain.h5"
    rm -f "$W/s24.auto.h5" "$W/s24.plain.h5" "$W/s24.final.h5"
    # the (a, b) path: the kept candidates in (a, b) order of the input indices
    CONTACTGRID_STEP_ORDER=file check "bench s24 auto, file order" steps s24 1 auto 40 s24.auto_file
    check "s24: cell order = file order (contacts on the last step)" \
      bash -c "grep -h 'contacts on the last step' '$OUT/s24.auto.log' '$OUT/s24.auto_file.log' | sed -E 's/.*, ([0-9]+) contacts on the last step.*/\1/' | uniq | wc -l | grep -qx 1"
    table_one s24 | tee "$OUT/table.md"
    printf 'file order (CONTACTGRID_STEP_ORDER=file): mean %s, build %s, reuse %s ms, %s, mean/fresh %s\n' \
      "$(field s24.auto_file mean)" "$(field s24.auto_file build)" "$(field s24.auto_file reuse)" \
      "$(lists s24.auto_file)" "$(ratio "$(field s24.auto_file mean)" "$(field s24.fresh fresh)")" | tee -a "$OUT/table.md"
    printf 'cell order (default):                    mean %s, build %s, reuse %s ms, %s, mean/fresh %s\n' \
      "$(field s24.auto mean)" "$(field s24.auto build)" "$(field s24.auto reuse)" \
      "$(lists s24.auto)" "$(ratio "$(field s24.auto mean)" "$(field s24.fresh fresh)")" | tee -a "$OUT/table.md"
    for t in s24.fresh s24.auto s24.auto_file; do
      echo "-- $t: per-step stages (ms, median of the steps)"
      sed -nE '/^resident steps/,/^  candidate lists/p' "$OUT/$t.log"
    done
    ;;
  migrate)
    log "CUDA cases of the splice; MPI moving steps at np 2 (one rank per GPU), spliced and whole"
    timeout 60 "$BIN/contactgrid_tests" --gtest_color=no --gtest_filter='EngineResidentSplice*:StepBodies.*' \
      >"$OUT/tests.splice.log" 2>&1
    check "contactgrid_tests EngineResidentSplice* (both backends), StepBodies" gtest_ok "$OUT/tests.splice.log"
    grep -E '^\[  (PASSED|FAILED) ' "$OUT/tests.splice.log"
    for knob in CONTACTGRID_STEP_MIGRATE=splice CONTACTGRID_STEP_MIGRATE=whole; do
      timeout 90 env "$knob" "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no \
        --gtest_filter='MovingSteps.*:StepLoop.*' >"$OUT/mpi_tests.np2.$knob.log" 2>&1
      check "contactgrid_mpi_tests MovingSteps np 2, $knob" gtest_ok "$OUT/mpi_tests.np2.$knob.log"
    done

    log "bench: 2^25 spheres, fp32, 6 contacts per body, drift 0.01, skin auto, 16 steps: np 1, np 2 after, np 2 before"
    N25=$((33554432 >> SCALE))
    timeout 60 "$CG" generate "$W/s25.h5" -n $N25 --seed 25 --contacts-per-body 6 -q
    check "bench s25 np 1" steps s25 1 auto 16 s25.np1
    check "bench s25 np 2 after (spliced)" steps s25 2 auto 16 s25.np2
    CONTACTGRID_STEP_MIGRATE=whole check "bench s25 np 2 before (CONTACTGRID_STEP_MIGRATE=whole)" steps s25 2 auto 16 s25.np2_whole
    rm -f "$W/s25.h5"
    lasthash() { sed -nE 's/.*, ([0-9]+) contacts on the last step \(the output; pair hash ([0-9a-f]+)\).*/\1 \2/p' "$OUT/$1.log"; }
    h1=$(lasthash s25.np1); h2=$(lasthash s25.np2); h3=$(lasthash s25.np2_whole)
    check "s25: np 1, np 2 and np 2 whole have the same last step (contacts, pair hash)" \
      bash -c "[ -n '$h1' ] && [ '$h1' = '$h2' ] && [ '$h1' = '$h3' ]"
    {
      printf '| run (2^25 spheres) | mean | build | reuse | layout | migrate | halo | frame | builds/reuses | np1/np2 (mean) | last step |\n'
      printf '|---|---|---|---|---|---|---|---|---|---|---|\n'
      for t in np1 np2 np2_whole; do
        sp=; [ $t != np1 ] && sp=$(ratio "$(field s25.np1 mean)" "$(field s25.$t mean)")
        printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' $t "$(field s25.$t mean)" \
          "$(field s25.$t build)" "$(field s25.$t reuse)" "$(field s25.$t layout)" "$(field s25.$t migrate)" \
          "$(field s25.$t halo)" "$(field s25.$t frame)" "$(lists s25.$t)" "$sp" "$(lasthash s25.$t)"
      done
      for t in np1 np2 np2_whole; do
        echo "-- $t"
        sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/s25.$t.log"
      done
    } | tee "$OUT/table.md"
    (cd "$OUT" && tar czf migrate.tgz ./*.log && rm -f ./*.log)
    ;;
  two)
    log "MPI moving steps at np 2 (one rank per GPU)"
    "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no --gtest_filter='MovingSteps.*:StepLoop.*' \
      >"$OUT/mpi_tests.np2.log" 2>&1
    check "contactgrid_mpi_tests MovingSteps np 2" gtest_ok "$OUT/mpi_tests.np2.log"

    log "bench: 2^26 spheres and 2^24 ellipsoids, fp32, 6 contacts per body, drift 0.01, skin auto, np 1 and 2"
    "$CG" generate "$W/s26.h5" -n $N26 --seed 26 --contacts-per-body 6 -q
    "$CG" generate "$W/e24.h5" -n $N24 --seed 25 --kind ellipsoids --max-aspect 4 --contacts-per-body 6 -q
    for sc in s26 e24; do
      for np in 1 2; do check "bench $sc np $np" steps $sc $np auto 24 $sc.np$np; done
    done
    {
      printf '| scene | np | mean | build | reuse | layout | migrate | halo | builds/reuses | np1/np2 (mean) |\n'
      printf '|---|---|---|---|---|---|---|---|---|---|\n'
      for sc in s26 e24; do
        for np in 1 2; do
          t=$sc.np$np
          sp=; [ $np = 2 ] && sp=$(ratio "$(field $sc.np1 mean)" "$(field $t mean)")
          printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' $sc $np "$(field $t mean)" \
            "$(field $t build)" "$(field $t reuse)" "$(field $t layout)" "$(field $t migrate)" \
            "$(field $t halo)" "$(lists $t)" "$sp"
        done
      done
    } | tee "$OUT/table.md"
    ;;
  *) echo "usage: BIN=dir OUT=dir $0 quick|one|migrate|two"; exit 2 ;;
esac

log "done"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED: %s\n' "${failed[@]}"
  exit 1
fi
echo "all checks passed"
