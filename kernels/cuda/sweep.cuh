#pragma once
// CUDA broad phase sweep: Baraff's sort and sweep (the host's host/sweep.cpp). The boxes' lower faces
// along the axis (orderable bits) → CUB radix sort of (face, body) → the spheres gathered into that
// order → per sorted body a warp sweeps the later ones, 32 at a time, while their lower face is at most
// its upper face (the boxes that start before it ends), testing those whose boxes overlap: count →
// scan → fill (broad.cuh), the candidates in ws.pairs.
#include <cub/device/device_radix_sort.cuh>

#include "cuda/broad.cuh"
#include "cuda/pair_estimate.cuh"

namespace cg::cuda {

template <class Real, class Bits>
__global__ void __launch_bounds__(kBlock)
    sweep_keys_kernel(const Sphere<Real>* __restrict__ spheres, std::uint32_t n, int axis,
                      Bits* __restrict__ keys, std::uint32_t* __restrict__ index) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= n) return;
  const Sphere<Real> s = spheres[i];
  keys[i] = orderable_bits(axis_of(s, axis) - box_radius(s.r));
  index[i] = i;
}

// The sweep of sorted place k by one warp (kBlock / 32 places a block). kFill false: counts[k] and the
// totals of pairs and tests into c; true: the pairs written from offsets[k] (warp-compacted).
template <bool kFill, class Real, class Test>
__global__ void __launch_bounds__(kBlock)
    sweep_kernel(const Sphere<Real>* __restrict__ sorted, const std::uint32_t* __restrict__ index,
                 std::uint32_t n, int axis, const std::uint8_t* __restrict__ report,
                 std::uint32_t* __restrict__ counts, const std::uint32_t* __restrict__ offsets,
                 std::uint32_t* __restrict__ pair_a, std::uint32_t* __restrict__ pair_b,
                 Counters* __restrict__ c, Test test) {
  constexpr unsigned kAll = 0xffffffffu;
  const std::uint32_t k = (blockIdx.x * kBlock + threadIdx.x) / 32u, lane = threadIdx.x & 31u;
  if (k >= n) return;  // (the whole warp)
  const Sphere<Real> sa = sorted[k];
  const std::uint32_t a = index[k];
  const Real end = axis_of(sa, axis) + box_radius(sa.r);
  std::uint64_t w = kFill ? offsets[k] : 0;
  std::uint32_t tests = 0;
  for (std::uint32_t base = k + 1; base < n; base += 32u) {
    const std::uint32_t l = base + lane;
    bool in = false, hit = false;
    if (l < n) {
      const Sphere<Real> sb = sorted[l];
      in = axis_of(sb, axis) - box_radius(sb.r) <= end;
      if (in) {
        const std::uint32_t b = index[l];
        if (boxes_overlap(sa, sb) && pair_reported(report, a, b)) {
          ++tests;
          hit = test(sa, sb, a, b);
        }
      }
    }
    const unsigned hits = __ballot_sync(kAll, hit);
    if constexpr (kFill)
      if (hit) store_pair(pair_a, pair_b, w + __popc(hits & ((1u << lane) - 1u)), a, index[l]);
    w += __popc(hits);
    if (__ballot_sync(kAll, in) != kAll) break;  // a lane past the end: every later place too
  }
  if constexpr (!kFill) {
    const std::uint32_t warp_tests = __reduce_add_sync(kAll, tests);
    if (lane == 0) {
      counts[k] = static_cast<std::uint32_t>(w);
      if (w) atomicAdd(&c->pairs, static_cast<unsigned long long>(w));
      if (warp_tests) atomicAdd(&c->tests, static_cast<unsigned long long>(warp_tests));
    }
  }
}

// The boxes the sweep of sorted place k passes (the later ones that start before its box ends: a
// bound of its tests), as a CellWork (tests, largest) for the estimate's reduction.
template <class Real, class Bits>
struct SweepOverlaps {
  const Sphere<Real>* sorted;
  const Bits* keys;  // the sorted lower faces' orderable bits
  std::uint32_t n;
  int axis;
  __host__ __device__ CellWork operator()(std::uint32_t k) const {
    const Sphere<Real> s = sorted[k];
    const Bits end = orderable_bits(axis_of(s, axis) + box_radius(s.r));
    std::uint32_t lo = k + 1, hi = n;  // the first later place whose lower face is above the end
    while (lo < hi) {
      const std::uint32_t mid = lo + (hi - lo) / 2;
      if (keys[mid] <= end)
        lo = mid + 1;
      else
        hi = mid;
    }
    const unsigned long long m = lo - k - 1;
    return {m, m};
  }
};

}  // namespace cg::cuda

namespace cg::detail {

// The sweep's pair estimate (pair_estimate.hpp; the host's host::sweep_estimate) after its sort: one
// reduction and one wait; check_pair_estimate may refuse the scene before the sweep runs.
template <class Real, class Key, class Narrow, class Bits>
void sweep_estimate_stage(RunState<Real, Key, Narrow>& r, const Sphere<Real>* sorted, const Bits* keys,
                          int axis) {
  PairEstimate e{0, r.n64, r.n64, 0, kDevicePairTestsPerSecond};
  if (r.n > 1)
    add_cell_work(r,
                  thrust::make_transform_iterator(thrust::counting_iterator<std::uint32_t>(0),
                                                  cuda::SweepOverlaps<Real, Bits>{sorted, keys, r.n, axis}),
                  r.n, e);
  check_pair_estimate(e, r.job.pair_limits);
  r.pair_progress = follows_progress(e, r.job.pair_limits);
}

// BroadPhase::sweep, after pack (spheres only): stages sort and pairs (see the file comment).
template <class Real, class Key, class Narrow>
void sweep_stages(RunState<Real, Key, Narrow>& r) {
  using cuda::kBlock;
  using Bits = decltype(orderable_bits(Real(0)));
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  const std::uint32_t n = r.n;
  const int axis = r.job.sweep_axis;
  broad_input(r);
  r.read_counters();  // the bad-data status
  check_packed(r);
  ws.reserve({{&ws.keys[0], r.n64 * sizeof(Bits)},
              {&ws.keys[1], r.n64 * sizeof(Bits)},
              {&ws.bodies[0], r.n64 * sizeof(std::uint32_t)},
              {&ws.bodies[1], r.n64 * sizeof(std::uint32_t)},
              {&ws.broad_pairs, r.n64 * sizeof(Sphere<Real>)}},
             "sort");
  cub::DoubleBuffer<Bits> keys(ws.keys[0].span_as<Bits>(n).data(), ws.keys[1].span_as<Bits>(n).data());
  cub::DoubleBuffer<std::uint32_t> index = ws.home_index(n);
  Sphere<Real>* sorted = ws.broad_pairs.span_as<Sphere<Real>>(n).data();
  cuda::sweep_keys_kernel<Real, Bits>
      <<<r.nb, kBlock, 0, st>>>(r.d_cell_spheres, n, axis, keys.Current(), index.Current());
  CG_CUDA_CHECK_LAUNCH("sweep_keys");
  cub_run(ws, "sort", [&](void* t, std::size_t& b) {
    return cub::DeviceRadixSort::SortPairs(t, b, keys, index, int(n), 0, int(8 * sizeof(Bits)), st);
  });
  cuda::gather_kernel<Sphere<Real>><<<r.nb, kBlock, 0, st>>>(r.d_cell_spheres, index.Current(), n, sorted);
  CG_CUDA_CHECK_LAUNCH("sweep_gather");
  r.events.mark(EngineStage::sort, st);
  if (r.job.pair_limits.wanted()) sweep_estimate_stage(r, sorted, keys.Current(), axis);

  const std::uint32_t warps = cuda::blocks_for(32 * r.n64);
  const ItemCounts ic = item_counts(ws, r.n64);
  zero_pair_counters(r);
  with_pair_test(r, [&](auto test) {
    cuda::sweep_kernel<false, Real, decltype(test)>
        <<<warps, kBlock, 0, st>>>(sorted, index.Current(), n, axis, r.d_report, ic.counts, nullptr, nullptr,
                                   nullptr, r.d_counters, test);
  });
  CG_CUDA_CHECK_LAUNCH("sweep_count");
  r.read_counters();
  r.stats.pair_tests = r.h_counters->tests;
  std::uint32_t* store = candidate_store(r, ic, r.n64, ws.pairs, r.h_counters->pairs);
  if (r.np > 0) {
    with_pair_test(r, [&](auto test) {
      cuda::sweep_kernel<true, Real, decltype(test)>
          <<<warps, kBlock, 0, st>>>(sorted, index.Current(), n, axis, r.d_report, nullptr, ic.offsets, store,
                                     store + r.np, r.d_counters, test);
    });
    CG_CUDA_CHECK_LAUNCH("sweep_fill");
  }
  r.events.mark(EngineStage::pairs, st);
}

}  // namespace cg::detail
