#!/usr/bin/env bash
# The long fuzz job (tests/fuzz/build_and_run.sh) on a bigger machine that has no compiler or Debian
# HDF5: run the harness built here, with Debian's libhdf5 1.10.8 and its dependencies carried beside it
# (the library whose crashes #21 is about), in libFuzzer's fork mode on many cores.
#   here:   jobs/fuzz_elsewhere.sh pack DIR        (fuzz_readers, its libraries, the grown corpus)
#   there:  jobs/fuzz_elsewhere.sh run DIR SECONDS JOBS OUTDIR
set -euo pipefail
mode=$1 dir=$(realpath -m "$2")
case $mode in
  pack)
    mkdir -p "$dir/lib"
    cp build-fuzz/fuzz_readers "$dir/"
    ldd build-fuzz/fuzz_readers | awk '/=>/{print $3}' |
      grep -v -E 'libc\.so|libm\.so|libstdc|libgcc_s|ld-linux' | xargs -I{} cp -L {} "$dir/lib/"
    tar czf "$dir/corpus.tgz" -C build-fuzz corpus seeds ;;
  run)
    seconds=$3 jobs=$4 out=$(realpath -m "$5")
    mkdir -p "$out" /tmp/fuzzrun/findings && tar xzf "$dir/corpus.tgz" -C /tmp/fuzzrun
    source tests/fuzz/fuzz_options.sh
    cd /tmp/fuzzrun
    LD_LIBRARY_PATH="$dir/lib" "$dir/fuzz_readers" corpus seeds -fork="$jobs" -max_total_time="$seconds" "${FUZZ_LIMITS[@]}" \
      -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 >"$out/fuzz.log" 2>&1 || true
    grep -E '^#[0-9]+:' "$out/fuzz.log" | tail -3
    grep -E 'INFO: exiting|ERROR|SUMMARY' "$out/fuzz.log" | tail -5
    ls findings | head; tar czf "$out/findings.tgz" findings ;;
esac
