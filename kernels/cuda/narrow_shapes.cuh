#pragma once
// CUDA stage narrow, scenes with ellipsoids: the count passes of the rejecting path (narrow.cuh's
// narrow_compact calls narrow_shapes_count) — their kernels over the candidate lists, WarpRuns (the
// whole start set on a lane group), the fp32 pairs solved in fp64 and their rows — with the warp
// helpers they share with narrow.cuh's accept kernel (add_flags; append builds the lists). Apart from
// narrow.cuh so that the sphere path reads alone; ShapeDecide (core/shape_narrow.hpp) is the decider.
//
// Scenes with ellipsoids count in passes (narrow_shapes_count): a screen of every candidate, then the
// first start, the settle pass and the whole start set, each over a list of the candidates the previous
// pass left (appended by that pass), so that a warp's lanes do the same work (the whole set of a short
// list: a lane group per pair, its starts on the lanes).
#include <limits>
#include <type_traits>

#include "core/narrow.hpp"
#include "core/shape_narrow.hpp"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// The narrow flags of the warp's candidates into the call's counters: summed (the largest of
// max_evaluations) over the warp, one lane's atomics. Every lane of the warp must call it (the kernels
// below do not return early).
__device__ inline void add_flags(const NarrowFlags& f, Counters* c) {
  constexpr unsigned kAll = 0xffffffffu;
  auto add = [&](unsigned long long* to, std::uint32_t v) {
    const std::uint32_t sum = __reduce_add_sync(kAll, v);
    if ((threadIdx.x & 31u) == 0 && sum) atomicAdd(to, static_cast<unsigned long long>(sum));
  };
  add(&c->fallbacks, f.fallbacks);
  add(&c->unconverged, f.unconverged);
  add(&c->fp64_rows, f.fp64_rows);
  add(&c->solver_runs, f.solver_runs);
  add(&c->evaluations, f.evaluations);
  const std::uint32_t most = __reduce_max_sync(kAll, f.max_evaluations);
  if ((threadIdx.x & 31u) == 0 && most) atomicMax(&c->max_evaluations, static_cast<unsigned long long>(most));
}

// Candidate k onto `list` when `take` (its length in *count): one atomic per warp, the warp's items
// in lane order. Every lane of the warp must call it. The lists' order depends on the warps' timing;
// what each pass computes for a candidate does not, nor do the sums and maxima of the counters.
// Returns the candidate's place in the list (for what goes beside it), or ~0 when not taken.
__device__ inline unsigned long long append(bool take, std::uint32_t k, std::uint32_t* list,
                                            unsigned long long* count) {
  constexpr unsigned kAll = 0xffffffffu;
  const unsigned takers = __ballot_sync(kAll, take);
  if (takers == 0) return ~0ull;
  const unsigned lane = threadIdx.x & 31u, leader = __ffs(takers) - 1;
  unsigned long long base = 0;
  if (lane == leader) base = atomicAdd(count, static_cast<unsigned long long>(__popc(takers)));
  base = __shfl_sync(kAll, base, leader);
  if (!take) return ~0ull;
  const unsigned long long at = base + __popc(takers & ((1u << lane) - 1u));
  list[at] = k;
  return at;
}

// narrow, shapes, first pass (triage) over every candidate. Two kernels in general: kFirstToo false,
// ShapeDecide::screen — verdict[k] (reject, accept, hard, or solve: a general pair for the first start)
// and the kept normal of a settled pair: closed forms, root finds, the centre line, no solver code; the
// `solve` ones onto `to_solve` (c->to_solve), the `hard` ones onto `unsettled` (c->unsettled, where the
// first pass adds its own); then ShapeDecide::first_pass over the `solve` list alone (the PW filter and
// one Newton run with the cheap certificates; in one kernel the Newton lanes — half the candidates —
// would make every warp pay for them). kFirstToo true, ShapeDecide::triage (the screen, then the first start
// on the candidate's own thread), the hard ones onto `unsettled` with their kept first start beside
// them in `carry`: for scenes of ellipsoids alone whose pair stage took the centre cut, where the
// screen leaves nearly every candidate to the first start and the list between the two kernels would
// only gather them again (BENCHMARKS.md §3).
template <class Real, bool kFirstToo>
__global__ void __launch_bounds__(kBlock)
    narrow_triage_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                         std::uint32_t n_pairs, ShapeDecide<Real> decide, std::uint32_t* __restrict__ verdict,
                         Vec3<Real>* __restrict__ normal, std::uint32_t* __restrict__ to_solve,
                         std::uint32_t* __restrict__ unsettled, FirstStart<Real>* __restrict__ carry,
                         Counters* __restrict__ c) {
  using Verdict = typename ShapeDecide<Real>::Verdict;
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  NarrowFlags flags;
  Verdict v = Verdict::reject;
  FirstStart<Real> first{};  // a hard pair's first start, kept for settle (fp32's pairs in fp64: none)
  if (k < n_pairs) {
    Vec3<Real> n{};
    if constexpr (kFirstToo)
      v = decide.triage(pair_a[k], pair_b[k], flags, n, &first);
    else
      v = decide.screen(pair_a[k], pair_b[k], flags, n);
    verdict[k] = static_cast<std::uint32_t>(v);
    normal[k] = n;
  }
  if constexpr (!kFirstToo) append(v == Verdict::solve, k, to_solve, &c->to_solve);
  // hard: fp32's pairs in fp64 (straight to settle), and with the first start the uncertified ones
  const unsigned long long at = append(v == Verdict::hard, k, unsettled, &c->unsettled);
  if constexpr (kFirstToo)
    if (at != ~0ull) carry[at] = first;  // for settle, beside the pair in its list
  add_flags(flags, c);
}

// Pass `Pass` of ShapeDecide over the candidates listed in `list` (their count on the device: launched
// over every candidate, the blocks past the count return at once, so the host need not wait for it),
// so that every lane of a warp runs the same pass: first_pass (the general pairs the screen left),
// settle (the ones triage left hard), whole (the start set for the ones still hard, when there are more
// than warp_limit: fewer go one lane group each, narrow_whole_warp_kernel; fp32's pairs in fp64 are left to
// narrow_hard_fp64_kernel). verdict[k] and the kept minimiser normal[k]; first and settle put the
// candidates they leave hard onto `next` (*n_next), the next pass's list.
enum class ListPass { first, settle, whole };
template <class Real, ListPass Pass>
__global__ void __launch_bounds__(kBlock)
    narrow_list_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                       const std::uint32_t* __restrict__ list, const unsigned long long* __restrict__ n_list,
                       ShapeDecide<Real> decide, std::uint32_t* __restrict__ verdict,
                       Vec3<Real>* __restrict__ normal, std::uint32_t* __restrict__ next,
                       unsigned long long* __restrict__ n_next, Counters* __restrict__ c,
                       FirstStart<Real>* __restrict__ carry, unsigned long long warp_limit = 0) {
  using Verdict = typename ShapeDecide<Real>::Verdict;
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  const unsigned long long count = *n_list;
  if (blockIdx.x * kBlock >= count) return;                    // the whole block is past the count
  if (Pass == ListPass::whole && count <= warp_limit) return;  // narrow_whole_warp_kernel's
  NarrowFlags flags;
  bool still_hard = false;
  std::uint32_t k = 0;
  FirstStart<Real> first{};  // ListPass::first: a hard pair's first start, kept for settle
  if (i < count) {
    k = list[i];
    const std::uint32_t a = pair_a[k], b = pair_b[k];
    Vec3<Real> n{};
    Verdict v;
    if constexpr (Pass == ListPass::first) {
      v = decide.first_pass(a, b, flags, n, &first);
    } else if constexpr (Pass == ListPass::settle) {
      v = decide.settle(a, b, flags, n, carry + i);  // (fp32's pairs in fp64: none kept, none read)
    } else {
      v = decide.in_fp64(a, b)
              ? Verdict::hard
              : (decide.template solve<false>(a, b, flags, n) ? Verdict::accept : Verdict::reject);
    }
    if (v != Verdict::hard || Pass != ListPass::whole) {
      verdict[k] = static_cast<std::uint32_t>(v);
      normal[k] = n;
    }
    still_hard = v == Verdict::hard;
  }
  if (Pass != ListPass::whole) {
    const unsigned long long at = append(still_hard, k, next, n_next);  // the next pass's list
    if constexpr (Pass == ListPass::first)
      if (at != ~0ull) carry[at] = first;  // for settle, beside it
  }
  add_flags(flags, c);
}

// The start set of one hard pair on a group of kSolveLanes lanes of a warp (core/ellipsoid_solve.hpp:
// SerialRuns, whose bits and counts these are): lane j of the group runs start j of a round of the
// batch, all at once, then every lane takes the results in start order, so the group's lanes agree on
// each step of the solve after it (the same values, the same branches) — the pair's serial chain of
// runs becomes the longest run of each round. Lanes per pair: fp32 16 (one round for the 11 starts, the
// screen's 4 and the safety net's 13), fp64 8 (its kernel holds one block per SM, so twice the resident
// groups); the fastest of 8, 16 and 32 on the H100 (BENCHMARKS.md §3).
template <class Real>
inline constexpr int kSolveLanes = sizeof(Real) == 8 ? 8 : 16;
template <int kSolveLanes>
struct WarpRuns {
  unsigned mask;  // the group's lanes
  int base;       // the group's first lane in the warp
  template <class Real>
  __device__ detail::LocalResult<Real> from_lane(const detail::LocalResult<Real>& v, int j) const {
    detail::LocalResult<Real> o;
    o.n = {__shfl_sync(mask, v.n.x, j, kSolveLanes), __shfl_sync(mask, v.n.y, j, kSolveLanes),
           __shfl_sync(mask, v.n.z, j, kSolveLanes)};
    o.f = __shfl_sync(mask, v.f, j, kSolveLanes);
    o.grad = __shfl_sync(mask, v.grad, j, kSolveLanes);
    o.evaluations = __shfl_sync(mask, v.evaluations, j, kSolveLanes);
    o.converged = __shfl_sync(mask, v.converged ? 1 : 0, j, kSolveLanes) != 0;
    return o;
  }
  template <class Start, class Run, class More, class Take>
  __device__ void batch(int count, const Start& start, const Run& run, const More& more,
                        const Take& take) const {
    const int lane = static_cast<int>(threadIdx.x & 31u) - base;
    for (int round = 0; round < count; round += kSolveLanes) {
      const int j = round + lane;
      const auto s = start(j < count ? j : round);
      const bool mine = j < count && !is_zero(s);
      decltype(run(s)) res{};
      if (mine) res = run(s);
      const unsigned valid = __ballot_sync(mask, mine) >> base;
      for (int t = 0; t < kSolveLanes && round + t < count; ++t) {
        if (!more()) return;
        const auto rt = from_lane(res, t);  // every lane of the group shuffles
        if (valid >> t & 1u) take(rt);
      }
    }
  }
};

// The whole start set of the hard pairs, one group of kSolveLanes lanes per pair (WarpRuns), on a
// fixed grid that walks the list: used when the list is short (*n_hard <= warp_limit, the host's bound
// from the resident groups), where the one-thread-per-pair kernel waits on its slowest pair's serial
// chain of ~17 runs; beyond it the list kernel (ListPass::whole) takes them (a group that must take
// pairs one after the other loses to it, BENCHMARKS.md §3). The same bits either way.
template <class Real, int kSolveLanes>
__global__ void __launch_bounds__(kBlock)
    narrow_whole_warp_kernel(const std::uint32_t* __restrict__ pair_a,
                             const std::uint32_t* __restrict__ pair_b, const std::uint32_t* __restrict__ list,
                             const unsigned long long* __restrict__ n_list, unsigned long long warp_limit,
                             ShapeDecide<Real> decide, std::uint32_t* __restrict__ verdict,
                             Vec3<Real>* __restrict__ normal, Counters* __restrict__ c) {
  const unsigned long long count = *n_list;
  if (count > warp_limit) return;  // the list kernel's
  const int base = static_cast<int>(threadIdx.x & 31u) & ~(kSolveLanes - 1);
  const WarpRuns<kSolveLanes> runs{unsigned((1ull << kSolveLanes) - 1u) << base, base};
  const bool lead = (threadIdx.x & (kSolveLanes - 1)) == 0;
  const unsigned long long groups = std::uint64_t(gridDim.x) * (kBlock / kSolveLanes);
  NarrowFlags flags;  // the lead lane's: the other lanes solve the same pairs
  for (unsigned long long i = (std::uint64_t(blockIdx.x) * kBlock + threadIdx.x) / kSolveLanes; i < count;
       i += groups) {
    const std::uint32_t k = list[i], a = pair_a[k], b = pair_b[k];
    if (decide.in_fp64(a, b)) continue;  // narrow_hard_fp64_kernel's
    NarrowFlags pair_flags;
    Vec3<Real> n{};
    const bool contact = decide.template solve<false>(a, b, pair_flags, n, runs);
    if (lead) {
      verdict[k] = contact ? 1u : 0u;
      normal[k] = n;
      flags.add(pair_flags);
    }
  }
  add_flags(flags, c);  // every lane, after the walk
}

// fp32's pairs in fp64 (core/shape_narrow.hpp: ShapeDecide::in_fp64, sent to the hard list by triage):
// solved in double here, so that the double solve's registers and stack are this kernel's alone (in
// the hard and fill kernels they would double the registers and slow the narrow stage, BENCHMARKS.md §3).
// The kept normal is a NaN marker: the fill kernel leaves those rows to narrow_fill_fp64_kernel.
// Both kernels are rare work behind a cheap test, with ~250 registers a thread: a fixed grid of
// kRareBlocks walks the list (a grid of one thread per item would spend its time in empty waves).
inline constexpr std::uint32_t kRareBlocks = 256;
template <class Real>
__global__ void __launch_bounds__(kBlock)
    narrow_hard_fp64_kernel(const std::uint32_t* __restrict__ pair_a,
                            const std::uint32_t* __restrict__ pair_b, const std::uint32_t* __restrict__ hard,
                            const unsigned long long* __restrict__ n_hard, ShapeDecide<Real> decide,
                            std::uint32_t* __restrict__ verdict, Vec3<Real>* __restrict__ normal,
                            std::uint32_t* __restrict__ fp64_list, Counters* __restrict__ c) {
  const unsigned long long count = *n_hard;
  NarrowFlags flags;
  for (unsigned long long i = blockIdx.x * kBlock + threadIdx.x; i < count; i += kRareBlocks * kBlock) {
    const std::uint32_t k = hard[i];
    const std::uint32_t a = pair_a[k], b = pair_b[k];
    if (decide.in_fp64(a, b)) {
      verdict[k] = decide.fp64_solve(a, b, flags).contact ? 1u : 0u;
      const Real nan = std::numeric_limits<Real>::quiet_NaN();
      normal[k] = {nan, nan, nan};
      fp64_list[atomicAdd(&c->fp64_pairs, 1ull)] = k;  // for narrow_fill_fp64_kernel (rare: one atomic each)
    }
  }
  add_flags(flags, c);  // every lane, after the walk
}

// The rows of fp32's pairs in fp64 (NaN-marked and listed by narrow_hard_fp64_kernel): fp64's row
// rounded once, as row_from gives them on the host. It walks the list, not every candidate: a few rows.
template <class Real>
__global__ void __launch_bounds__(kBlock)
    narrow_fill_fp64_kernel(const std::uint32_t* __restrict__ pair_a,
                            const std::uint32_t* __restrict__ pair_b,
                            const std::uint32_t* __restrict__ fp64_list, ShapeDecide<Real> decide,
                            const std::uint32_t* __restrict__ accept,
                            const std::uint32_t* __restrict__ offset, ContactPtrs<Real> out, bool full,
                            const Counters* __restrict__ c) {
  const unsigned long long count = c->fp64_pairs;
  for (unsigned long long i = blockIdx.x * kBlock + threadIdx.x; i < count; i += kRareBlocks * kBlock) {
    const std::uint32_t k = fp64_list[i];
    if (!accept[k]) continue;
    const std::uint32_t a = pair_a[k], b = pair_b[k];
    ContactRow<Real> row = decide.fp64_row(a, b, full);
    row.id_a = a;
    row.id_b = b;
    store_row(out, offset[k], row, full);
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// The warp kernel's grid (every resident block of it) and its limit: lists up to
// Tuning::warp_solve_pairs pairs per resident lane group go a group per pair; 0 (the knob at 0): never.
template <class Narrow>
unsigned long long whole_warp_plan(const Tuning& tuning, int& blocks) {
  constexpr int kLanes = cuda::kSolveLanes<Narrow>;
  blocks = 0;
  if (tuning.warp_solve_pairs == 0) return 0;
  int device = 0, sms = 0, per_sm = 0;
  CG_CUDA_CHECK(cudaGetDevice(&device));
  CG_CUDA_CHECK(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
  CG_CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(
      &per_sm, cuda::narrow_whole_warp_kernel<Narrow, kLanes>, cuda::kBlock, 0));
  blocks = sms * (per_sm > 0 ? per_sm : 1);
  return static_cast<unsigned long long>(blocks) * (cuda::kBlock / kLanes) * tuning.warp_solve_pairs;
}

// The count pass of scenes with ellipsoids, in three: triage every candidate, settle the ones it left
// hard, then the whole solve for the ones still hard (each list made by the pass before it: append;
// d_list is d_offset, dead until the scan). Returns the kept minimisers (ws.normals, one per candidate).
template <class Real, class Key, class Narrow>
const Vec3<Narrow>* narrow_shapes_count(RunState<Real, Key, Narrow>& r, const ShapeDecide<Narrow>& decide,
                                        std::uint32_t* d_verdict, std::uint32_t* d_list) {
  using cuda::blocks_for;
  using cuda::kBlock;
  cudaStream_t st = r.st;
  const std::uint32_t np = r.np;
  r.ws.reserve({{&r.ws.normals, std::size_t(np) * sizeof(Vec3<Narrow>)},
                {&r.ws.narrow_list, std::size_t(np) * sizeof(std::uint32_t)},
                {&r.ws.narrow_carry, std::size_t(np) * sizeof(FirstStart<Narrow>)}},
               "narrow");
  // beside the unsettled list: each pair's first start, kept by the first pass for settle
  FirstStart<Narrow>* d_carry = r.ws.narrow_carry.template span_as<FirstStart<Narrow>>(np).data();
  Vec3<Narrow>* d_normal = r.ws.normals.template span_as<Vec3<Narrow>>(np).data();
  // the lists, each made by the pass before (append; the counters start at 0): solve → d_list,
  // unsettled → ws.narrow_list, hard → d_list again (the solve list is done with by then)
  std::uint32_t* d_list2 = r.ws.narrow_list.template span_as<std::uint32_t>(np).data();
  unsigned long long* d_n_hard = &r.d_counters->hard;
  unsigned long long* d_n_unsettled = &r.d_counters->unsettled;
  unsigned long long* d_n_solve = &r.d_counters->to_solve;
  const std::uint32_t* a = r.pair_a.Current();
  const std::uint32_t* b = r.pair_b.Current();
  r.events.mark_narrow_split(0, st);
  if (decide.centre_cut && r.job.ellipsoids == r.n64) {  // ellipsoids alone, cut: one triage kernel
    cuda::narrow_triage_kernel<Narrow, true><<<blocks_for(np), kBlock, 0, st>>>(
        a, b, np, decide, d_verdict, d_normal, nullptr, d_list2, d_carry, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow_triage");
  } else {
    cuda::narrow_triage_kernel<Narrow, false><<<blocks_for(np), kBlock, 0, st>>>(
        a, b, np, decide, d_verdict, d_normal, d_list, d_list2, nullptr, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow_screen");
    cuda::narrow_list_kernel<Narrow, cuda::ListPass::first><<<blocks_for(np), kBlock, 0, st>>>(
        a, b, d_list, d_n_solve, decide, d_verdict, d_normal, d_list2, d_n_unsettled, r.d_counters, d_carry);
    CG_CUDA_CHECK_LAUNCH("narrow_first_pass");
  }
  r.events.mark_narrow_split(1, st);
  cuda::narrow_list_kernel<Narrow, cuda::ListPass::settle><<<blocks_for(np), kBlock, 0, st>>>(
      a, b, d_list2, d_n_unsettled, decide, d_verdict, d_normal, d_list, d_n_hard, r.d_counters, d_carry);
  CG_CUDA_CHECK_LAUNCH("narrow_settle");
  r.events.mark_narrow_split(2, st);
  // the whole start set: a lane group per pair while the list is short (a few pairs per resident group),
  // else one thread per pair; each kernel reads the count on the device and leaves the other's lists
  constexpr int kLanes = cuda::kSolveLanes<Narrow>;
  int warp_blocks = 0;
  const unsigned long long warp_limit = whole_warp_plan<Narrow>(r.tuning, warp_blocks);
  if (warp_limit > 0) {
    cuda::narrow_whole_warp_kernel<Narrow, kLanes><<<warp_blocks, kBlock, 0, st>>>(
        a, b, d_list, d_n_hard, warp_limit, decide, d_verdict, d_normal, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow_hard_warp");
  }
  cuda::narrow_list_kernel<Narrow, cuda::ListPass::whole>
      <<<blocks_for(np), kBlock, 0, st>>>(a, b, d_list, d_n_hard, decide, d_verdict, d_normal, nullptr,
                                          nullptr, r.d_counters, nullptr, warp_limit);
  CG_CUDA_CHECK_LAUNCH("narrow_hard");
  if constexpr (std::is_same_v<Narrow, float>) {
    cuda::narrow_hard_fp64_kernel<Narrow><<<cuda::kRareBlocks, kBlock, 0, st>>>(
        a, b, d_list, d_n_hard, decide, d_verdict, d_normal, d_list2, r.d_counters);  // (list2 done with)
    CG_CUDA_CHECK_LAUNCH("narrow_hard_fp64");
  }
  r.events.mark_narrow_split(3, st);
  return d_normal;
}

}  // namespace cg::detail
