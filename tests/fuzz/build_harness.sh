#!/usr/bin/env bash
# Builds the libFuzzer harness over the readers (tests/fuzz/fuzz_readers.cpp) into
# build-fuzz/fuzz_readers with clang-14 and -fsanitize=fuzzer,address,undefined, when it is missing
# or older than its sources; used by build_and_run.sh (the long job) and replay_corpus.sh (CI).
# Needs clang-14 and libclang-rt-14-dev (Debian 12). libhdf5 itself is not instrumented.
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=build-fuzz
mkdir -p "$OUT"
HDF5_FLAGS=$(pkg-config --cflags --libs hdf5-serial 2>/dev/null || pkg-config --cflags --libs hdf5)
VERSION=$(sed -n 's/^project(contactgrid VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
SOURCES=(src/io/*.cpp src/run/stop.cpp kernels/contacts.cpp tests/fuzz/fuzz_readers.cpp)
if [[ ! -x $OUT/fuzz_readers || -n $(find "${SOURCES[@]}" src/io src/run/stop.hpp kernels/errors.hpp \
        kernels/contacts.hpp kernels/core/contact_fields.hpp -newer "$OUT/fuzz_readers" 2>/dev/null) ]]; then
  clang++-14 -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
    -DCONTACTGRID_VERSION="\"${VERSION:-0}\"" -Wno-unknown-pragmas \
    -Itests/fuzz/stub -Isrc -Ikernels "${SOURCES[@]}" $HDF5_FLAGS -lfmt -o "$OUT/fuzz_readers"
fi
