#pragma once
// Stable LSD radix sort of (key, value) pairs on the host, over the low `bits` bits of the key only
// (Le Grand's sort: a cell key needs far fewer bits than its type). Digits of up to 11 bits, so a
// 27-bit key takes 3 passes. Multi-threaded: per-thread histograms, then a scatter whose order
// (digit, thread, position) keeps the sort stable and the result independent of the thread count.
#include <omp.h>

#include <algorithm>
#include <cstdint>
#include <vector>

namespace cg::detail {

struct NoValues {};

template <class Key, class Value>
void radix_sort(std::vector<Key>& keys, std::vector<Value>& values, int bits, int threads) {
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  const std::size_t n = keys.size();
  if (n < 2 || bits <= 0) return;
  const int passes = (bits + 10) / 11;
  const int width = (bits + passes - 1) / passes;
  const std::size_t buckets = std::size_t(1) << width;
  const Key mask = Key(buckets - 1);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  nt = int(std::max<std::size_t>(1, std::min<std::size_t>(nt, n / 262144 + 1)));

  std::vector<Key> k2(n);
  std::vector<Value> v2;
  if constexpr (with_values) v2.resize(n);
  std::vector<std::size_t> hist(std::size_t(nt) * buckets);
  Key* ksrc = keys.data();
  Key* kdst = k2.data();
  Value* vsrc = nullptr;
  Value* vdst = nullptr;
  if constexpr (with_values) {
    vsrc = values.data();
    vdst = v2.data();
  }
  for (int pass = 0; pass < passes; ++pass) {
    const int shift = pass * width;
#pragma omp parallel num_threads(nt)
    {
      const int t = omp_get_thread_num();
      const std::size_t lo = n * t / nt, hi = n * (t + 1) / nt;
      std::size_t* h = hist.data() + std::size_t(t) * buckets;
      std::fill(h, h + buckets, 0);
      for (std::size_t i = lo; i < hi; ++i) ++h[(ksrc[i] >> shift) & mask];
#pragma omp barrier
#pragma omp single
      {
        std::size_t sum = 0;
        for (std::size_t d = 0; d < buckets; ++d)
          for (int u = 0; u < nt; ++u) {
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
  if (ksrc != keys.data()) {
    keys.swap(k2);
    if constexpr (with_values) values.swap(v2);
  }
}

template <class Key>
void radix_sort_keys(std::vector<Key>& keys, int bits, int threads) {
  std::vector<NoValues> none;
  radix_sort(keys, none, bits, threads);
}

}  // namespace cg::detail
