#pragma once
// CUDA broad phase levels: a hierarchy of grids (core/broad.hpp; the host's host/levels.cpp). Per
// body its level and the key of its lowest cell in that level's grid (the level in the key's top
// bits) → scan of the block totals → entries of all levels in one array → the entry sort (sort.cuh)
// → the pairs within each level by the grid's pair walk (pairs.cuh, unchanged: equal keys are one
// cell of one level) → the pairs across levels from the smaller body's side: each body looks up its
// cells in every larger non-empty level (binary search of the level's run of sorted keys: the host's
// routine, core/broad.hpp cross_level_pairs), count → scan → fill, appended to the level pairs in
// ws.broad_pairs.
#include <cub/device/device_scan.cuh>

#include "cuda/broad.cuh"
#include "cuda/pair_estimate.cuh"
#include "cuda/sort.cuh"

namespace cg::cuda {

// levels, cells: per body (input order) its level, the key of its lowest cell in that level's grid
// (level << key_shift | cell key), its control byte with the report flags (as reorder_kernel), and
// per block the sum of the entry counts (total added to c->entries).
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    level_cells_kernel(const Sphere<Real>* __restrict__ spheres, const CutShape* __restrict__ cut,
                       const std::uint8_t* __restrict__ report, std::uint32_t n, LevelParams<Real> lp,
                       Key* __restrict__ lo_key, std::uint8_t* __restrict__ ctrl,
                       std::uint32_t* __restrict__ block_entries, Counters* __restrict__ c) {
  using Reduce = cub::BlockReduce<std::uint32_t, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  std::uint32_t count = 0;
  if (i < n) {
    const Sphere<Real> s = spheres[i];
    const int l = level_of(s.r, lp);
    const GridParams<Real> g = lp.grid[l];
    const BodyCells bc = cut ? cut_cells(s, cut[i], g) : body_cells(s, g);
    const std::uint32_t m = report ? report[i] : 0u;
    ctrl[i] = static_cast<std::uint8_t>(control_bits(bc) | ((m & kReportedBit) ? kReportBit : 0u) |
                                        ((m & kPairedBit) ? kPairedCtrlBit : 0u));
    lo_key[i] = (Key(l) << lp.key_shift) | cell_key<Key>(bc.lo[0], bc.lo[1], bc.lo[2], g);
    count = entry_count(bc);
  }
  const std::uint32_t total = Reduce(tmp).Sum(count);
  if (threadIdx.x == 0) {
    block_entries[blockIdx.x] = total;
    atomicAdd(&c->entries, static_cast<unsigned long long>(total));
  }
}

// levels, entries: fill_entries_kernel's, each body's cells in its own level's grid.
template <class Key, class Real>
__global__ void __launch_bounds__(kBlock)
    level_entries_kernel(const Key* __restrict__ lo_key, const std::uint8_t* __restrict__ ctrl,
                         std::uint32_t n, LevelParams<Real> lp,
                         const std::uint32_t* __restrict__ block_offset, Key* __restrict__ keys,
                         std::uint32_t* __restrict__ body) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  __shared__ Key s_keys[8 * kBlock];
  __shared__ std::uint32_t s_body[8 * kBlock];
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  const Key low = (Key(1) << lp.key_shift) - Key(1);
  Key k0{};
  std::uint32_t cb = 0, count = 0;
  int l = 0;
  if (i < n) {
    k0 = lo_key[i];
    cb = ctrl[i];
    count = 1u << popcount3((cb >> 3) & 7u);
    l = key_level(k0, lp.key_shift);
  }
  std::uint32_t rank, total;
  Scan(tmp).ExclusiveSum(count, rank, total);
  const GridParams<Real> g = lp.grid[l];
  for (std::uint32_t m = 0; m < count; ++m) {
    s_keys[rank + m] = (k0 & ~low) | spilled_cell_key<Key>(k0 & low, cb, m, g);
    s_body[rank + m] = i;
  }
  __syncthreads();
  const std::uint64_t base = block_offset[blockIdx.x];
  for (std::uint32_t t = threadIdx.x; t < total; t += kBlock) {
    keys[base + t] = s_keys[t];
    body[base + t] = s_body[t];
  }
}

// levels: where each level's run of the sorted keys starts (begin[count] = the entry count).
template <class Key>
__global__ void level_begin_kernel(const Key* __restrict__ keys, std::uint32_t ne, int count, int key_shift,
                                   std::uint32_t* __restrict__ begin) {
  const int l = static_cast<int>(threadIdx.x);
  if (l > count) return;
  if (l == count) {  // (count << key_shift may not fit the key)
    begin[l] = ne;
    return;
  }
  begin[l] = lower_bound_key(keys, std::uint32_t(0), ne, Key(Key(l) << key_shift));
}

// The levels and where each level's run of the sorted keys starts, as a block's copy in shared memory
// (a thread's copy of the parameters would be indexed in local memory); load ends in a barrier.
template <class Real>
struct BlockLevels {
  std::uint32_t begin[kMaxLevels + 1];
  LevelParams<Real> lp;
  __device__ void load(const LevelParams<Real>& params, const std::uint32_t* __restrict__ level_begin) {
    if (threadIdx.x <= static_cast<unsigned>(params.count)) begin[threadIdx.x] = level_begin[threadIdx.x];
    if (threadIdx.x == 0) lp = params;
    __syncthreads();
  }
};

// levels, across: per body a the pairs with the bodies of every larger non-empty level, where they
// share a cell of that level — core/broad.hpp's cross_level_pairs, the host's routine — reported and
// accepted by the pair test. kFill false: counts[a] and the totals of pairs and tests into c; true:
// the pairs written at offsets[a] onwards, searched again only for the bodies whose count is not 0
// (most small bodies of a mixed scene touch no larger one: the fill skips their lookups). The levels
// are read from BlockLevels.
template <bool kFill, class Real, class Key, class Test>
__global__ void __launch_bounds__(kBlock)
    cross_level_kernel(const Sphere<Real>* __restrict__ spheres, const CutShape* __restrict__ cut,
                       const std::uint8_t* __restrict__ ctrl, const std::uint8_t* __restrict__ report,
                       const Key* __restrict__ lo_key, std::uint32_t n, LevelParams<Real> lp,
                       const Key* __restrict__ keys, const std::uint32_t* __restrict__ body,
                       const std::uint32_t* __restrict__ level_begin, std::uint32_t* __restrict__ counts,
                       const std::uint32_t* __restrict__ offsets, std::uint32_t* __restrict__ pair_a,
                       std::uint32_t* __restrict__ pair_b, Counters* __restrict__ c, Test test) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  __shared__ BlockLevels<Real> s;
  s.load(lp, level_begin);
  const std::uint32_t a = blockIdx.x * kBlock + threadIdx.x;
  std::uint32_t found = 0;
  std::uint64_t tests = 0;
  if (a < n && (!kFill || counts[a] > 0)) {
    const Sphere<Real> sa = spheres[a];
    std::uint64_t w = kFill ? offsets[a] : 0;
    const auto cells_in = [&](const GridParams<Real>& g) {
      return cut ? cut_cells(sa, cut[a], g) : body_cells(sa, g);
    };
    tests = cross_level_pairs(a, key_level(lo_key[a], s.lp.key_shift), s.lp, keys, body, s.begin, ctrl,
                              report, cells_in, [&](std::uint32_t b) {
                                if (test(sa, spheres[b], a, b)) {
                                  if constexpr (kFill) store_pair(pair_a, pair_b, w++, a, b);
                                  ++found;
                                }
                              });
    if constexpr (!kFill) counts[a] = found;
  }
  if constexpr (!kFill) {
    const unsigned long long block_found = Reduce(tmp).Sum(found);
    __syncthreads();  // tmp is reused
    const unsigned long long block_tests = Reduce(tmp).Sum(tests);
    if (threadIdx.x == 0) {
      if (block_found) atomicAdd(&c->pairs, block_found);
      if (block_tests) atomicAdd(&c->tests, block_tests);
    }
  }
}

// levels, estimate: the bound of every body's pair tests across levels (core/broad.hpp
// cross_level_bound), summed into c->tests. The levels are read from BlockLevels.
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    cross_level_bound_kernel(const Sphere<Real>* __restrict__ spheres, const CutShape* __restrict__ cut,
                             const Key* __restrict__ lo_key, std::uint32_t n, LevelParams<Real> lp,
                             const Key* __restrict__ keys, const std::uint32_t* __restrict__ level_begin,
                             Counters* __restrict__ c) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  __shared__ BlockLevels<Real> s;
  s.load(lp, level_begin);
  const std::uint32_t a = blockIdx.x * kBlock + threadIdx.x;
  unsigned long long tests = 0;
  if (a < n) {
    const int la = key_level(lo_key[a], s.lp.key_shift);
    if (la + 1 < s.lp.count) {
      const Sphere<Real> sa = spheres[a];
      tests = cross_level_bound(la, s.lp, keys, s.begin, [&](const GridParams<Real>& g) {
        return cut ? cut_cells(sa, cut[a], g) : body_cells(sa, g);
      });
    }
  }
  const unsigned long long block_tests = Reduce(tmp).Sum(tests);
  if (threadIdx.x == 0 && block_tests) atomicAdd(&c->tests, block_tests);
}

}  // namespace cg::cuda

namespace cg::detail {

// The levels' pair estimate (may refuse the scene): the grid's over the cells of all levels, and the
// bound of the pairs across levels (cross_level_bound_kernel; the levels' runs found first). The pair
// counters it borrows are zeroed again for the pair stage.
template <class Real, class Key, class Narrow>
void levels_estimate(RunState<Real, Key, Narrow>& r) {
  const LevelParams<Real>& lp = r.job.levels;
  PairEstimate e = cell_estimate(r);
  if (lp.count > 1 && r.n > 0) {
    const ItemCounts ic = item_counts(r.ws, r.n64, kMaxLevels + 1);
    cuda::level_begin_kernel<Key><<<1, 32, 0, r.st>>>(
        r.keys.Current(), static_cast<std::uint32_t>(r.n_entries), lp.count, lp.key_shift, ic.extra);
    CG_CUDA_CHECK_LAUNCH("level_begin");
    zero_pair_counters(r);
    cuda::cross_level_bound_kernel<Real, Key><<<r.nb, cuda::kBlock, 0, r.st>>>(
        r.d_cell_spheres, r.box_cut(), r.d_lo_key, r.n, lp, r.keys.Current(), ic.extra, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("cross_level_bound");
    r.read_counters();
    e.tests += r.h_counters->tests;
    zero_pair_counters(r);
  }
  check_estimate(r, e);
}

// BroadPhase::levels, after pack (spheres only): stages entries, sort and pairs (see the file comment).
template <class Real, class Key, class Narrow>
void levels_stages(RunState<Real, Key, Narrow>& r) {
  using cuda::kBlock;
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  const LevelParams<Real>& lp = r.job.levels;
  broad_input(r);
  cuda::level_cells_kernel<Real, Key><<<r.nb, kBlock, 0, st>>>(r.d_cell_spheres, r.box_cut(), r.d_report, r.n,
                                                               lp, r.d_lo_key, r.d_ctrl, r.d_body_totals,
                                                               r.d_counters);
  CG_CUDA_CHECK_LAUNCH("level_cells");
  cub_run(ws, "entries", [&](void* t, std::size_t& b) {
    return cub::DeviceScan::ExclusiveSum(t, b, r.d_body_totals, r.d_body_offsets, int(r.nb), st);
  });
  r.read_counters();  // the entries total and the bad-data status
  check_packed(r);
  r.n_entries = r.h_counters->entries;
  r.stats.entries = r.n_entries;
  if (r.n_entries >= (std::uint64_t(1) << 31))
    throw ResourceError(
        std::to_string(r.n_entries) +
        " (cell, body) entries exceed the 2^31 - 1 items one CUB sort handles; use fewer bodies "
        "per rank (more MPI ranks)");
  const auto ne = static_cast<std::uint32_t>(r.n_entries);
  ws.reserve({{&ws.keys[0], ne * sizeof(Key)},
              {&ws.keys[1], ne * sizeof(Key)},
              {&ws.bodies[0], ne * sizeof(std::uint32_t)},
              {&ws.bodies[1], ne * sizeof(std::uint32_t)},
              {&ws.entry_blocks, 2 * std::size_t(cuda::blocks_for(ne)) * sizeof(std::uint32_t)}},
             "entries");
  r.keys = ws.entry_keys<Key>(ne);
  r.body = ws.entry_bodies(ne);
  cuda::level_entries_kernel<Key><<<r.nb, kBlock, 0, st>>>(r.d_lo_key, r.d_ctrl, r.n, lp, r.d_body_offsets,
                                                           r.keys.Current(), r.body.Current());
  CG_CUDA_CHECK_LAUNCH("level_entries");
  r.events.mark(EngineStage::entries, st);
  sort_stage(r);
  if (r.job.pair_limits.wanted()) levels_estimate(r);  // may refuse the scene

  // the pairs within each level: the grid's walk (its cell type sits below the common key_shift)
  r.g.half_bits = lp.key_shift - 3;
  pairs_stage(r);
  if (lp.count < 2) return;

  // the pairs across levels
  const std::uint32_t np_in = r.np;
  const ItemCounts ic = item_counts(ws, r.n64, kMaxLevels + 1);
  cuda::level_begin_kernel<Key><<<1, 32, 0, st>>>(r.keys.Current(), ne, lp.count, lp.key_shift, ic.extra);
  CG_CUDA_CHECK_LAUNCH("level_begin");
  zero_pair_counters(r);
  with_pair_test(r, [&](auto test) {
    cuda::cross_level_kernel<false, Real, Key, decltype(test)><<<r.nb, kBlock, 0, st>>>(
        r.d_cell_spheres, r.box_cut(), r.d_ctrl, r.d_report, r.d_lo_key, r.n, lp, r.keys.Current(),
        r.body.Current(), ic.extra, ic.counts, nullptr, nullptr, nullptr, r.d_counters, test);
  });
  CG_CUDA_CHECK_LAUNCH("cross_level_count");
  r.read_counters();
  const std::uint64_t across = r.h_counters->pairs;
  r.stats.pair_tests += r.h_counters->tests;
  if (across > 0) {
    const std::uint32_t* in_a = r.pair_a.Current();
    const std::uint32_t* in_b = r.pair_b.Current();
    std::uint32_t* store = candidate_store(r, ic, r.n64, ws.broad_pairs, np_in + across);
    const std::size_t np = r.np;
    if (np_in > 0) {
      CG_CUDA_CHECK(
          cudaMemcpyAsync(store, in_a, np_in * sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, st));
      CG_CUDA_CHECK(
          cudaMemcpyAsync(store + np, in_b, np_in * sizeof(std::uint32_t), cudaMemcpyDeviceToDevice, st));
    }
    with_pair_test(r, [&](auto test) {
      cuda::cross_level_kernel<true, Real, Key, decltype(test)>
          <<<r.nb, kBlock, 0, st>>>(r.d_cell_spheres, r.box_cut(), r.d_ctrl, r.d_report, r.d_lo_key, r.n, lp,
                                    r.keys.Current(), r.body.Current(), ic.extra, ic.counts, ic.offsets,
                                    store + np_in, store + np + np_in, r.d_counters, test);
    });
    CG_CUDA_CHECK_LAUNCH("cross_level_fill");
  }
  r.events.mark(EngineStage::pairs, st);
}

}  // namespace cg::detail
