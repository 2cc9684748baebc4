#!/usr/bin/env bash
# The laptop engineer's check (issues #33 and #37's CPU target): Python contactgrid.detect on NumPy
# arrays of 2^20 uniform spheres, CPU backend, 2 cores, >= 20x SciPy's cKDTree.query_pairs + filter
# (the same pairs), before / after in one call on cores 0,1 (taskset -c 0,1, 2 threads), the same
# binaries: before = CONTACTGRID_HOST_CELL_BODIES=types (the cell sort as merged in s11: after the
# entries are written, the walk's bodies gathered type after type, an even share of the entries a
# thread, so each body's 24-byte record is read once for each of the eight cell types), after = the
# defaults (s12: the gather chunk by chunk of 256 super-cells, the eight types of a chunk together:
# each record read from memory about once, the layer of super-cells behind a chunk in the cache).
# BEFORE="CONTACTGRID_HOST_ENTRIES=cells-via-cells CONTACTGRID_HOST_CELL_BODIES=types" compares with
# s10's cell sort; BEFORE="CONTACTGRID_HOST_ENTRIES=body-order" with the entry sort. ROUNDS (default 5)
# before / after alternations of the engine.
# Needs no GPU; runs on the device host for its quiet cores. Steps:
#   unit     (BIN holds contactgrid_tests) CellBodies* (the chunk gather = the type gather: entries,
#            walk bodies byte for byte, and contact bytes + stats through the engine, 1-3 threads, on
#            scenes above the one-thread size, radii over two decades, centres on cell faces, huge
#            spheres, one body, none), CellSort*, HostEntries*, HostWalk*, RadixSort*, HostStages*,
#            and CPU = CUDA (CudaBackendTest/*, CudaNarrowTest/*: the CPU side takes the cell sort);
#            CellBodies.EngineGivesTheTypeGathersBytesAndStats, CellSort.EngineGivesTheEntrySortsBytes
#            AndStats and a CudaBackendTest BitIdenticalToCpu case must run and pass
#   module   the Python module compiled against the device's interpreter (jobs/gpu_python_check.sh)
#   engine   host_stage_bench, a new engine a call, 9 calls, before and after alternated ROUNDS times;
#            the same contacts and stats (entries, pair tests, candidates) required; per-stage table
#            of the lower of the medians; then one thread on core 0, alternated 3 times (sort, sum)
#   python   tests/bench/python_bench.py: before (knob, no SciPy), after with SciPy and C++, before
#            again; the lower of the two before medians counts
# Expect (H100 host of s11 call 10, 2 threads: engine plan / pack / entries / sort / pairs / order /
# narrow 4.8 / 14.3 / 23.5 / 38.9 / 24.1 / 6.6 / 15.2 ms, sum 128.5; Python 151.0 ms, C++ 145.9,
# SciPy 2858.7 = 18.9x): before about those; after: only "sort" moves (the other stages are the
# same code: their ratios show the machine's noise). Dev VM, BENCHMARKS-style lower of medians, five
# alternations: sort 16.0 -> 13.6 ms at 2 threads (1.18x), 28.4 -> 25.5 at 1 thread (1.12x). The
# H100 host's sort is 2.6x the dev VM's at 2 threads (the rest ~2x): where that is the records'
# eight sweeps from memory, after should gain more there (sort ~30 ms or less). 20x needs Python
# <= SciPy / 20 (~143 ms against 2859).
# Prints a table; writes $OUT/laptop.tgz (every log); exits non-zero naming what failed (a step,
# contacts or stats that differ, different pairs from SciPy, SciPy / Python below 20).
# Here: BUILD_DIR=build jobs/gpu_python_check.sh pack .devbin/py. There (about 4 minutes):
#   OUT=/tmp/out BIN=<dir with contactgrid_tests> jobs/gpu_laptop_check.sh .devbin/py
set -u
cd "$(dirname "$0")/.."
[ -f .devrt/env.sh ] && source .devrt/env.sh .devrt >/dev/null 2>&1
dir=$(realpath -m "${1:-.devbin/py}")
OUT=${OUT:-/tmp/out}
log_dir="$OUT/laptop"
mkdir -p "$log_dir"
failed=()
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
BIN=$(realpath -m "${BIN:-$dir}")
py=${PYTHON:-python3}
export LD_LIBRARY_PATH="$dir/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
cores="taskset -c 0,1"
before=${BEFORE:-"CONTACTGRID_HOST_CELL_BODIES=types"}
rounds=${ROUNDS:-5}
{ date -u; nproc; grep -m1 'model name' /proc/cpuinfo; uptime; git log -1 --format='commit %h %s' 2>/dev/null; } 2>&1 |
  tee "$log_dir/device.txt"

if [ -x "$BIN/contactgrid_tests" ]; then
  log "== unit: CellBodies, CellSort, HostEntries, HostWalk, RadixSort, HostStages, CPU = CUDA"
  timeout 300 "$BIN/contactgrid_tests" \
    --gtest_filter='CellBodies*:CellSort*:HostEntries*:HostWalk*:RadixSort*:HostStages*:CudaBackendTest/*:CudaNarrowTest/*' \
    >"$log_dir/unit.log" 2>&1 || failed+=(unit)
  grep -E '^\[  (PASSED|FAILED|SKIPPED) |^\[==========\]' "$log_dir/unit.log" | head -20
  grep -q 'OK \] CellSort.EngineGivesTheEntrySortsBytesAndStats' "$log_dir/unit.log" ||
    failed+=(cell_sort_case_did_not_run)
  grep -q 'OK \] CellBodies.EngineGivesTheTypeGathersBytesAndStats' "$log_dir/unit.log" ||
    failed+=(cell_bodies_case_did_not_run)
  grep -q 'OK \] CudaBackendTest/.*BitIdenticalToCpu' "$log_dir/unit.log" || failed+=(cuda_cpu_cases_did_not_run)
else
  echo "note: no $BIN/contactgrid_tests: unit cases not run"
fi

log "== the module (compiled against $py)"
timeout 240 jobs/gpu_python_check.sh module "$dir" >"$log_dir/module.log" 2>&1 || failed+=(module)
tail -3 "$log_dir/module.log"

scene="$log_dir/s20.h5"
"$dir/contactgrid" generate "$scene" -n 1048576 --seed 20 -q || failed+=(generate)

log "== engine: host_stage_bench 9 calls, 2 threads, cores 0,1, before ($before) / after alternated $rounds times"
for r in $(seq 1 "$rounds"); do
  env $before timeout 120 $cores "$dir/host_stage_bench" "$scene" 9 2 mixed fresh >"$log_dir/engine_before_$r.log" 2>&1 ||
    failed+=(engine_before)
  timeout 120 $cores "$dir/host_stage_bench" "$scene" 9 2 mixed fresh >"$log_dir/engine_after_$r.log" 2>&1 ||
    failed+=(engine_after)
done
{
  printf "\nengine stages, 2^20 mixed, cores 0,1, the lower of %s medians (ms; cpu: CPU ms a call):\n" "$rounds"
  printf "  %-8s %9s %9s %9s\n" stage before after before/after
  for st in $(awk '$1 != "stage" && $1 != "contacts" && $1 != "stats" {print $1}' "$log_dir/engine_after_1.log"); do
    low() { cat "$log_dir"/engine_"$1"_?.log | awk -v s="$st" '$1 == s {print $3}' | sort -n | head -1; }
    awk -v s="$st" -v b="$(low before)" -v a="$(low after)" 'BEGIN {
      printf "  %-8s %9s %9s %9s\n", s, b, a, (a > 0 ? sprintf("%.2fx", b / a) : "-")}'
  done
} | tee "$log_dir/engine_table.txt"
for r in $(seq 1 "$rounds"); do
  for v in before after; do
    grep -E '^contacts|^stats' "$log_dir/engine_${v}_$r.log" | tr '\n' ' ' >"$log_dir/engine_${v}_$r.id"
  done
  cmp -s "$log_dir/engine_before_$r.id" "$log_dir/engine_after_$r.id" || failed+=(engine_contacts_or_stats_differ)
done
echo "  before and after: $(cat "$log_dir/engine_after_1.id")"

log "== engine at one thread (core 0), before / after alternated 3 times: sort and the stage sum"
for r in 1 2 3; do
  env $before timeout 120 taskset -c 0 "$dir/host_stage_bench" "$scene" 9 1 mixed fresh >"$log_dir/engine1_before_$r.log" 2>&1 ||
    failed+=(engine1_before)
  timeout 120 taskset -c 0 "$dir/host_stage_bench" "$scene" 9 1 mixed fresh >"$log_dir/engine1_after_$r.log" 2>&1 ||
    failed+=(engine1_after)
done
for st in sort "(sum)"; do
  low1() { cat "$log_dir"/engine1_"$1"_?.log | awk -v s="$st" '$1 == s {print $3}' | sort -n | head -1; }
  awk -v s="$st" -v b="$(low1 before)" -v a="$(low1 after)" 'BEGIN {
    printf "  1 thread %-8s %9s %9s %9s\n", s, b, a, (a > 0 ? sprintf("%.2fx", b / a) : "-")}'
done | tee -a "$log_dir/engine_table.txt"

python_before() {
  log "== Python before ($before, no SciPy), cores 0,1, 9 calls ($1 of 2)"
  PYTHONPATH=/tmp/cgpy env $before timeout 200 $cores $py tests/bench/python_bench.py --log2n 20 --backend cpu \
    --threads 2 --repetitions 9 --no-scipy --binary "$dir/contactgrid" --cxx "$dir/detect_call_bench" \
    >"$log_dir/python_before_$1.log" 2>&1 || failed+=(python_before)
  grep -E '^contactgrid.detect|^same call' "$log_dir/python_before_$1.log"
}
python_before 1
log "== Python after, C++, SciPy: python_bench.py, cores 0,1 (9 calls each, SciPy 5)"
PYTHONPATH=/tmp/cgpy timeout 300 $cores $py tests/bench/python_bench.py --log2n 20 --backend cpu --threads 2 \
  --repetitions 9 --scipy-repetitions 5 --binary "$dir/contactgrid" --cxx "$dir/detect_call_bench" 2>&1 |
  tee "$log_dir/python.log"
[ "${PIPESTATUS[0]}" -eq 0 ] || failed+=(python_bench)
python_before 2
rm -f "$scene"

eb=$(cat "$log_dir"/engine_before_?.log | awk '$1 == "(sum)" {print $3}' | sort -n | head -1)
ea=$(cat "$log_dir"/engine_after_?.log | awk '$1 == "(sum)" {print $3}' | sort -n | head -1)
pyb=$(cat "$log_dir"/python_before_?.log | awk '/^contactgrid.detect/ {print $2}' | sort -n | head -1)
cxxb=$(cat "$log_dir"/python_before_?.log | awk '/^same call from C\+\+/ {print $5}' | sort -n | head -1)
pyt=$(awk '/^contactgrid.detect/ {print $2}' "$log_dir/python.log")
cxx=$(awk '/^same call from C\+\+/ {print $5}' "$log_dir/python.log")
sp=$(awk '/^SciPy cKDTree/ {print $3}' "$log_dir/python.log")
same=$(grep -o 'same pairs: [A-Za-z]*' "$log_dir/python.log" | awk '{print $3}')
awk -v eb="$eb" -v ea="$ea" -v pb="$pyb" -v p="$pyt" -v xb="$cxxb" -v x="$cxx" -v s="$sp" -v same="$same" \
  -v k="$before" 'BEGIN {
  printf "\nlaptop mode, 2^20 uniform spheres, CPU backend, cores 0,1, medians (ms), same binaries, this run:\n"
  printf "  %-34s %10s %10s %8s\n", "", "before", "after", "ratio"
  printf "  (before: %s; after: the defaults, the chunk gather of the walk bodies)\n", k
  if (eb > 0 && ea > 0) printf "  %-34s %10s %10s %7.2fx\n", "engine stages (lower median)", eb, ea, eb / ea
  if (pb > 0 && p > 0) printf "  %-34s %10s %10s %7.2fx\n", "Python contactgrid.detect", pb, p, pb / p
  if (xb > 0 && x > 0) printf "  %-34s %10s %10s %7.2fx\n", "the same call from C++", xb, x, xb / x
  if (s > 0) printf "  %-34s %10s\n", "SciPy cKDTree + filter", s
  if (pb > 0 && p > 0 && s > 0) printf "  %-34s %9.1fx %9.1fx   (target >= 20)\n", "SciPy / Python", s / pb, s / p
  if (p > 0 && x > 0) printf "  %-34s %10s %10.3f   (target <= 1.05)\n", "Python / C++", "", p / x
  printf "  same pairs as SciPy: %s\n", same
}' | tee "$log_dir/summary.txt"
[ "$same" = True ] || failed+=(same_pairs)
awk -v p="$pyt" -v s="$sp" 'BEGIN {exit !(p > 0 && s >= 20 * p)}' || failed+=(scipy_ratio_below_20)

tar czf "$OUT/laptop.tgz" -C "$OUT" laptop && rm -rf "${log_dir:?}"
if [ ${#failed[@]} -gt 0 ]; then
  echo "FAILED: ${failed[*]}"
  exit 1
fi
echo "all passed"
