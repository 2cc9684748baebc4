#pragma once
// CUDA stage pairs: the candidate pairs of the sorted entries, (a, b) u32 arrays of input indices
// a < b. count_pairs counts per sorted entry (block-staged walk) and writes the pairs directly at a
// block-aggregated atomic cursor into the dead alternate entry-body buffer; when they overflow the
// space there: scan of the block totals → fill_pairs into ws.pairs. The candidate filter is
// spheres_touch (every candidate is a contact: the narrow stage needs no compaction); scenes with
// ellipsoids take the bounding spheres (where 4 bodies in 5 are ellipsoids, less the centre cut,
// core/centre_cut.hpp: its second part over the pairs the walk found, after the walk) and the narrow
// stage rejects; forced by Tuning::candidates, the cell rule alone (CandidateFilter::cells) or the
// bounding spheres alone.
#include <cub/device/device_scan.cuh>
#include <type_traits>

#include "core/kept_room.hpp"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// The host's for_each_contact for sorted entry e: tests against the later entries f >= f0 of its cell
// (f0 = e + 1 for the whole walk). Bodies are cell-ordered indices; perm maps them to input indices.
// The host visits a pair (a, b) of input indices a < b from a's entry and skips it when report[a] is
// 0; here the entry order within a cell follows the cell order, so the report flag of the smaller
// input index of the two decides (kReportBit of its control byte, set by reorder from the mask). Both tests
// are symmetric in the two bodies (bit for bit), so the decisions are the host's.
// Input index of cell-ordered body j: perm[j], or j itself where the bodies were not renumbered (perm
// null: the pair stage then reads no permutation).
__device__ __forceinline__ std::uint32_t input_index(const std::uint32_t* __restrict__ perm,
                                                     std::uint32_t j) {
  return perm ? perm[j] : j;
}

// With a report mask, the order key of cell-ordered body j that decides which of a pair reports it:
// its input index, the top bit set for a wide body (kWideBit), so that the smaller key is the pair's
// anchor (core/broad.hpp: pair_reported; indices are below 2^31 on one GPU).
constexpr std::uint32_t kWideKey = 0x80000000u;
__device__ __forceinline__ std::uint32_t report_key(const std::uint32_t* __restrict__ perm,
                                                    const std::uint8_t* __restrict__ report,
                                                    std::uint32_t j) {
  const std::uint32_t i = input_index(perm, j);
  return i | ((report[i] & kWideBit) ? kWideKey : 0u);
}

template <class Real>
struct EntryBody {  // what a visit needs of the first body of a pair
  std::uint32_t a, type, pa;
  std::uint8_t ca;
  Sphere<Real> sa;
};

// `test`: the candidate filter's pair test (core/narrow.hpp: SpheresTouch by default, CellRule for
// CandidateFilter::cells, Fp64Touch for mixed), on cell-ordered body indices (its perm maps them).
template <class Test, class Real, class Emit>
__device__ __forceinline__ void visit(const EntryBody<Real>& x, std::uint32_t b, std::uint8_t cb,
                                      const Sphere<Real>& sb, std::uint32_t pb, const std::uint8_t* report,
                                      std::uint32_t& tests, const Test& test, Emit& emit) {
  // the report flag of the pair's anchor (the smaller report key); no pair of two bodies paired elsewhere
  if (report && (!((x.pa < pb ? x.ca : cb) & kReportBit) || (x.ca & cb & kPairedCtrlBit))) return;
  if (!test_in_cell(x.ca, cb, x.type)) return;
  ++tests;
  if (test(x.sa, sb, x.a, b)) emit(x.a, b);
}

// The pair writer of count_pairs' direct write and of fill_pairs: the pair (a, b) of cell-ordered
// bodies, a fixed for the entry, at w, the body of the smaller input index first (pa = a's), as the
// host's; then w + 1. As input indices, or (`cell`: the kept list of a cell-order skin build,
// cuda/cell_order.cuh) as the cell-order indices themselves.
template <class Index>
struct PairWriter {
  std::uint32_t* pair_a;
  std::uint32_t* pair_b;
  const std::uint32_t* perm;
  std::uint32_t pa;
  Index w;
  bool cell = false;
  __device__ __forceinline__ void operator()(std::uint32_t a, std::uint32_t b) {
    const std::uint32_t pb = input_index(perm, b);
    const std::uint32_t first = cell ? a : pa, second = cell ? b : pb;
    pair_a[w] = pa < pb ? first : second;
    pair_b[w] = pa < pb ? second : first;
    ++w;
  }
};

// A pair test in two parts (CentreCut): `Coarse` in the staged walk's hot loop, `refine` over the
// pairs it found, after it; the same decisions as the whole test.
template <class Test>
concept TwoPartTest = requires {
  typename Test::Coarse;
};
template <class Test>
__device__ __forceinline__ auto coarse_part(const Test& test) {
  if constexpr (TwoPartTest<Test>)
    return typename Test::Coarse{};
  else
    return test;
}

template <class Test, class Real, class Key, class Emit>
__device__ __forceinline__ std::uint32_t walk_from_memory(
    std::uint32_t f0, Key k, const EntryBody<Real>& x, const Key* __restrict__ keys,
    const std::uint32_t* __restrict__ body, std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
    const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
    const std::uint8_t* __restrict__ report, const Test& test, Emit&& emit) {
  std::uint32_t tests = 0;
  for (std::uint32_t f = f0; f < n_entries && keys[f] == k; ++f) {
    const std::uint32_t b = body[f];
    visit(x, b, ctrl[b], spheres[b], report ? report_key(perm, report, b) : 0u, report, tests, test, emit);
  }
  return tests;
}

// pairs, count: per block the number of contacting (reported) pairs (block_pairs); totals of pairs
// and tests added to c; per entry e a contact mask: bit j (1..31) set when entry e + j is a contact
// of e, bit 0 set when contacts lie past e + 31 or past the block's last entry (fill_pairs then walks
// e's cell from memory). The block stages its entries and a halo of the next 32 (key, control byte,
// sphere, input index when a report mask is given) in shared memory once; each thread then walks
// only its own cell's later entries there (a few shared loads per step, no warp-wide shuffles: the
// walk is issue-light), and walks from memory only a cell that goes on past e + 31 (or past the
// last entry). Without the halo, the cell that straddles the block's end would be walked from memory
// by up to a cell's worth of threads, a chain of dependent global loads that keeps the whole block
// resident (the block's tail).
// Direct write: the block takes the range [base, base + block total) of the pair cursor c->pairs (one
// atomicAdd) and, when the range ends at or below `cap`, writes its pairs (pair_a[w], pair_b[w]) of
// input indices, a < b, there, each thread at base + its exclusive rank (same walk, emitting). When
// the cursor ends above cap, the host discards those writes and runs the scan → fill_pairs path
// from the masks instead. The pairs' order is the blocks' arrival order; the order stage sorts them.
// `cell_out`: the direct write holds cell-order indices (PairWriter::cell), the kept list of a
// cell-order skin build (the fill path writes input indices whatever it is).
// kWindow: the entries after e each thread tests in shared memory (31 by the 32-bit mask the fill
// path reads), and the halo staged past the block's last entry. A skin build's inflated cells hold
// more entries than a fresh call's (by the grid's geometry about 30 against 18 at 6 contacts a
// body), so more of their entries go on past e + 31 and walk the rest of their cell from memory,
// twice (count, then write): its kernel (kWindow 64, no mask: the cell-order build never fills from
// masks) keeps the entries found among e + 1 .. e + 63 in a 64-bit set and walks from memory only
// past those.
template <int kWindow>
using WindowBits = std::conditional_t<(kWindow > 32), unsigned long long, std::uint32_t>;
template <class Bits>
__device__ __forceinline__ int lowest_bit(Bits m) {
  if constexpr (sizeof(Bits) == 8)
    return __ffsll(static_cast<long long>(m)) - 1;
  else
    return __ffs(static_cast<int>(m)) - 1;
}

template <class Real, class Key, class Test, int kWindow = 32>
__global__ void __launch_bounds__(kBlock, kPairsMinBlocks)
    count_pairs_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ body,
                       std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
                       const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
                       const std::uint8_t* __restrict__ report, int half_bits, std::uint32_t pass_type,
                       std::uint32_t* __restrict__ mask, std::uint32_t* __restrict__ block_pairs,
                       Counters* __restrict__ c, std::uint32_t* __restrict__ pair_a,
                       std::uint32_t* __restrict__ pair_b, unsigned long long cap, bool cell_out, Test test) {
  static_assert(kWindow == 32 || kWindow == 64, "a window of 31 (the mask) or 63 entries");
  using Bits = WindowBits<kWindow>;
  constexpr std::uint32_t kStagedHere = kBlock + kWindow;
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  using Scan = cub::BlockScan<unsigned long long, kBlock>;
  __shared__ union {
    typename Reduce::TempStorage reduce;
    typename Scan::TempStorage scan;
  } tmp;
  __shared__ unsigned long long s_base;
  __shared__ Key s_key[kStagedHere];
  __shared__ std::uint32_t s_body[kStagedHere];
  __shared__ Sphere<Real> s_sphere[kStagedHere];
  __shared__ std::uint32_t s_perm[kStagedHere];
  __shared__ std::uint8_t s_ctrl[kStagedHere];
  const std::uint32_t base = blockIdx.x * kBlock;
  const std::uint32_t t = threadIdx.x;
  const std::uint32_t e = base + t;
  const bool valid = e < n_entries;
  const std::uint32_t end = n_entries - base < kStagedHere ? n_entries - base : kStagedHere;  // staged
  Key k{};
  EntryBody<Real> x{};
  if (valid) {
    k = keys[e];
    x.a = body[e];
    x.type = key_type(k, half_bits) | pass_type;  // type-pass path: keys hold no type bits
    x.ca = ctrl[x.a];
    x.sa = spheres[x.a];
    x.pa = report ? report_key(perm, report, x.a) : 0u;
    s_key[t] = k;
    s_body[t] = x.a;
    s_sphere[t] = x.sa;
    s_ctrl[t] = x.ca;
    s_perm[t] = x.pa;
  }
  if (t + kBlock < end) {  // the halo: the next block's first entries
    const std::uint32_t h = t + kBlock, b = body[base + h];
    s_key[h] = keys[base + h];
    s_body[h] = b;
    s_sphere[h] = spheres[b];
    s_ctrl[h] = ctrl[b];
    s_perm[h] = report ? report_key(perm, report, b) : 0u;
  }
  __syncthreads();
  std::uint32_t found = 0, tests = 0;
  Bits bits = 0;
  if (valid) {
    const std::uint32_t lim =
        end < t + kWindow ? end : t + kWindow;  // staged entries e + 1 .. e + kWindow - 1
    std::uint32_t f = t + 1;
    auto mark_one = [&](std::uint32_t, std::uint32_t) {
      ++found;
      bits |= Bits(1) << (f - t);
    };
    const auto coarse = coarse_part(test);
    for (; f < lim && s_key[f] == k; ++f)
      visit(x, s_body[f], s_ctrl[f], s_sphere[f], s_perm[f], report, tests, coarse, mark_one);
    if constexpr (TwoPartTest<Test>) {  // the rest of the test over the pairs found
      for (Bits m = bits; m != 0; m &= m - 1) {
        const std::uint32_t j = lowest_bit(m), g = t + j;
        if (!test.refine(x.sa, s_sphere[g], x.a, s_body[g])) {
          bits &= ~(Bits(1) << j);
          --found;
        }
      }
    }
    if (f == lim) {  // the cell may go on past the staged window: walk the rest from memory
      const std::uint32_t before = found;
      tests += walk_from_memory(base + f, k, x, keys, body, n_entries, ctrl, spheres, perm, report, test,
                                [&](std::uint32_t, std::uint32_t) { ++found; });
      if (found != before) bits |= 1u;
    }
    if constexpr (kWindow == 32) mask[e] = bits;  // (the fill path's; a wider window writes none)
  }
  unsigned long long rank, block_sum;
  Scan(tmp.scan).ExclusiveSum(static_cast<unsigned long long>(found), rank, block_sum);
  __syncthreads();  // tmp is reused
  const unsigned long long block_tests = Reduce(tmp.reduce).Sum(static_cast<unsigned long long>(tests));
  if (threadIdx.x == 0) {
    // Truncation is harmless: the host rejects totals >= 2^31 before block_pairs is used.
    block_pairs[blockIdx.x] = static_cast<std::uint32_t>(block_sum);
    s_base = block_sum ? atomicAdd(&c->pairs, block_sum) : 0ull;
    atomicAdd(&c->tests, block_tests);
  }
  __syncthreads();
  if (found == 0 || s_base + block_sum > cap) return;
  PairWriter<unsigned long long> emit{
      pair_a, pair_b, perm, report ? x.pa & ~kWideKey : input_index(perm, x.a), s_base + rank, cell_out};
  if constexpr (kWindow == 32) {
    if (bits & 1u) {
      walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report, test, emit);
    } else {
      for (std::uint32_t m = bits; m != 0; m &= m - 1) emit(x.a, s_body[t + __ffs(m) - 1]);
    }
  } else {  // the window's pairs from the set, then those past it from memory again
    for (Bits m = bits & ~Bits(1); m != 0; m &= m - 1) emit(x.a, s_body[t + lowest_bit(m)]);
    if (bits & 1u) {
      const std::uint32_t past = (end < t + kWindow ? end : t + kWindow) + base;
      walk_from_memory(past, k, x, keys, body, n_entries, ctrl, spheres, perm, report, test, emit);
    }
  }
}

// pairs, fill: pairs (pair_a[w], pair_b[w]) of input indices, a < b, at w = the block's scanned total +
// the entry's rank, from the contact masks of count_pairs_kernel (entries flagged in bit 0: the cell
// is walked from memory again, counting then emitting).
template <class Real, class Key, class Test>
__global__ void __launch_bounds__(kBlock)
    fill_pairs_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ body,
                      std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
                      const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
                      const std::uint8_t* __restrict__ report, int half_bits,
                      const std::uint32_t* __restrict__ mask, const std::uint32_t* __restrict__ block_offset,
                      std::uint32_t* __restrict__ pair_a, std::uint32_t* __restrict__ pair_b, Test test) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  const std::uint32_t e = blockIdx.x * kBlock + threadIdx.x;
  const std::uint32_t bits = e < n_entries ? mask[e] : 0u;
  EntryBody<Real> x{};
  Key k{};
  std::uint32_t mine = 0;
  if (bits & 1u) {  // slow path: contacts past the warp's end
    k = keys[e];
    x.a = body[e];
    x.type = key_type(k, half_bits);
    x.ca = ctrl[x.a];
    x.sa = spheres[x.a];
    x.pa = report ? report_key(perm, report, x.a) : 0u;
    walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report, test,
                     [&](std::uint32_t, std::uint32_t) { ++mine; });
  } else {
    mine = __popc(bits);
  }
  std::uint32_t rank;
  Scan(tmp).ExclusiveSum(mine, rank);
  if (mine == 0) return;
  const std::uint32_t a = body[e];
  PairWriter<std::uint32_t> emit{pair_a, pair_b, perm, input_index(perm, a), block_offset[blockIdx.x] + rank};
  if (bits & 1u) {
    walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report, test, emit);
  } else {
    for (std::uint32_t m = bits; m != 0; m &= m - 1) emit(a, body[e + __ffs(m) - 1]);
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// Calls launch(test) with the pair test of the call's candidate filter (core/narrow.hpp): the cell
// rule, the sphere test, scenes with ellipsoids the centre cut (core/centre_cut.hpp), or — mixed with
// the default filter — fp64's decision (Fp64Touch).
template <class Real, class Key, class Narrow, class Launch>
void with_pair_test(const RunState<Real, Key, Narrow>& r, Launch&& launch) {
  if (!candidates_touch(r.filter)) return launch(CellRule{});
  if (r.filter == CandidateFilter::centre_cut) return launch(CentreCut{r.d_cell_cut, r.cut_skin});
  if constexpr (!std::is_same_v<Real, Narrow>)
    if (r.filter == CandidateFilter::spheres_touch)
      return launch(Fp64Touch{{nullptr, r.d_pos, r.d_rad, r.origin}, float(r.g.radius_margin), r.d_perm});
  launch(SpheresTouch{});
}

// count_pairs_kernel / fill_pairs_kernel instantiated for the call's pair test (count_pairs: with its
// window of kWindow entries).
template <int kWindow = 32, class Real, class Key, class Narrow, class... Args>
void launch_count_pairs(const RunState<Real, Key, Narrow>& r, std::uint32_t blocks, Args... args) {
  with_pair_test(r, [&](auto test) {
    cuda::count_pairs_kernel<Real, Key, decltype(test), kWindow>
        <<<blocks, cuda::kBlock, 0, r.st>>>(args..., test);
  });
  CG_CUDA_CHECK_LAUNCH("count_pairs");
}
template <class Real, class Key, class Narrow, class... Args>
void launch_fill_pairs(const RunState<Real, Key, Narrow>& r, std::uint32_t blocks, Args... args) {
  with_pair_test(r, [&](auto test) {
    cuda::fill_pairs_kernel<Real, Key, decltype(test)><<<blocks, cuda::kBlock, 0, r.st>>>(args..., test);
  });
  CG_CUDA_CHECK_LAUNCH("fill_pairs");
}

template <class Real, class Key, class Narrow>
void pairs_stage(RunState<Real, Key, Narrow>& r) {
  using cuda::kBlock;
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  const auto ne = static_cast<std::uint32_t>(r.n_entries);
  const std::uint32_t neb = cuda::blocks_for(ne);
  // ---- count (and direct write) ----
  const Key* d_keys = r.keys.Current();
  const std::uint32_t* d_body = r.body.Current();
  std::uint32_t* d_pair_count = Workspace::pair_masks(r.keys);
  std::uint32_t* d_entry_totals = ws.entry_blocks.span_as<std::uint32_t>(2 * neb).data();
  std::uint32_t* d_entry_offsets = d_entry_totals + neb;
  // Direct write of the pairs as four u32 arrays (a, b, and the order sort's second copies) of
  // cap pairs each: cap = ne / 4 in the dead alternate entry-body buffer, or — where an earlier call
  // left ws.pairs larger (a rebuild of a skin's list: about the previous build's candidates, with the
  // buffer's geometric growth) — in ws.pairs, so a rebuild skips the scan → fill walk.
  // A cell-order skin build (cuda/cell_order.cuh; not under CONTACTGRID_STEP_BUILD=copy): a and b
  // alone, as cell-order indices, straight into the kept list, whose room the previous build's
  // count sets, or before any list the last pair stage's count (core/kept_room.hpp); no fill walk,
  // no mapping of the pairs afterwards. A walk that finds more than that room walks again into room
  // of the counted size (CONTACTGRID_STEP_REBUILD=fill: the scan → fill walk and the mapping).
  const bool into_kept = r.cell_order && !r.tuning.step_build_copy;
  const bool rewalk = into_kept && !r.tuning.step_rebuild_fill;
  const std::size_t pair_bytes = 2 * sizeof(std::uint32_t);
  const std::uint64_t held_cap = ws.pairs.capacity() / (4 * sizeof(std::uint32_t));
  const bool direct_in_pairs = held_cap > ne / 4;
  std::uint64_t direct_cap = direct_in_pairs ? held_cap : ne / 4;
  std::uint32_t* d_direct = nullptr;
  if (into_kept) {
    const std::uint64_t basis = rewalk ? kept_room_basis(ws.kept_count, ws.last_pairs) : ws.kept_count;
    direct_cap = kept_room(basis, ne, ws.kept_pairs.capacity() / pair_bytes);
    ws.reserve({{&ws.kept_pairs, direct_cap * pair_bytes}}, "pairs");
    direct_cap = ws.kept_pairs.capacity() / pair_bytes;  // (the buffer's growth: all of it)
    d_direct = ws.kept_pairs.span_as<std::uint32_t>(2 * direct_cap).data();
  } else {
    d_direct = direct_in_pairs ? ws.pairs.span_as<std::uint32_t>(4 * held_cap).data()
                               : Workspace::direct_pairs(r.body);
  }
  // the cell-order build's walk: 63 entries after each in shared memory (CONTACTGRID_STEP_BUILD_WINDOW=32:
  // the 31 of every other call; the former fill path's masks need 31)
  const bool wide = rewalk && r.tuning.step_build_window == 64;
  auto count = [&] {
    auto launch = [&](auto window) {
      launch_count_pairs<decltype(window)::value>(r, neb, d_keys, d_body, ne, r.d_ctrl, r.d_cell_spheres,
                                                  r.pair_perm(), r.d_report, r.g.half_bits, 0u, d_pair_count,
                                                  d_entry_totals, r.d_counters, d_direct,
                                                  d_direct + direct_cap, direct_cap, into_kept);
    };
    if constexpr (std::is_same_v<Real, float> && std::is_same_v<Narrow, float>) {  // (cell order: fp32)
      if (wide) return launch(std::integral_constant<int, 64>{});
    }
    launch(std::integral_constant<int, 32>{});
  };
  count();
  r.stats.pair_walks = 1;
  r.read_counters_reporting_tests();  // host needs the pairs total
  const std::uint64_t n_pairs = r.h_counters->pairs;
  r.stats.pair_tests = r.h_counters->tests;
  check_pairs(n_pairs);
  r.np = static_cast<std::uint32_t>(n_pairs);

  // ---- (scan → fill) ----
  // Pairs as (a, b) u32 arrays, double-buffered (16 B a pair). When they fit the direct write's room
  // (np <= cap), the count kernel has already written them there; else they are placed in ws.pairs
  // by the scan of the block totals → fill_pairs (from the contact masks), or — a cell-order build
  // (rewalk) — the same walk writes them again into the kept list, grown to the count: the count
  // kernel's staged walk costs less than the fill's walk from memory, and the list needs no mapping.
  bool written = n_pairs <= direct_cap;
  if (rewalk && !written) {
    ws.reserve({{&ws.kept_pairs, n_pairs * pair_bytes}}, "pairs");
    direct_cap = ws.kept_pairs.capacity() / pair_bytes;
    d_direct = ws.kept_pairs.span_as<std::uint32_t>(2 * direct_cap).data();
    // the cursor and the tests from zero again (the walk counts the same tests a second time)
    CG_CUDA_CHECK(cudaMemsetAsync(&r.d_counters->pairs, 0, sizeof r.d_counters->pairs, st));
    CG_CUDA_CHECK(cudaMemsetAsync(&r.d_counters->tests, 0, sizeof r.d_counters->tests, st));
    count();
    written = true;
    r.stats.pair_walks = 2;
  }
  r.kept_written = into_kept && written;
  if (r.kept_written) {  // the kept list, a then b (keep_cell_candidates keeps it)
    ws.reserve({{&ws.out, r.out_bytes_for(r.np)}}, "pairs");
    ws.kept_stride = direct_cap;
    r.pair_a = cub::DoubleBuffer<std::uint32_t>(d_direct, d_direct);
    r.pair_b = cub::DoubleBuffer<std::uint32_t>(d_direct + direct_cap, d_direct + direct_cap);
    r.events.mark(EngineStage::pairs, st);
    return;
  }
  ws.reserve({{&ws.pairs, written ? 0 : 4 * std::size_t(r.np) * sizeof(std::uint32_t)},
              {&ws.out, r.out_bytes_for(r.np)}},
             "pairs");
  const std::size_t stride = written ? std::size_t(direct_cap) : std::size_t(r.np);
  std::uint32_t* d_pair_store =
      written ? d_direct : ws.pairs.span_as<std::uint32_t>(4 * std::size_t(r.np)).data();
  r.pair_a = cub::DoubleBuffer<std::uint32_t>(d_pair_store, d_pair_store + 2 * stride);
  r.pair_b = cub::DoubleBuffer<std::uint32_t>(d_pair_store + stride, d_pair_store + 3 * stride);
  if (!written && r.np > 0) {
    cub_run(ws, "pairs", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, d_entry_totals, d_entry_offsets, int(neb), st);
    });
    launch_fill_pairs(r, neb, d_keys, d_body, ne, r.d_ctrl, r.d_cell_spheres, r.pair_perm(), r.d_report,
                      r.g.half_bits, d_pair_count, d_entry_offsets, r.pair_a.Current(), r.pair_b.Current());
    r.stats.pair_walks = 2;
  }
  r.events.mark(EngineStage::pairs, st);
}

}  // namespace cg::detail
