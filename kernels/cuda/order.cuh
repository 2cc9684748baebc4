#pragma once
// CUDA stage order: the candidate pairs in (a, b) order. Grouped by a with a counting sort over the
// bodies (count → scan → scatter; the two dead key buffers of the entry sort hold the counts and the
// offsets: ws.a_counts / a_offsets) while those counters stay in half the L2 (there it beats the radix
// sort), else by a radix sort of (a, b) by a (the counters' random atomics in DRAM cost several times
// the sort; BENCHMARKS.md §3); Tuning::counting_order forces one. Then each run of
// equal a is sorted by b: a short one (a body's few contacts) by its first thread (sort_runs_kernel),
// a long one (a large body's contacts with the grains of larger index: tens of thousands among
// r = 0.01 grains) by CUB's segmented sort, so that no thread sorts a long run alone (quadratic).
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_segmented_sort.cuh>

#include "core/broad.hpp"
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

// Runs of equal a up to this length are sorted by their first thread; longer ones by the segmented sort.
constexpr std::uint32_t kShortRun = 32;

// order, second step: each run of equal a (pair_a ascending) is put in b order, into `b_out` (the dead
// alternate b buffer). One thread per pair: a pair in a run of at most kShortRun pairs finds its run
// (the neighbours of equal a, in L1), counts the b of its run below its own (pairs are distinct, so
// the counts are the ranks) and writes its b at the run's start + its rank: every thread works, none
// waits on another, and a run is read from DRAM once. A pair of a longer run copies its b unchanged,
// and the run's first pair lists it for the segmented sort: [run_begin[s], run_end[s]) at s = an
// atomic cursor c->long_runs (its end found by a binary search, not a walk). The result is the (a, b)
// order of the host's sort of a << id_bits | b, whatever the order within the runs before.
__global__ void __launch_bounds__(kBlock)
    sort_runs_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                     std::uint32_t n_pairs, std::uint32_t* __restrict__ b_out,
                     std::uint32_t* __restrict__ run_begin, std::uint32_t* __restrict__ run_end,
                     Counters* __restrict__ c) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = pair_a[k], b = pair_b[k];
  // the run around k, each side walked no further than tells a long run from a short one
  std::uint32_t start = k, end = k + 1;
  while (start > 0 && pair_a[start - 1] == a && k - start <= kShortRun) --start;
  while (end < n_pairs && pair_a[end] == a && end - start <= kShortRun) ++end;
  if (end - start > kShortRun) {  // a long run: b as it is, and the run's first pair lists the run
    b_out[k] = b;
    if (k > 0 && pair_a[k - 1] == a) return;
    const std::uint32_t run_stop = lower_bound_key(pair_a, k + 1, n_pairs, a + 1u);
    const auto s = static_cast<std::uint32_t>(atomicAdd(&c->long_runs, 1ull));
    run_begin[s] = k;
    run_end[s] = run_stop;
    return;
  }
  std::uint32_t rank = 0;
  for (std::uint32_t i = start; i < end; ++i) rank += pair_b[i] < b ? 1u : 0u;
  b_out[start + rank] = b;
}

// order, the long runs: each block copies its run of the segmented sort's output back.
__global__ void __launch_bounds__(kBlock)
    copy_runs_kernel(const std::uint32_t* __restrict__ sorted, std::uint32_t* __restrict__ pair_b,
                     const std::uint32_t* __restrict__ run_begin, const std::uint32_t* __restrict__ run_end) {
  for (std::uint32_t i = run_begin[blockIdx.x] + threadIdx.x, end = run_end[blockIdx.x]; i < end; i += kBlock)
    pair_b[i] = sorted[i];
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
    // the long runs' list in the dead alternate a buffer (at most np / (kShortRun + 1) runs: begins in
    // its first half, ends in its second); sort_runs writes into the alternate b buffer, which becomes
    // the current one, and the segmented sort of the long runs into the other, copied back
    std::uint32_t* run_begin = r.pair_a.Alternate();
    std::uint32_t* run_end = run_begin + np / 2;
    unsigned long long* d_long = &r.d_counters->long_runs;
    unsigned long long* h_long = &r.h_counters->long_runs;
    CG_CUDA_CHECK(cudaMemsetAsync(d_long, 0, sizeof *d_long, st));
    cuda::sort_runs_kernel<<<blocks_for(np), kBlock, 0, st>>>(
        r.pair_a.Current(), r.pair_b.Current(), np, r.pair_b.Alternate(), run_begin, run_end, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("sort_runs");
    r.pair_b.selector ^= 1;  // the short runs sorted, the long ones as they were
    CG_CUDA_CHECK(cudaMemcpyAsync(h_long, d_long, sizeof *h_long, cudaMemcpyDeviceToHost, st));
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    const std::uint64_t long_runs = *h_long;
    if (long_runs > 0) {
      cub_run(ws, "order", [&](void* t, std::size_t& b) {
        return cub::DeviceSegmentedSort::SortKeys(t, b, r.pair_b.Current(), r.pair_b.Alternate(),
                                                  std::int64_t(np), std::int64_t(long_runs), run_begin,
                                                  run_end, st);
      });
      cuda::copy_runs_kernel<<<static_cast<unsigned>(long_runs), kBlock, 0, st>>>(
          r.pair_b.Alternate(), r.pair_b.Current(), run_begin, run_end);
      CG_CUDA_CHECK_LAUNCH("copy_runs");
    }
  }
  r.events.mark(EngineStage::order, st);
}

}  // namespace cg::detail
