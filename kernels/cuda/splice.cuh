#pragma once
// Engine::splice_resident on the DEVICE rows (splice_rows.hpp is the host's): rows `leaving` (strictly
// ascending) removed and arrival j inserted before old row at[j] (non-decreasing). One thread a row:
// a row that stays goes to its index less the leaving rows before it plus the arrivals placed at or
// before it; arrival j to at[j] less the leaving rows before at[j] plus j. The leaving rows and the
// places are few (the bodies that crossed a cut): two binary searches a row, in L2.
#include <cstddef>
#include <cstdint>

#include "cuda/common.cuh"

namespace cg::cuda {

// The first index of sorted `v[0 … n)` whose value is not below x (upper: above x).
__device__ __forceinline__ std::size_t splice_bound(const std::uint64_t* v, std::size_t n, std::uint64_t x,
                                                    bool upper) {
  std::size_t lo = 0, hi = n;
  while (lo < hi) {
    const std::size_t mid = (lo + hi) / 2;
    if (upper ? v[mid] <= x : v[mid] < x)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

// Rows of `words` T each: n old rows `from`, m `arrivals`, into `into` (n - l + m rows).
template <class T>
__global__ void __launch_bounds__(kBlock)
    splice_kernel(const T* __restrict__ from, std::size_t n, const T* __restrict__ arrivals, std::size_t m,
                  const std::uint64_t* __restrict__ leaving, std::size_t l,
                  const std::uint64_t* __restrict__ at, std::size_t words, T* __restrict__ into) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  const T* src;
  std::size_t dst;
  if (k < n) {
    const std::size_t gone = splice_bound(leaving, l, k, false);
    if (gone < l && leaving[gone] == k) return;
    dst = k - gone + splice_bound(at, m, k, true);
    src = from + k * words;
  } else if (k < n + m) {
    const std::size_t j = k - n;
    dst = at[j] - splice_bound(leaving, l, at[j], false) + j;
    src = arrivals + j * words;
  } else {
    return;
  }
  for (std::size_t w = 0; w < words; ++w) into[dst * words + w] = src[w];
}

}  // namespace cg::cuda
