#!/usr/bin/env bash
# contactgrid simulate's slots path (#32: kernels/dem_slots.hpp, core/dem_slots.hpp) on one GPU, in
# one call (under 5 minutes on one H100):
#   unit   DemSlots/cuda.* (the slots path against the rows path on the CUDA backend, bit for bit:
#          bodies, energies, contacts with history, the lists' builds, over 280 steps with rebuilds,
#          friction, rolling friction, plain Verlet, walls and gravity), DemSlotsBackends.* (CUDA's
#          slots = the CPU's slots, bit for bit), and the cases the change touches: DemRows/cuda.*
#          (run() on the slots path against the rank interface on the rows path), DemPhysics/cuda.*,
#          DemBackends.*, Simulate*
#   perf   whole steps on a pour at a settled pack's contact count (generate --kind pour
#          --pour-spacing 1.97: six neighbours each), fp32, --backend cuda, no mpirun: 2^20 (300 steps,
#          the first and last frames with --write-contacts) and 2^24 (60 steps, the first and last
#          frames), each on the slots path (the default, "slots") and on the rows path
#          (CONTACTGRID_DEM_PATH=rows, "rows"); steps/s from log.csv (its first block left out, as
#          jobs/gpu_simulate_check.sh); the two runs' log.csv (all but seconds_per_step: energies,
#          contacts, rebuilds) and every HDF5 file (frames, contacts with history) the same bytes;
#          then 40 steps of each with --stage-times (where a step's time goes)
# What to expect: every unit case passes (none skipped); the files identical; slots steps/s above the
# rows path's at both sizes (the issue: >= 1 500 steps/s at 2^20, >= 120 at 2^24; the rows path gave
# 784.7 and 63.0 on an H100, BENCHMARKS.md §23). Writes $OUT/table.md, $OUT/stages.txt,
# $OUT/summary.txt and $OUT/fused_logs.tar.gz; exits non-zero naming every failed check.
#   BIN=dir-with-the-CUDA-build's-binaries OUT=results-dir jobs/gpu_simulate_fused_check.sh [unit] [perf]
# (BIN holds contactgrid and contactgrid_tests; run from the repository root; .devrt/env.sh, when
# present, supplies the runtime libraries. N20, N24: smaller pours, BACKEND=cpu: a dry run.)
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt
BIN=${BIN:-.devbin/new}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"; W=${WORK:-/tmp/cgfused}; mkdir -p "$W"
BIN=$(cd "$BIN" && pwd)
CG="$BIN/contactgrid"
BACKEND=${BACKEND:-cuda}  # (cpu: a dry run of this script on a machine without a GPU)
parts=("$@"); [ ${#parts[@]} -eq 0 ] && parts=(unit perf)
failed=()
D="$OUT/fused_logs"; mkdir -p "$D"
log() { echo "[$(date -u +%H:%M:%S)] $*" | tee -a "$OUT/summary.txt"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; git rev-parse --short HEAD 2>/dev/null; } \
  >"$OUT/device.txt" 2>&1
cat "$OUT/device.txt"

part_unit() {
  local filter='DemSlots*:DemRows/cuda.*:DemPhysics/cuda.*:DemBackends*:Simulate*'
  timeout 240 "$BIN/contactgrid_tests" --gtest_filter="$filter" >"$D/unit.log" 2>&1 || failed+=("unit: $filter")
  grep -E '^\[  (PASSED|FAILED) |^\[  SKIPPED|^\[  FAILED' "$D/unit.log" | head -30 | tee -a "$OUT/summary.txt"
  if grep -q '^\[  SKIPPED \].*cuda' "$D/unit.log"; then failed+=("unit: CUDA cases skipped (no GPU seen)"); fi
}

part_perf() {
  scene() {  # name count
    timeout 120 "$CG" generate "$W/$1.h5" --kind pour -n "$2" --rlow 0.00495 --rhigh 0.005 --pour-spacing 1.97 \
      --seed 5 -q || { failed+=("perf: generate $1"); return 1; }
  }
  bench() {  # name count steps label [extra simulate options] -- [environment]
    local name=$1 n=$2 steps=$3 label=$4; shift 4
    local opts=() envs=()
    while [ $# -gt 0 ] && [ "$1" != -- ]; do opts+=("$1"); shift; done
    [ $# -gt 0 ] && shift
    envs=("$@")
    local run="$W/$name.$label.run"
    rm -rf "$run"
    if ! timeout 150 env "${envs[@]}" "$CG" simulate "$W/$name.h5" -o "$run" --steps "$steps" --output-every "$steps" \
        --log-every $((steps / 6)) --backend "$BACKEND" --precision fp32 --no-plot "${opts[@]}" >"$D/$name.$label.log" 2>&1; then
      failed+=("perf: simulate $name ($label)"); tail -3 "$D/$name.$label.log"; return
    fi
    grep -q "backend $BACKEND" "$D/$name.$label.log" || failed+=("perf: $name did not run on the $BACKEND backend")
    cp "$run/log.csv" "$D/$name.$label.log.csv"
    local sps cpb
    sps=$(awk -F, 'NR > 1 && $1 !~ /^#/ && $7 > 0 { n++; if (n > 1) { s += $7; k++ } } END { if (k) printf "%.1f", k / s }' "$run/log.csv")
    cpb=$(grep -oE '[0-9.]+ contacts/body' "$D/$name.$label.log" | head -1 | cut -d' ' -f1)
    printf '| %-22s | %9s | %6s | %8s | %10.3g | %9s |\n' "$name ($label)" "$n" "$steps" "$sps" \
      "$(awk -v s="$sps" -v n="$n" 'BEGIN { print s * n }')" "$cpb" >>"$OUT/table.md"
  }
  same_files() {  # name: the slots and rows runs' log.csv (but seconds_per_step) and HDF5 files, the same bytes
    local name=$1
    cmp <(cut -d, -f1-6 "$W/$name.slots.run/log.csv") <(cut -d, -f1-6 "$W/$name.rows.run/log.csv") \
      >"$D/$name.same.log" 2>&1 || failed+=("perf: $name's log.csv (energies, contacts, rebuilds) differs between slots and rows")
    # the files' bytes first (the same bytes: done); else their datasets and root attributes (h5py)
    local f bytes=1
    for f in "$W/$name.rows.run"/*.h5; do
      cmp -s "$f" "$W/$name.slots.run/$(basename "$f")" || bytes=0
    done
    [ "$(ls "$W/$name.rows.run"/*.h5 | wc -l)" = "$(ls "$W/$name.slots.run"/*.h5 | wc -l)" ] || bytes=0
    if [ $bytes = 1 ]; then
      echo "$name: $(ls "$W/$name.rows.run"/*.h5 | wc -l) HDF5 files the same bytes (cmp), slots and rows; log.csv too" \
        >>"$D/$name.same.log"
    else
      python3 - "$W/$name.slots.run" "$W/$name.rows.run" >>"$D/$name.same.log" 2>&1 <<'PYEOF' ||
import sys, glob, os, h5py
def datasets(path):
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda n, o: out.__setitem__(n, o[()].tobytes()) if isinstance(o, h5py.Dataset) else None)
        out["@attrs"] = repr(sorted((k, repr(v)) for k, v in f.attrs.items()))
    return out
a, b = sys.argv[1], sys.argv[2]
names = sorted(os.path.basename(p) for p in glob.glob(a + "/*.h5"))
assert names, "no files"
assert names == sorted(os.path.basename(p) for p in glob.glob(b + "/*.h5")), "different files"
for n in names:
    x, y = datasets(os.path.join(a, n)), datasets(os.path.join(b, n))
    bad = [k for k in sorted(set(x) | set(y)) if x.get(k) != y.get(k)]
    assert not bad, f"{n} differs in {bad}"
print(f"{len(names)} HDF5 files ({', '.join(names)}) the same bytes, slots and rows; log.csv too")
PYEOF
        failed+=("perf: $name's HDF5 files differ between slots and rows ($name.same.log)")
    fi
    cat "$D/$name.same.log" | tee -a "$OUT/summary.txt"
    rm -rf "$W/$name.slots.run" "$W/$name.rows.run"
  }
  stages() {  # name steps label [environment]
    local name=$1 steps=$2 label=$3; shift 3
    rm -rf "$W/$name.st.run"
    if ! timeout 120 env "$@" "$CG" simulate "$W/$name.h5" -o "$W/$name.st.run" --steps "$steps" --output-every "$steps" \
        --backend "$BACKEND" --precision fp32 --no-plot --stage-times >"$D/$name.$label.stages.log" 2>&1; then
      failed+=("perf: simulate $name --stage-times ($label)"); tail -3 "$D/$name.$label.stages.log"; return
    fi
    { echo "$name ($label):"; grep -E 'steps/s|stage times|within detect|energ|candidate' "$D/$name.$label.stages.log"; } \
      >>"$OUT/stages.txt"
    rm -rf "$W/$name.st.run"
  }
  printf '| %-22s | %9s | %6s | %8s | %10s | %9s |\n' run bodies steps steps/s body-st/s contacts/b >"$OUT/table.md"
  echo '|---|---|---|---|---|---|' >>"$OUT/table.md"
  : >"$OUT/stages.txt"
  local n20=${N20:-$((1 << 20))} n24=${N24:-$((1 << 24))}
  if scene p20 "$n20"; then
    bench p20 "$n20" 300 slots --write-contacts
    bench p20 "$n20" 300 rows --write-contacts -- CONTACTGRID_DEM_PATH=rows
    same_files p20
    stages p20 120 slots
    stages p20 120 rows CONTACTGRID_DEM_PATH=rows
    rm -f "$W/p20.h5"
  fi
  if scene p24 "$n24"; then
    bench p24 "$n24" 60 slots
    bench p24 "$n24" 60 rows -- CONTACTGRID_DEM_PATH=rows
    same_files p24
    stages p24 40 slots
    stages p24 40 rows CONTACTGRID_DEM_PATH=rows
    rm -f "$W/p24.h5"
  fi
  cat "$OUT/table.md" "$OUT/stages.txt" | tee -a "$OUT/summary.txt"
}

for p in "${parts[@]}"; do
  log "part $p"
  "part_$p"
done
tar -czf "$OUT/fused_logs.tar.gz" -C "$OUT" fused_logs 2>/dev/null
if [ ${#failed[@]} -gt 0 ]; then
  log "FAILED:"
  for f in "${failed[@]}"; do log "  $f"; done
  exit 1
fi
log "all checks passed"
