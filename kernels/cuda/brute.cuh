#pragma once
// CUDA broad phase brute: every pair, tiled (the host's host/brute.cpp). Tiles of kBlock bodies; block
// (tj, ti), ti <= tj, stages tile tj's spheres in shared memory and each of its threads tests its body
// of tile ti against them (b > a, overlapping boxes): count → scan → fill (broad.cuh), the candidates
// in ws.pairs. Blocks with tj < ti exit at once (and count 0).
#include "cuda/broad.cuh"

namespace cg::cuda {

// kFill false: counts[ti · tiles + tj] and the totals of pairs and tests into c; true: the pairs
// written from offsets[ti · tiles + tj] (a shared cursor: any order within the tile pair).
template <bool kFill, class Real, class Test>
__global__ void __launch_bounds__(kBlock)
    brute_kernel(const Sphere<Real>* __restrict__ spheres, const std::uint8_t* __restrict__ report,
                 std::uint32_t n, std::uint32_t tiles, std::uint32_t* __restrict__ counts,
                 const std::uint32_t* __restrict__ offsets, std::uint32_t* __restrict__ pair_a,
                 std::uint32_t* __restrict__ pair_b, Counters* __restrict__ c, Test test) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  __shared__ Sphere<Real> s_b[kBlock];
  __shared__ unsigned long long s_cursor;
  const std::uint32_t ti = blockIdx.y, tj = blockIdx.x;
  const std::uint64_t item = std::uint64_t(ti) * tiles + tj;
  if (tj < ti) {
    if (!kFill && threadIdx.x == 0) counts[item] = 0;
    return;  // (the whole block)
  }
  const std::uint32_t b0 = tj * kBlock, a = ti * kBlock + threadIdx.x;
  if (b0 + threadIdx.x < n) s_b[threadIdx.x] = spheres[b0 + threadIdx.x];
  if (kFill && threadIdx.x == 0) s_cursor = offsets[item];
  __syncthreads();
  std::uint32_t found = 0, tests = 0;
  if (a < n) {
    const Sphere<Real> sa = spheres[a];
    const std::uint32_t first = a + 1 > b0 ? a + 1 - b0 : 0, last = n - b0 < kBlock ? n - b0 : kBlock;
    for (std::uint32_t j = first; j < last; ++j) {
      const Sphere<Real> sb = s_b[j];
      const std::uint32_t b = b0 + j;
      if (!boxes_overlap(sa, sb) || !pair_reported(report, a, b)) continue;
      ++tests;
      if (test(sa, sb, a, b)) {
        if constexpr (kFill) store_pair(pair_a, pair_b, atomicAdd(&s_cursor, 1ull), a, b);
        ++found;
      }
    }
  }
  if constexpr (!kFill) {
    const unsigned long long block_found = Reduce(tmp).Sum(found);
    __syncthreads();  // tmp is reused
    const unsigned long long block_tests = Reduce(tmp).Sum(tests);
    if (threadIdx.x == 0) {
      counts[item] = static_cast<std::uint32_t>(block_found);
      if (block_found) atomicAdd(&c->pairs, block_found);
      if (block_tests) atomicAdd(&c->tests, block_tests);
    }
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// BroadPhase::brute, after pack (spheres only): stage pairs (see the file comment).
template <class Real, class Key, class Narrow>
void brute_stages(RunState<Real, Key, Narrow>& r) {
  using cuda::kBlock;
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  broad_input(r);
  r.read_counters();  // the bad-data status
  check_packed(r);
  const std::uint32_t tiles = cuda::blocks_for(r.n64);
  const std::uint64_t items = std::uint64_t(tiles) * tiles;
  if (items >= (std::uint64_t(1) << 31))  // (the scan of the tile pairs' counts is one CUB call)
    throw ResourceError("the brute broad phase takes at most 11.8 million bodies on one GPU; use another");
  const dim3 grid(tiles, tiles);
  const ItemCounts ic = item_counts(ws, items);
  zero_pair_counters(r);
  with_pair_test(r, [&](auto test) {
    cuda::brute_kernel<false, Real, decltype(test)><<<grid, kBlock, 0, st>>>(
        r.d_cell_spheres, r.d_report, r.n, tiles, ic.counts, nullptr, nullptr, nullptr, r.d_counters, test);
  });
  CG_CUDA_CHECK_LAUNCH("brute_count");
  r.read_counters();
  r.stats.pair_tests = r.h_counters->tests;
  std::uint32_t* store = candidate_store(r, ic, items, ws.pairs, r.h_counters->pairs);
  if (r.np > 0) {
    with_pair_test(r, [&](auto test) {
      cuda::brute_kernel<true, Real, decltype(test)>
          <<<grid, kBlock, 0, st>>>(r.d_cell_spheres, r.d_report, r.n, tiles, nullptr, ic.offsets, store,
                                    store + r.np, r.d_counters, test);
    });
    CG_CUDA_CHECK_LAUNCH("brute_fill");
  }
  r.events.mark(EngineStage::pairs, st);
}

}  // namespace cg::detail
