#pragma once
// What the CUDA broad phases other than the grid share (levels.cuh, sweep.cuh, brute.cuh;
// broad_phase.hpp): their input — pack's spheres in input order (no renumbering: they read the bodies
// by input index), inflated by a skin, and in centre-cut scenes the cut shapes — and the count → scan →
// fill of their candidates: a count kernel writes each item's candidates to broad_counts and adds the
// totals of candidates and tests to the counters, the host reads the total (one synchronisation),
// the counts are scanned, a fill kernel writes each item's candidates (input indices a < b) from its
// offset, in any order within the item (the order stage sorts them).
#include <cstddef>
#include <cub/device/device_scan.cuh>

#include "core/broad.hpp"
#include "core/centre_cut.hpp"
#include "cuda/common.cuh"
#include "cuda/pack.cuh"
#include "cuda/pairs.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// The pair stage's spheres (input order, radius + a skin's inflation; out null: pack's are those) and
// the cut shapes of the centre cut (cut null: none), from pack's spheres and packed shapes.
template <class Real, class Packed>
__global__ void __launch_bounds__(kBlock)
    broad_input_kernel(const Sphere<Real>* __restrict__ spheres, std::uint32_t n, Real inflation,
                       Sphere<Real>* __restrict__ out, const PackedShape<Packed>* __restrict__ shapes,
                       CutShape* __restrict__ cut) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= n) return;
  if (out) {
    Sphere<Real> s = spheres[i];
    s.r += inflation;
    out[i] = s;
  }
  if (cut) cut[i] = cut_shape(shapes[i]);
}

// A candidate (a, b) of input indices as the order stage takes it: a < b.
__device__ __forceinline__ void store_pair(std::uint32_t* __restrict__ pair_a,
                                           std::uint32_t* __restrict__ pair_b, std::uint64_t w,
                                           std::uint32_t a, std::uint32_t b) {
  pair_a[w] = a < b ? a : b;
  pair_b[w] = a < b ? b : a;
}

}  // namespace cg::cuda

namespace cg::detail {

// After pack (spheres only, input order): the pair stage's spheres and cut shapes (r.d_cell_spheres,
// r.d_cell_cut, both in input order; r.pair_perm() null). The bad-body check comes with the broad
// phase's first read of the counters (check_packed).
template <class Real, class Key, class Narrow>
void broad_input(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  r.renumbered = false;
  r.d_perm = nullptr;  // input order: Fp64Touch maps nothing
  const bool inflate = r.job.inflation != 0;
  r.d_cell_spheres = inflate ? ws.cell_spheres.span_as<Sphere<Real>>(r.n).data() : r.d_spheres;
  r.d_cell_cut = nullptr;
  if (r.filter == CandidateFilter::centre_cut) {
    ws.reserve({{&ws.cell_cut, r.n64 * sizeof(CutShape)}}, "pack");
    r.d_cell_cut = ws.cell_cut.span_as<CutShape>(r.n).data();
  }
  if (inflate || r.d_cell_cut)
    cuda::broad_input_kernel<Real, Narrow>
        <<<r.nb, cuda::kBlock, 0, r.st>>>(r.d_spheres, r.n, static_cast<Real>(r.job.inflation),
                                          inflate ? r.d_cell_spheres : nullptr, r.d_shapes, r.d_cell_cut);
  CG_CUDA_CHECK_LAUNCH("broad_input");
}

// Per-item counts and their exclusive scan in ws.broad_counts (items u32 each, then `extra` u32).
struct ItemCounts {
  std::uint32_t* counts;
  std::uint32_t* offsets;
  std::uint32_t* extra;
};
inline ItemCounts item_counts(Workspace& ws, std::uint64_t items, std::size_t extra = 0) {
  ws.reserve({{&ws.broad_counts, (2 * items + extra) * sizeof(std::uint32_t)}}, "pairs");
  std::uint32_t* p = ws.broad_counts.span_as<std::uint32_t>(2 * items + extra).data();
  return {p, p + items, p + 2 * items};
}

// The counters' candidate and test totals set to 0 (before a count kernel adds to them).
template <class Real, class Key, class Narrow>
void zero_pair_counters(RunState<Real, Key, Narrow>& r) {
  static_assert(offsetof(cuda::Counters, tests) ==
                offsetof(cuda::Counters, pairs) + sizeof(unsigned long long));
  CG_CUDA_CHECK(cudaMemsetAsync(&r.d_counters->pairs, 0, 2 * sizeof(unsigned long long), r.st));
}

// The scan of the counts (offsets), and `buffer` made the candidates' store of np pairs: four u32
// arrays (a, b, and the order sort's second copies) as r.pair_a / r.pair_b, r.np = np, and the
// contact rows' room.
template <class Real, class Key, class Narrow>
std::uint32_t* candidate_store(RunState<Real, Key, Narrow>& r, const ItemCounts& ic, std::uint64_t items,
                               cuda::DeviceBuffer<std::byte>& buffer, std::uint64_t np) {
  check_pairs(np);
  Workspace& ws = r.ws;
  ws.reserve({{&buffer, 4 * np * sizeof(std::uint32_t)}, {&ws.out, r.out_bytes_for(np)}}, "pairs");
  if (items > 0)
    cub_run(ws, "pairs", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, ic.counts, ic.offsets, int(items), r.st);
    });
  std::uint32_t* store = buffer.span_as<std::uint32_t>(4 * np).data();
  r.pair_a = cub::DoubleBuffer<std::uint32_t>(store, store + 2 * np);
  r.pair_b = cub::DoubleBuffer<std::uint32_t>(store + np, store + 3 * np);
  r.np = static_cast<std::uint32_t>(np);
  return store;
}

}  // namespace cg::detail
