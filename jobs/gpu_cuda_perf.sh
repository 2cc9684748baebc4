#!/usr/bin/env bash
# The CUDA backend on one GPU (issue #3's record): the test suite with its CUDA cases, memcheck and
# racecheck on the CUDA tests, the per-stage bench at the default (tuned) cell and at the smallest
# cell, and a cell-edge sweep at 2^24 (the data behind kPairWeight in kernels/engine.hpp).
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_cuda_perf.sh
# BIN holds contactgrid_tests and contactgrid_cuda_bench. Logs go to $OUT.
set -u
BIN=${BIN:-.devbin}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
{ date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader; } >"$OUT/device.txt"
cat "$OUT/device.txt"
log "tests"
"$BIN/contactgrid_tests" >"$OUT/tests.log" 2>&1
grep -E '^\[  (PASSED|FAILED) |^\[==========\]|Failure' "$OUT/tests.log" | head -20
log "bench: tuned cell (default)"
"$BIN/contactgrid_cuda_bench" 16 26 2 20 auto >"$OUT/bench_auto.md" 2>&1
grep -E '^\| 2\^' "$OUT/bench_auto.md" | cut -d'|' -f2-14,16,18-20
log "bench: smallest cell"
"$BIN/contactgrid_cuda_bench" 20 24 4 20 min >"$OUT/bench_min.md" 2>&1
grep -E '^\| 2\^' "$OUT/bench_min.md" | cut -d'|' -f2-14,16,18-20
log "cell sweep at 2^24"
for c in 3 4 4.5 5 5.5 6; do "$BIN/contactgrid_cuda_bench" 24 24 2 10 $c 2>&1 | grep -E '^\| 2\^'; done \
  >"$OUT/sweep24.md"
cut -d'|' -f2-14 "$OUT/sweep24.md"
log "renumbering forced on / off (tuned cell; default: on above half the L2)"
for r in 1 0; do CONTACTGRID_CUDA_RENUMBER=$r "$BIN/contactgrid_cuda_bench" 20 24 4 20 auto 2>&1 | grep -E '^\| 2\^' \
  | sed "s/^/renumber=$r /"; done >"$OUT/renumber.md"
cut -d'|' -f1-14 "$OUT/renumber.md"
log "memcheck"
timeout 300 compute-sanitizer --tool memcheck --leak-check full "$BIN/contactgrid_tests" \
  --gtest_filter='*cuda*:*Cuda*' >"$OUT/memcheck.log" 2>&1
grep -E 'ERROR SUMMARY|LEAK SUMMARY|PASSED|FAILED' "$OUT/memcheck.log" | head
log "racecheck"
timeout 240 compute-sanitizer --tool racecheck "$BIN/contactgrid_tests" --gtest_filter='CudaBackendTest*' \
  >"$OUT/racecheck.log" 2>&1
grep -E 'RACECHECK SUMMARY|PASSED|FAILED' "$OUT/racecheck.log" | head
log "done"
