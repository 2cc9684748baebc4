#pragma once
// CUDA stage order: the candidate pairs in (a, b) order. Grouped by a with a counting sort over the
// bodies (count → scan → scatter; the two dead key buffers of the entry sort hold the counts and the
// offsets: ws.a_counts / a_offsets) while those counters stay in half the L2 (there it beats the radix
// sort), else by a radix sort of (a, b) by a (the counters' random atomics in DRAM cost several times
// the sort; BENCHMARKS.md §3); Tuning::counting_order forces one. Then each run of
// equal a is sorted by b (sort_runs_kernel).
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// order, first step: a counting sort by a. count_a: count[a] of each pair (count zeroed); after an
// exclusive scan of the counts into offset, scatter_a writes each pair at offset[a]++ (grouped by a,
// in any order within a group).
__global__ void __launch_bounds__(kBlock)
    count_a_kernel(const std::uint32_t* __restrict__ pair_a, std::uint32_t n_pairs, std::uint32_t* count) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k < n_pairs) atomicAdd(&count[pair_a[k]], 1u);
}

__global__ void __launch_bounds__(kBlock)
    scatter_a_kernel(const std::uint32_t* __restrict__ a_in, const std::uint32_t* __restrict__ b_in,
                     std::uint32_t n_pairs, std::uint32_t* offset, std::uint32_t* __restrict__ a_out,
                     std::uint32_t* __restrict__ b_out) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = a_in[k];
  const std::uint32_t w = atomicAdd(&offset[a], 1u);
  a_out[w] = a;
  b_out[w] = b_in[k];
}

// order, second step: each run of equal a is put in b order by its first thread (insertion sort;
// runs are a body's contacts, short). Pairs are distinct, so the result is the (a, b) order of the
// host's sort of a << id_bits | b, whatever the order within the runs before.
__global__ void __launch_bounds__(kBlock)
    sort_runs_kernel(const std::uint32_t* __restrict__ pair_a, std::uint32_t* __restrict__ pair_b,
                     std::uint32_t n_pairs) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = pair_a[k];
  if (k > 0 && pair_a[k - 1] == a) return;  // not the first of its run
  std::uint32_t end = k + 1;
  while (end < n_pairs && pair_a[end] == a) ++end;
  for (std::uint32_t i = k + 1; i < end; ++i) {
    const std::uint32_t v = pair_b[i];
    std::uint32_t j = i;
    for (; j > k && pair_b[j - 1] > v; --j) pair_b[j] = pair_b[j - 1];
    pair_b[j] = v;
  }
}

}  // namespace cg::cuda

namespace cg::detail {

template <class Real, class Key, class Narrow>
void order_stage(RunState<Real, Key, Narrow>& r) {
  using cuda::blocks_for;
  using cuda::kBlock;
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  const std::uint32_t np = r.np, n = r.n;
  const bool counting_order = tuned(r.tuning.counting_order, r.n64 * sizeof(std::uint32_t) <= r.l2_bytes / 2);
  if (np > 1 && !counting_order) {
    const int id_bits = std::max(1, bits_for(r.n64));
    cub_run(ws, "order", [&](void* t, std::size_t& b) {
      return cub::DeviceRadixSort::SortPairs(t, b, r.pair_a, r.pair_b, int(np), 0, id_bits, st);
    });
  } else if (np > 1) {
    std::uint32_t* d_a_count = ws.a_counts(n);  // n <= entries: the buffers hold n u32
    std::uint32_t* d_a_offset = ws.a_offsets(n);
    CG_CUDA_CHECK(cudaMemsetAsync(d_a_count, 0, r.n64 * sizeof(std::uint32_t), st));
    cuda::count_a_kernel<<<blocks_for(np), kBlock, 0, st>>>(r.pair_a.Current(), np, d_a_count);
    CG_CUDA_CHECK_LAUNCH("count_a");
    cub_run(ws, "order", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, d_a_count, d_a_offset, int(n), st);
    });
    cuda::scatter_a_kernel<<<blocks_for(np), kBlock, 0, st>>>(
        r.pair_a.Current(), r.pair_b.Current(), np, d_a_offset, r.pair_a.Alternate(), r.pair_b.Alternate());
    CG_CUDA_CHECK_LAUNCH("scatter_a");
    r.pair_a.selector ^= 1;
    r.pair_b.selector ^= 1;
  }
  if (np > 1) {
    cuda::sort_runs_kernel<<<blocks_for(np), kBlock, 0, st>>>(r.pair_a.Current(), r.pair_b.Current(), np);
    CG_CUDA_CHECK_LAUNCH("sort_runs");
  }
  r.events.mark(EngineStage::order, st);
}

}  // namespace cg::detail
