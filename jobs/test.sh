#!/usr/bin/env bash
# The README's test command: install, build, run the whole suite (unit, validation, CLI, MPI at
# 1–4 ranks). CUDA cases skip visibly on a machine without a GPU.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs/install_deps.sh
jobs/build.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
ctest --test-dir "${BUILD_DIR:-build}" --output-on-failure -j "$(nproc)" "$@"
