#!/usr/bin/env bash
# The Python module on a GPU machine whose Python is not Debian's (the device: Python 3.12, NumPy 2,
# CuPy, pip's pybind11, nvcc and g++; no HDF5 headers). The module is compiled THERE against that
# interpreter from this tree's sources, linking the static libraries built HERE (CUDA on) and Debian's
# shared libraries carried beside them; then its pytest suite runs with the GPU (test_gpu.py: our
# DeviceArray and CuPy) and the zero-copy timing against contactgrid_cuda_bench.
#   here:   jobs/gpu_python_check.sh pack [DIR=.devbin/py]     (after a CUDA build in build/, or
#           BUILD_DIR=<that build>; the DLPack header travels along: the device has no libdlpack-dev)
#   there:  jobs/gpu_python_check.sh run  [DIR=.devbin/py] [OUT=/tmp/out]
#           jobs/gpu_python_check.sh module [DIR=.devbin/py]   (the module alone, into /tmp/cgpy:
#           what jobs/gpu_library_check.sh times)
set -euo pipefail
cd "$(dirname "$0")/.."
mode=$1 dir=$(realpath -m "${2:-.devbin/py}")
# The module compiled here against this interpreter ($PYTHON or python3) into /tmp/cgpy/contactgrid.
build_module() {
    mkdir -p /tmp/cgpy/contactgrid
    py=${PYTHON:-python3}
    ext=$($py -c "import sysconfig; print(sysconfig.get_config_var('EXT_SUFFIX'))")
    cp src/python/contactgrid/__init__.py src/python/contactgrid/__init__.pyi /tmp/cgpy/contactgrid/
    version=$(sed -n 's/^project(contactgrid VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
    for so in "$dir"/lib/*.so.*; do ln -sf "$(basename "$so")" "$dir/lib/$(basename "$so" | sed 's/\.so\..*/.so/')"; done
    g++ -O2 -std=c++20 -shared -fPIC -fvisibility=hidden -ffp-contract=off $($py -m pybind11 --includes) \
      -Ikernels -Isrc -I"$dir/include" -DCONTACTGRID_HAVE_CUDA=1 -DCONTACTGRID_VERSION="\"$version\"" src/python/*.cpp \
      -o "/tmp/cgpy/contactgrid/_contactgrid$ext" "$dir/libcg_io.a" "$dir/libcontactgrid.a" \
      -L/usr/local/cuda/lib64 -lcudart_static -ldl -lrt -lpthread -fopenmp -L"$dir/lib" -lhdf5_serial -lfmt \
      -Wl,--exclude-libs,ALL -Wl,-rpath,"$dir/lib" -Wl,-rpath-link,"$dir/lib" 2>&1 | tail -20
}
case $mode in
  pack)
    build=${BUILD_DIR:-build}
    mkdir -p "$dir/lib" "$dir/include/dlpack"
    cp /usr/include/dlpack/dlpack.h "$dir/include/dlpack/"
    cp "$build"/kernels/libcontactgrid.a "$build"/src/libcg_io.a "$build"/src/contactgrid "$dir/"
    cp "$build"/kernels/contactgrid_cuda_bench "$dir/" 2>/dev/null || true
    cmake --build "$build" --target detect_call_bench host_stage_bench host_bandwidth &&
      cp "$build"/tests/detect_call_bench "$build"/tests/host_stage_bench "$build"/tests/host_bandwidth "$dir/"
    { ldd "$build"/src/python/contactgrid/_contactgrid*.so; ldd "$build"/src/contactgrid; ldd "$dir/detect_call_bench"; } | awk '/=>/{print $3}' |
      grep -v -E 'libc\.so|libm\.so|libstdc|libgcc_s|ld-linux|libpython|libgomp' | sort -u |
      xargs -I{} cp -L {} "$dir/lib/"
    du -sh "$dir" ;;
  module)
    build_module ;;
  run)
    set +e  # every step runs and reports, whatever an earlier one did
    out=$(realpath -m "${3:-/tmp/out}")
    mkdir -p "$out"
    build_module
    export PYTHONPATH=/tmp/cgpy CG_BINARY="$dir/contactgrid" LD_LIBRARY_PATH="$dir/lib"
    { date -u; nvidia-smi --query-gpu=name,driver_version --format=csv,noheader || true; $py --version;
      $py -c "import numpy, contactgrid; print('numpy', numpy.__version__, 'cuda', contactgrid.cuda_available())" || true
    } >"$out/device.txt" 2>&1
    cat "$out/device.txt"
    (cd tests/python && $py -m pytest -q -rs -p no:cacheprovider test_gpu.py test_detect.py test_engine_and_files.py \
      test_history.py test_dlpack.py \
      2>&1 | tee "$out/pytest.log" | tail -15; exit "${PIPESTATUS[0]}")
    pytest_rc=$?
    $py tests/bench/python_gpu_bench.py --min 20 --max 24 --runs 20 2>&1 | tee "$out/python_gpu_bench.log"
    # CUDA from NumPy arrays (host memory: upload and download included) against the same call from C++
    $py tests/bench/python_bench.py --log2n 24 --backend cuda --repetitions 10 --no-scipy \
      --binary "$dir/contactgrid" --cxx "$dir/detect_call_bench" 2>&1 | tee "$out/python_bench_cuda.log"
    # The laptop figure on a quiet machine: two of the host's cores, the CPU backend against SciPy
    if $py -c "import scipy" 2>/dev/null; then
      taskset -c 0,1 $py tests/bench/python_bench.py --log2n 20 --backend cpu --threads 2 --repetitions 7 \
        --binary "$dir/contactgrid" --cxx "$dir/detect_call_bench" 2>&1 | tee "$out/python_bench_cpu2.log"
    else
      echo "no SciPy for $py: the quiet CPU comparison did not run" | tee "$out/python_bench_cpu2.log"
    fi
    if [ -x "$dir/contactgrid_cuda_bench" ]; then
      "$dir/contactgrid_cuda_bench" 20 24 2 20 2>&1 | tee "$out/cuda_bench.log" | tail -40
    fi
    if [ "$pytest_rc" -ne 0 ]; then echo "FAILED: the Python GPU pytest suite (exit $pytest_rc; $out/pytest.log)"; exit 1; fi ;;
esac
