// The host's streaming bandwidth, for the floor column of BENCHMARKS.md §2 (not a test): a STREAM-like
// copy b[i] = a[i] and a read-only sum of arrays far larger than the caches, split statically over
// THREADS OpenMP threads (each thread touches its own part first), best of REPETITIONS. Copy counts
// the bytes read and written (2 × size), sum the bytes read.
//   host_bandwidth [THREADS=2] [MIB=512] [REPETITIONS=10]
// Prints: threads, MiB per array, copy GB/s, read GB/s.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

int main(int argc, char** argv) {
  const int threads = argc > 1 ? std::atoi(argv[1]) : 2;
  const std::size_t mib = argc > 2 ? std::strtoull(argv[2], nullptr, 10) : 512;
  const int repetitions = argc > 3 ? std::atoi(argv[3]) : 10;
  const std::size_t n = mib * (std::size_t(1) << 20) / sizeof(std::uint64_t);
  auto* a = static_cast<std::uint64_t*>(std::malloc(n * sizeof(std::uint64_t)));
  auto* b = static_cast<std::uint64_t*>(std::malloc(n * sizeof(std::uint64_t)));
  if (!a || !b) return 1;
#pragma omp parallel for num_threads(threads) schedule(static)
  for (std::size_t i = 0; i < n; ++i) {
    a[i] = i & 1023;
    b[i] = 0;
  }
  double best_copy = 1e30, best_read = 1e30;
  std::uint64_t sink = 0;
  for (int r = 0; r < repetitions; ++r) {
    auto t0 = std::chrono::steady_clock::now();
#pragma omp parallel for num_threads(threads) schedule(static)
    for (std::size_t i = 0; i < n; ++i) b[i] = a[i];
    auto t1 = std::chrono::steady_clock::now();
    std::uint64_t s = 0;  // integer sum: vectorised, so the loads and not the adds set the pace
#pragma omp parallel for num_threads(threads) schedule(static) reduction(+ : s)
    for (std::size_t i = 0; i < n; ++i) s += b[i];
    auto t2 = std::chrono::steady_clock::now();
    sink += s;
    best_copy = std::min(best_copy, std::chrono::duration<double>(t1 - t0).count());
    best_read = std::min(best_read, std::chrono::duration<double>(t2 - t1).count());
  }
  const double bytes = double(n * sizeof(std::uint64_t));
  std::printf("threads %d MiB %zu copy_GBps %.2f read_GBps %.2f (%d)\n", threads, mib,
              2 * bytes / best_copy / 1e9, bytes / best_read / 1e9, int(sink & 1));
  std::free(a);
  std::free(b);
  return 0;
}
