#pragma once
// Stable radix sort of (key, value) pairs on the host, over the low `bits` bits of the key only
// (Le Grand's sort: a cell key needs far fewer bits than its type). Multi-threaded: per-thread
// histograms, then a scatter whose order (digit, thread, position) keeps the sort stable and the
// result independent of the thread count. From 2^17 elements the top digit goes first (one scatter
// into at most 256 buckets, then each bucket's low bits by LSD passes in the cache, a bucket a
// thread), unless a bucket holds more than a sixteenth of the keys; otherwise LSD passes of up to
// 11 bits over the whole array (a 27-bit key: 3 passes). A stable sort's result is unique: both give
// the same bytes. CONTACTGRID_HOST_SORT=lsd: the LSD passes always (a measurement switch).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <type_traits>
#include <vector>

#include "host/scratch_pool.hpp"

namespace cg::detail {

struct NoValues {};

// The sort on arrays: keys[0, n) (and values alongside, unless Value is NoValues) by the low `bits`
// bits of the key; key_tmp and value_tmp hold n elements of scratch. Returns true when the sorted
// arrays end in the scratch (an odd number of passes). `threads` 0: all. Defined in radix_sort.cpp
// (compiled with OpenMP) for Key = uint32_t, uint64_t and Value = uint32_t, NoValues.
template <class Key, class Value>
bool radix_sort_arrays(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, std::size_t n, int bits,
                       int threads);

// The top-digit-first sort's second half, for a caller that made its first (host/entries.cpp writes
// the entries by the top digit of their key): bucket d = [start[d], start[d + 1]) of keys (values
// alongside), d = 0 … buckets − 1, holds the keys whose bits above `shift` make digit d, in stable
// order; each bucket is sorted by its low `shift` bits (LSD passes in the cache, a bucket a thread).
// key_tmp and value_tmp hold start[buckets] elements of scratch. Returns true when the sorted arrays
// end in the scratch. Defined for Key = uint32_t, uint64_t and Value = uint32_t.
template <class Key, class Value>
bool radix_sort_buckets(Key* keys, Value* values, Key* key_tmp, Value* value_tmp, const std::size_t* start,
                        std::size_t buckets, int shift, int threads);

// The sort on vectors (std::vector or the stages' host::Array): the scratch is an Array (pooled, no
// zero sweep: host/scratch_pool.hpp); the result is swapped in where the types allow, else copied back.
template <class KeyVector, class ValueVector>
void radix_sort(KeyVector& keys, ValueVector& values, int bits, int threads) {
  using Key = typename KeyVector::value_type;
  using Value = typename ValueVector::value_type;
  constexpr bool with_values = !std::is_same_v<Value, NoValues>;
  const std::size_t n = keys.size();
  if (n < 2 || bits <= 0) return;
  host::Array<Key> key_tmp(n);
  host::Array<Value> value_tmp(with_values ? n : 0);
  if (!radix_sort_arrays(keys.data(), with_values ? values.data() : nullptr, key_tmp.data(),
                         with_values ? value_tmp.data() : nullptr, n, bits, threads))
    return;
  if constexpr (std::is_same_v<KeyVector, host::Array<Key>>)
    keys.swap(key_tmp);
  else
    std::memcpy(keys.data(), key_tmp.data(), n * sizeof(Key));
  if constexpr (with_values) {
    if constexpr (std::is_same_v<ValueVector, host::Array<Value>>)
      values.swap(value_tmp);
    else
      std::memcpy(values.data(), value_tmp.data(), n * sizeof(Value));
  }
}

template <class KeyVector>
void radix_sort_keys(KeyVector& keys, int bits, int threads) {
  std::vector<NoValues> none;
  radix_sort(keys, none, bits, threads);
}

}  // namespace cg::detail
