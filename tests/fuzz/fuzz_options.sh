# The libFuzzer options of the long fuzz job, sourced by tests/fuzz/build_and_run.sh (this machine)
# and jobs/fuzz_elsewhere.sh (a many-core host), so that every recorded run fuzzes under the same limits.
# allocator_may_return_null: HDF5 sizes some buffers from the file (H5C_protect) and handles a failed
# malloc as an error; ASan would abort instead of returning null, and spend seconds on the
# gigabytes a damaged size asks for (the contactgrid binary gets them as untouched virtual memory).
export ASAN_OPTIONS=detect_leaks=0:allocator_may_return_null=1:max_allocation_size_mb=2048
FUZZ_LIMITS=(-timeout=10 -rss_limit_mb=4096 -malloc_limit_mb=1048576 -max_len=65536
             -artifact_prefix=findings/ -print_final_stats=1)
