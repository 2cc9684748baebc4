#!/usr/bin/env bash
# Installs the Debian 12 packages contactgrid builds against (nothing is downloaded at configure time).
# CUDA is optional: the CUDA backend builds when /usr/local/cuda/bin/nvcc (or nvcc on PATH) exists.
# Python (import contactgrid): pybind11 and NumPy of Debian's python3; pytest, pip, h5py and meshio
# for its tests (meshio reads the XDMF files back); SciPy only for tests/bench/python_bench.py;
# libdlpack-dev: dlpack/dlpack.h, the DLPack ABI the module exchanges GPU and CPU arrays through.
set -euo pipefail
pkgs=(build-essential cmake ninja-build pkg-config
      libopenmpi-dev openmpi-bin libhdf5-dev hdf5-tools libbullet-dev
      libgtest-dev libcli11-dev libfmt-dev gnuplot-nox clang-format python3
      python3-dev pybind11-dev libdlpack-dev python3-numpy python3-pytest python3-pip python3-h5py python3-meshio
      clang-14 libclang-rt-14-dev)  # the fuzz harness and the sanitizer build (tests/fuzz, jobs/sanitize.sh)
missing=()
for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if ((${#missing[@]})); then
  SUDO=; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq "${missing[@]}"
fi
