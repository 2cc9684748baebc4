#!/usr/bin/env bash
# Bodies that move under mpirun (#31), a 2-GPU host (one rank per GPU; ~5 min): the halo and the slab
# scans where the rows are, against the former host paths in the same call.
#   BIN=dir OUT=dir jobs/gpu_ranks_check.sh
# 1. CUDA unit cases (one GPU): EngineRowListsTest/cuda.* (row lists: device gather into the engine's
#    page-locked buffer, scatter, device-to-device copy, rows_outside = a host filter, bit for bit),
#    EngineResidentSplice*, StepPlan.* (make_step_plan_of = make_step_plan), StepBodies.*.
# 2. MPI moving steps at np 2 (CUDA and CPU cases; each step = a one-rank detection from scratch), with
#    the defaults and with the former paths (CONTACTGRID_STEP_HALO=host CONTACTGRID_STEP_SCAN=host
#    CONTACTGRID_STEP_MERGE=wait);
#    MovingSteps.CudaTheHaloAndScansWhereTheRowsAreGiveTheFormerPathsBits compares both in one run.
# 3. Bench, 2^25 spheres (then 2^26 np 1 and np 2 when under BUDGET26=330 s have passed; SKIP26=1
#    skips it), fp32, 6 contacts per body, drift 0.01 (1 % of r_max) per step, skin auto, 16 steps:
#    np 1; np 2 (defaults); np 2 former (the three knobs: the previous main's paths); np 2 with the
#    former halo alone. One table: mean / build / reuse / layout /
#    migrate / merge wait (the wait for the host rows' merge that runs beside the layout and the
#    detection, where it was joined outside the timed stages; in the mean) / halo (and its parts: pack
#    = device gather + download + B's boundary rows copied, mpi = the exchange, including the wait for
#    the slower rank, unpack = upload + scatter into B) / frame in ms (medians over the steps of the
#    maxima over ranks), builds/reuses and the skin chosen, np1/np2 (target >= 1.8), and the last
#    step's contacts and pair hash, which must be equal in every run of a scene (checked).
# Expect (not measured before this script's first run): halo from ~17 ms to a few ms at 2^25 (the
# halo's ~15 MB each way at pinned speed, the scatter); migrate and layout per rebuild lower by the
# host's passes over every row (owners' test, plan); what remains per rebuild is the host merge of the
# bodies' rows (~96 B a body, StepBodies kept in id order) and engine B's set_resident.
# BIN holds the CUDA build's contactgrid, contactgrid_tests and contactgrid_mpi_tests. Every check runs
# whatever an earlier one did; the script exits non-zero naming each failed check.
# A dry run without a GPU: BACKEND=cpu SCALE=10 (2^10 times fewer bodies; the CUDA checks then fail).
set -u
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; W=${WORK:-/tmp/cgwork}
mkdir -p "$OUT" "$W"
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt
CG="$BIN/contactgrid"
BACKEND=${BACKEND:-cuda}; SCALE=${SCALE:-0}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_btl_vader_single_copy_mechanism=cma
MPI=(mpirun --bind-to none --allow-run-as-root)
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
failed=()
check() {  # NAME COMMAND…: runs it, records the failure by name
  local name=$1; shift
  if "$@"; then echo "  ok    $name"; else echo "  FAIL  $name"; failed+=("$name"); fi
}
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; git log -1 --oneline 2>/dev/null; } \
  >"$OUT/device.txt" 2>&1
cat "$OUT/device.txt"
gtest_ok() {  # LOG: passed, nothing failed, no CUDA case skipped
  grep -q '^\[  PASSED  \]' "$1" && ! grep -q '^\[  FAILED  \]' "$1" && ! grep -q 'no CUDA device' "$1"
}

log "1. CUDA unit cases: row lists, splice, step plan, step bodies"
timeout 90 "$BIN/contactgrid_tests" --gtest_color=no \
  --gtest_filter='EngineRowLists*:EngineResidentSplice*:StepPlan.*:StepBodies.*' >"$OUT/tests.log" 2>&1
check "contactgrid_tests EngineRowLists*, EngineResidentSplice*, StepPlan, StepBodies" gtest_ok "$OUT/tests.log"
grep -E '^\[  (PASSED|FAILED) ' "$OUT/tests.log"

log "2. MPI moving steps at np 2: defaults, then the former paths"
timeout 150 "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" --gtest_color=no \
  --gtest_filter='MovingSteps.*:StepLoop.*' >"$OUT/mpi_tests.np2.log" 2>&1
check "contactgrid_mpi_tests MovingSteps, StepLoop np 2 (defaults)" gtest_ok "$OUT/mpi_tests.np2.log"
grep -E '^\[  (PASSED|FAILED) ' "$OUT/mpi_tests.np2.log"
timeout 120 env CONTACTGRID_STEP_HALO=host CONTACTGRID_STEP_SCAN=host CONTACTGRID_STEP_MERGE=wait "${MPI[@]}" -np 2 "$BIN/contactgrid_mpi_tests" \
  --gtest_color=no --gtest_filter='MovingSteps.Cuda*:StepLoop.*' >"$OUT/mpi_tests.np2.former.log" 2>&1
check "contactgrid_mpi_tests MovingSteps.Cuda*, StepLoop np 2 (former paths)" gtest_ok "$OUT/mpi_tests.np2.former.log"

# steps SCENE NP TAG [ENV…]: one drifting run, its summary in $OUT/TAG.log
steps() {
  local scene=$1 np=$2 tag=$3; shift 3
  timeout 150 env "$@" "${MPI[@]}" -np "$np" "$CG" detect "$W/$scene.h5" -o "$W/$tag.h5" --backend "$BACKEND" \
    --precision fp32 --steps 16 --drift 0.01 --skin auto >"$OUT/$tag.log" 2>&1
  local rc=$?
  rm -f "$W/$tag.h5"
  return $rc
}
field() {  # TAG WHAT: a figure of a run's summary in ms
  local f=$OUT/$1.log
  case $2 in
    mean) sed -nE 's/.*mean step ([0-9.e+-]+) s.*/\1/p' "$f" ;;
    build) sed -nE 's/.*detection ([0-9.e+-]+) s building.*/\1/p' "$f" ;;
    reuse) sed -nE 's/.*building, ([0-9.e+-]+) s reusing.*/\1/p' "$f" ;;
    layout) sed -nE 's/^  rebuild +([0-9.e+-]+).*/\1/p' "$f" ;;
    migrate) sed -nE 's/^  migrate +([0-9.e+-]+).*/\1/p' "$f" ;;
    halo) sed -nE 's/^  halo +([0-9.e+-]+).*/\1/p' "$f" ;;
    pack) sed -nE 's/^    halo pack +([0-9.e+-]+).*/\1/p' "$f" ;;
    mpi) sed -nE 's/^    halo mpi +([0-9.e+-]+).*/\1/p' "$f" ;;
    unpack) sed -nE 's/^    halo unpack +([0-9.e+-]+).*/\1/p' "$f" ;;
    frame) sed -nE 's/^  frame +([0-9.e+-]+).*/\1/p' "$f" ;;
    wait) sed -nE 's/^    merge wait +([0-9.e+-]+).*/\1/p' "$f" ;;
  esac | head -1 | awk '{ printf "%.3f", $1 * 1000 }'
}
lists() { sed -nE 's/.*candidate lists: ([0-9]+) builds, ([0-9]+) reuses, skin ([0-9.e+-]+).*/\1\/\2 skin \3/p' "$OUT/$1.log"; }
lasthash() { sed -nE 's/.*, ([0-9]+) contacts on the last step \(the output; pair hash ([0-9a-f]+)\).*/\1 \2/p' "$OUT/$1.log"; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { if (b > 0) printf "%.3f", a / b; else print "-" }'; }
same_last() {  # TAG…: every run's last step has one (contacts, pair hash), not empty
  local first; first=$(lasthash "$1"); [ -n "$first" ] || return 1
  for t in "$@"; do [ "$(lasthash "$t")" = "$first" ] || return 1; done
}
table() {  # SCENE RUN…
  local sc=$1; shift
  printf '| run (%s) | mean | build | reuse | layout | migrate | merge wait | halo | pack | mpi | unpack | frame | builds/reuses | np1/np2 (mean) | last step |\n' "$sc"
  printf '|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n'
  for t in "$@"; do
    local sp=; [ "$t" != np1 ] && sp=$(ratio "$(field "$sc.np1" mean)" "$(field "$sc.$t" mean)")
    printf '| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$t" "$(field "$sc.$t" mean)" \
      "$(field "$sc.$t" build)" "$(field "$sc.$t" reuse)" "$(field "$sc.$t" layout)" "$(field "$sc.$t" migrate)" \
      "$(field "$sc.$t" wait)" \
      "$(field "$sc.$t" halo)" "$(field "$sc.$t" pack)" "$(field "$sc.$t" mpi)" "$(field "$sc.$t" unpack)" \
      "$(field "$sc.$t" frame)" "$(lists "$sc.$t")" "$sp" "$(lasthash "$sc.$t")"
  done
  for t in "$@"; do
    echo "-- $sc $t"
    sed -nE '/^resident steps/,/slab rebalances/p' "$OUT/$sc.$t.log"
  done
}

log "3. bench: 2^25 spheres, fp32, 6 contacts per body, drift 0.01, skin auto, 16 steps"
timeout 90 "$CG" generate "$W/s25.h5" -n $((33554432 >> SCALE)) --seed 25 --contacts-per-body 6 -q
check "s25 np 1" steps s25 1 s25.np1
check "s25 np 2 (defaults)" steps s25 2 s25.np2
FORMER=(CONTACTGRID_STEP_HALO=host CONTACTGRID_STEP_SCAN=host CONTACTGRID_STEP_MERGE=wait)
check "s25 np 2 former (${FORMER[*]})" steps s25 2 s25.np2_former "${FORMER[@]}"
check "s25 np 2 halo=host alone" steps s25 2 s25.np2_halo_host CONTACTGRID_STEP_HALO=host
rm -f "$W/s25.h5"
check "s25: every run's last step has the same contacts and pair hash" \
  same_last s25.np1 s25.np2 s25.np2_former s25.np2_halo_host
table s25 np1 np2 np2_former np2_halo_host | tee "$OUT/table.md"
# 2^26 when the call has time left (the device's limit is 10 minutes a command)
if [ "${SKIP26:-0}" != 1 ] && [ "$SECONDS" -lt "${BUDGET26:-330}" ]; then
  log "3b. bench: 2^26 spheres, the same (np 1, np 2; ${SECONDS} s so far)"
  timeout 120 "$CG" generate "$W/s26.h5" -n $((67108864 >> SCALE)) --seed 26 --contacts-per-body 6 -q
  check "s26 np 1" steps s26 1 s26.np1
  check "s26 np 2 (defaults)" steps s26 2 s26.np2
  rm -f "$W/s26.h5"
  check "s26: np 1 and np 2 have the same last step" same_last s26.np1 s26.np2
  table s26 np1 np2 | tee -a "$OUT/table.md"
else
  echo "2^26 skipped (SKIP26=${SKIP26:-0}, ${SECONDS} s so far)"
fi
s26=-; [ -f "$OUT/s26.np2.log" ] && s26=$(ratio "$(field s26.np1 mean)" "$(field s26.np2 mean)")
echo "np1/np2 (mean step): s25 $(ratio "$(field s25.np1 mean)" "$(field s25.np2 mean)") (former $(ratio \
  "$(field s25.np1 mean)" "$(field s25.np2_former mean)")); s26 $s26; target >= 1.8" | tee -a "$OUT/table.md"
(cd "$OUT" && tar czf ranks.tgz ./*.log && rm -f ./*.log)
log "done"
if [ ${#failed[@]} -gt 0 ]; then
  printf 'FAILED: %s\n' "${failed[@]}"
  exit 1
fi
echo "all checks passed"
