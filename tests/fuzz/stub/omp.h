#pragma once
// The libFuzzer build (build_and_run.sh) compiles the readers without OpenMP (clang-14 has no libomp
// on the CI image): one thread, the `#pragma omp` lines ignored.
inline int omp_get_max_threads() { return 1; }
