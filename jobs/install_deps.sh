#!/usr/bin/env bash
# Installs the Debian 12 packages contactgrid builds against (nothing is downloaded at configure time).
# CUDA is optional: the CUDA backend builds when /usr/local/cuda/bin/nvcc (or nvcc on PATH) exists.
set -euo pipefail
pkgs=(build-essential cmake ninja-build pkg-config
      libopenmpi-dev openmpi-bin libhdf5-dev hdf5-tools libbullet-dev
      libgtest-dev libcli11-dev libfmt-dev gnuplot-nox clang-format
      clang-14 libclang-rt-14-dev)  # the fuzz harness (tests/fuzz: libFuzzer, sanitizers)
missing=()
for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if ((${#missing[@]})); then
  SUDO=; [ "$(id -u)" -ne 0 ] && SUDO=sudo
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq "${missing[@]}"
fi
