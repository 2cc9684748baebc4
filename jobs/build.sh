#!/usr/bin/env bash
# Configures and builds contactgrid into ${BUILD_DIR:-build} (Release). Extra arguments go to cmake.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@" >"$BUILD_DIR.configure.log" 2>&1 \
  || { cat "$BUILD_DIR.configure.log"; exit 1; }
grep -A8 'Enabled features' "$BUILD_DIR.configure.log" || true
cmake --build "$BUILD_DIR" -j "$(nproc)"
