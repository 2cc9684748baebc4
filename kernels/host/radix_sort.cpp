// Stable LSD radix sort of the CPU backend (see radix_sort.hpp). Kept out of the header so that every
// caller uses this one OpenMP-compiled definition (a template instantiated in a TU built without
// OpenMP would silently sort only the first thread's chunk).
#include "host/radix_sort.hpp"

#include <omp.h>

#include <algorithm>
#include <type_traits>

namespace cg::detail {

template <class Key, class Value>
bool radix_sort_arrays(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, std::size_t n, int bits,
                       int threads) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  if (n < 2 || bits <= 0) return false;
  const int passes = (bits + 10) / 11;
  const int width = (bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << width;
  const Key mask = Key(buckets - 1);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  nt = int(std::max<std::size_t>(1, std::min<std::size_t>(nt, n / 262144 + 1)));

  std::vector<std::size_t> hist(std::size_t(nt) * buckets);
  Key* ksrc = keys;
  Key* kdst = key_tmp;
  Value* vsrc = values;
  Value* vdst = value_tmp;
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * width;
    int team = 1;
#pragma omp parallel num_threads(nt)
    {
      // The runtime may give fewer threads than asked: chunks follow the actual team size.
#pragma omp single
      team = omp_get_num_threads();
      const int t = omp_get_thread_num();
      const std::size_t lo = n * t / team, hi = n * (t + 1) / team;
      std::size_t* h = hist.data() + std::size_t(t) * buckets;
      std::fill(h, h + buckets, 0);
      for (std::size_t i = lo; i < hi; ++i) ++h[(ksrc[i] >> shift) & mask];
#pragma omp barrier
#pragma omp single
      {
        std::size_t sum = 0;
        for (std::size_t d = 0; d < buckets; ++d)
          for (int u = 0; u < team; ++u) {
            std::size_t c = hist[std::size_t(u) * buckets + d];
            hist[std::size_t(u) * buckets + d] = sum;
            sum += c;
          }
      }
      for (std::size_t i = lo; i < hi; ++i) {
        const std::size_t pos = h[(ksrc[i] >> shift) & mask]++;
        kdst[pos] = ksrc[i];
        if constexpr (with_values) vdst[pos] = vsrc[i];
      }
    }
    std::swap(ksrc, kdst);
    if constexpr (with_values) std::swap(vsrc, vdst);
  }
  return ksrc != keys;
}

template bool radix_sort_arrays(std::uint32_t*, std::uint32_t*, std::uint32_t*, std::uint32_t*, std::size_t,
                                int, int);
template bool radix_sort_arrays(std::uint64_t*, std::uint32_t*, std::uint64_t*, std::uint32_t*, std::size_t,
                                int, int);
template bool radix_sort_arrays(std::uint32_t*, NoValues*, std::uint32_t*, NoValues*, std::size_t, int, int);
template bool radix_sort_arrays(std::uint64_t*, NoValues*, std::uint64_t*, NoValues*, std::size_t, int, int);

}  // namespace cg::detail
