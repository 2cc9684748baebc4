#!/usr/bin/env bash
# The long fuzz job (not part of the default build): a libFuzzer harness over the scene and contact
# readers (tests/fuzz/fuzz_readers.cpp), built with clang-14 and -fsanitize=fuzzer,address,undefined.
#   tests/fuzz/build_and_run.sh [seconds=600] [contactgrid binary=build/src/contactgrid]
# FUZZ_ARGS adds libFuzzer flags, e.g. FUZZ_ARGS="-fork=1 -ignore_crashes=1" to go on after a finding.
# Needs clang-14 and libclang-rt-14-dev (Debian 12). The seed corpus is made with the contactgrid
# binary (a generated sphere scene, an ellipsoid scene, a contact file); findings land in
# build-fuzz/findings/, the grown corpus in build-fuzz/corpus/, the log in build-fuzz/fuzz.log.
# libhdf5 itself is not instrumented: coverage guidance sees our readers only, while crashes inside
# HDF5 are still caught (deadly signal) and so are oversized allocations (-malloc_limit_mb).
set -euo pipefail
cd "$(dirname "$0")/../.."
SECONDS_TO_RUN=${1:-600}
CG=${2:-build/src/contactgrid}
OUT=build-fuzz
mkdir -p "$OUT/seeds" "$OUT/corpus" "$OUT/findings"
HDF5_FLAGS=$(pkg-config --cflags --libs hdf5-serial 2>/dev/null || pkg-config --cflags --libs hdf5)
VERSION=$(sed -n 's/^project(contactgrid VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
if [[ ! -x $OUT/fuzz_readers || tests/fuzz/fuzz_readers.cpp -nt $OUT/fuzz_readers ||
      -n $(find src/io -newer "$OUT/fuzz_readers" 2>/dev/null) ]]; then
  clang++-14 -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    -DCONTACTGRID_VERSION="\"${VERSION:-0}\"" -Wno-unknown-pragmas \
    -Itests/fuzz/stub -Isrc -Ikernels src/io/*.cpp src/run/stop.cpp kernels/contacts.cpp tests/fuzz/fuzz_readers.cpp \
    $HDF5_FLAGS -lfmt -o "$OUT/fuzz_readers"
fi
if [[ -x $CG && -z $(ls -A "$OUT/seeds") ]]; then
  "$CG" generate "$OUT/seeds/spheres.h5" -n 20 --seed 1 -q
  "$CG" generate "$OUT/seeds/polydisperse.h5" -n 30 --kind polydisperse --seed 2 -q
  "$CG" detect "$OUT/seeds/spheres.h5" -o "$OUT/seeds/contacts.h5" --backend cpu -q
  "$CG" detect "$OUT/seeds/polydisperse.h5" -o "$OUT/seeds/contacts_full.h5" --backend cpu --fields full \
    --precision fp32 -q || true
  cp tests/data/damaged/*.h5 "$OUT/seeds/" 2>/dev/null || true
fi
cd "$OUT"
source ../tests/fuzz/fuzz_options.sh
./fuzz_readers corpus seeds -max_total_time="$SECONDS_TO_RUN" "${FUZZ_LIMITS[@]}" ${FUZZ_ARGS:-} 2>&1 | tee fuzz.log | grep -E '^#[0-9]+ *(pulse|DONE|NEW)|ERROR|SUMMARY|stat::' || true
