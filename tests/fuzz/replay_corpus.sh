#!/usr/bin/env bash
# CI: every input of the committed fuzz corpus (tests/fuzz/corpus: the libFuzzer corpus of the long
# job, minimised with -merge=1) and every regression file (tests/data/damaged) run once through the
# harness built with AddressSanitizer and UndefinedBehaviorSanitizer (build_harness.sh). A crash, a
# sanitizer report, a timeout or an allocation over the limits of fuzz_options.sh fails the step.
set -euo pipefail
cd "$(dirname "$0")/../.."
tests/fuzz/build_harness.sh
source tests/fuzz/fuzz_options.sh
mkdir -p build-fuzz/replay/findings && cd build-fuzz/replay
inputs=(../../tests/fuzz/corpus/* ../../tests/data/damaged/*.h5)
start=$SECONDS
../fuzz_readers "${FUZZ_LIMITS[@]}" "${inputs[@]}" >replay.log 2>&1 \
  || { tail -60 replay.log; echo "fuzz corpus replay: FAILED (log: build-fuzz/replay/replay.log)"; exit 1; }
echo "fuzz corpus replay: ${#inputs[@]} inputs, no finding ($((SECONDS - start)) s)"
