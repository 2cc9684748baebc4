#pragma once
// Stable LSD radix sort of (key, value) pairs on the host, over the low `bits` bits of the key only
// (Le Grand's sort: a cell key needs far fewer bits than its type). Digits of up to 11 bits, so a
// 27-bit key takes 3 passes. Multi-threaded: per-thread histograms, then a scatter whose order
// (digit, thread, position) keeps the sort stable and the result independent of the thread count.
#include <algorithm>
#include <cstdint>
#include <vector>

namespace cg::detail {

struct NoValues {};

// Sorts keys (and values alongside) by the low `bits` bits of the key; `threads` 0: all. Defined in
// radix_sort.cpp (compiled with OpenMP) for Key = uint32_t, uint64_t and Value = uint32_t, NoValues.
template <class Key, class Value>
void radix_sort(std::vector<Key>& keys, std::vector<Value>& values, int bits, int threads);

template <class Key>
void radix_sort_keys(std::vector<Key>& keys, int bits, int threads) {
  std::vector<NoValues> none;
  radix_sort(keys, none, bits, threads);
}

}  // namespace cg::detail
