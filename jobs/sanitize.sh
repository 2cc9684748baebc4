#!/usr/bin/env bash
# CI's sanitizer step: the unit tests (contactgrid_tests and the contactgrid binary they drive) built
# with AddressSanitizer + UndefinedBehaviorSanitizer (GCC, without CUDA) and run (CTest label "unit",
# less the mpirun cases), then the committed fuzz corpus replayed through the libFuzzer harness
# (tests/fuzz/replay_corpus.sh: clang-14, -fsanitize=fuzzer,address,undefined).
#   jobs/sanitize.sh [extra ctest arguments]       BUILD_DIR (default build-asan)
# Any sanitizer report fails the step (no recovery; leaks are reported at exit).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build-asan}
mkdir -p "$BUILD_DIR"
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCONTACTGRID_ENABLE_CUDA=OFF \
  -DCONTACTGRID_SANITIZE=address,undefined ${CMAKE_EXTRA_ARGS:-} >"$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log"; exit 1; }
cmake --build "$BUILD_DIR" -j "$(nproc)" --target contactgrid contactgrid_tests
# detect_leaks: LeakSanitizer at every exit; allocator_may_return_null: a failed allocation is
# std::bad_alloc (exit 7), as without the sanitizer
export ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=1:abort_on_error=0:strict_string_checks=1
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export LSAN_OPTIONS=suppressions=$PWD/tests/sanitize/lsan.supp
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
ctest --test-dir "$BUILD_DIR" -L unit -E 'DyingRanks' --output-on-failure -j "$(nproc)" "$@"
tests/fuzz/replay_corpus.sh
