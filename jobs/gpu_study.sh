#!/usr/bin/env bash
# `contactgrid study` on the GPU machine (issue #13): the study's tests with CUDA present (the CUDA
# rows join the invariants), then the default study on both backends (< 5 min on an H100 host),
# CSV and SVG into $OUT.
#   BIN=dir-with-binaries OUT=results-dir jobs/gpu_study.sh
set -u
BIN=${BIN:-build}; OUT=${OUT:-/tmp/out}; mkdir -p "$OUT"
log() { echo "[$(date -u +%H:%M:%S)] $*"; }
log "study tests (CUDA rows included when a GPU is present)"
"$BIN/tests/contactgrid_tests" --gtest_filter='Study.*:ErrorMetrics.*:ExactReference.*' 2>&1 |
  grep -E '^\[  (PASSED|FAILED) |Failure|SKIPPED' | head -20
log "contactgrid study --backends cpu,cuda (scale 1)"
nvidia-smi --query-gpu=name --format=csv,noheader
timeout 290 "$BIN/src/contactgrid" study --backends cpu,cuda --csv "$OUT/study_gpu.csv" --svg "$OUT/study_gpu.svg" \
  2>"$OUT/study_gpu.progress"
echo "exit $?"
log "done"
