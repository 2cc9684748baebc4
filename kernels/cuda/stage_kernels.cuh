#pragma once
// The CUDA kernels of the Le Grand stages. Each mirrors one loop of kernels/host/host_backend.cpp and
// calls the same CG_HD functions of kernels/core/ in the same order, so every decision and every
// value is bit-identical to the CPU backend (no FMA contraction: --fmad=false; IEEE sqrt and div).
//
// Thread mapping: one thread per body (pack, fill_entries), per sorted entry (count_pairs,
// fill_pairs) or per pair (narrow); blocks of kBlock threads, no grid-stride loop in the
// count → fill pairs, so that a block's count kernel and fill kernel see the same items and the
// fill places its items with a block-wide exclusive scan plus the block's scanned total.
#include <cstdint>
#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>

#include "core/contact.hpp"
#include "core/grid.hpp"
#include "engine.hpp"

namespace cg::cuda {

constexpr int kBlock = 256;
constexpr int kStaged = kBlock + 32;  // count_pairs: a block's entries and the halo of its windows
// Bit 6 of a body's control byte (bits 0-5: control_bits) is its report flag when a report mask is
// given: the pair walk then reads the flag with the control byte it already holds, instead of a
// random read of the mask by input index per visit (at 2^26 on 2 H200 ranks the pairs stage took
// 5.5 ms per rank instead of about half of the single rank's 6.5 ms).
constexpr std::uint32_t kReportBit = 0x40u;
constexpr std::uint32_t kPairedCtrlBit = 0x80u;  // the mask's kPairedBit, likewise
#ifndef CG_PAIRS_MIN_BLOCKS
#define CG_PAIRS_MIN_BLOCKS 6
#endif
// count_pairs: resident blocks per SM asked of ptxas (6: at most 40 registers, 75 % occupancy, a few
// bytes of spill; measured on the H100 at 2^24: pairs 1.84 -> 1.67 ms fp32, 2.41 -> 2.11 ms fp64).
constexpr int kPairsMinBlocks = CG_PAIRS_MIN_BLOCKS;

// DEVICE counters of one call; zeroed (cudaMemsetAsync) before the first kernel that adds to them.
struct Counters {
  unsigned long long entries;          // sum of entry counts (pack)
  unsigned long long pairs;            // contacting pairs (count_pairs)
  unsigned long long tests;            // sphere tests made (count_pairs)
  unsigned long long bad;              // n - i of the first invalid body i (atomicMax), 0: none
  unsigned long long type_entries[8];  // entries per cell type (reorder, type-pass path only)
};

// Per-block partial bounds (device_bounds): box, r_max and the radius moments Σ r, Σ r², Σ r³.
struct BoundsPartial {
  double lo[3], hi[3], r_max, r_sum[3];
};
constexpr int kBoundsValues = 10;  // lo[3], hi[3], r_max: min/max; r_sum[3]: sums

// Folds value v of b into a (min for 0–2, max for 3–6, sum for 7–9).
__device__ __forceinline__ double fold_bound(int v, double a, double b) {
  if (v < 3) return b < a ? b : a;
  if (v < 7) return b > a ? b : a;
  return a + b;
}

// Pointers of the contact arrays in DEVICE memory; the `full` four are null for Fields::basic.
template <class Real>
struct ContactPtrs {
  std::int64_t *id_a, *id_b;
  Vec3<Real>*position_on_a, *position_on_b, *normal_on_b;
  Real* distance;
  Vec3<Real>*local_point_a, *local_point_b, *dir1, *dir2;
};

__device__ __forceinline__ bool body_is_bad(double x, double y, double z, double r) {
  return !isfinite(x) || !isfinite(y) || !isfinite(z) || !(r > 0) || !isfinite(r);
}

// Bounds of the bodies' boxes (p ± r, as compute_bounds), r_max and the radius moments, one partial
// per block (grid-stride). Records the first invalid body in c->bad. min/max are exact: same bits as
// the host; the moments (used only to choose the cell edge) are summed in a fixed order.
__global__ void bounds_partial_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                                      std::uint64_t n, BoundsPartial* __restrict__ partial,
                                      Counters* __restrict__ c) {
  __shared__ double sh[kBoundsValues][kBlock];
  double acc[kBoundsValues] = {INFINITY,  INFINITY, INFINITY, -INFINITY, -INFINITY,
                               -INFINITY, 0.0,      0.0,      0.0,       0.0};
  for (std::uint64_t i = std::uint64_t(blockIdx.x) * kBlock + threadIdx.x; i < n;
       i += std::uint64_t(gridDim.x) * kBlock) {
    const double p[3] = {pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
    const double r = rad[i];
    if (body_is_bad(p[0], p[1], p[2], r)) atomicMax(&c->bad, static_cast<unsigned long long>(n - i));
    for (int k = 0; k < 3; ++k) {
      const double lo = p[k] - r, hi = p[k] + r;
      acc[k] = lo < acc[k] ? lo : acc[k];
      acc[3 + k] = hi > acc[3 + k] ? hi : acc[3 + k];
    }
    acc[6] = r > acc[6] ? r : acc[6];
    acc[7] += r;
    acc[8] += r * r;
    acc[9] += r * r * r;
  }
  for (int v = 0; v < kBoundsValues; ++v) sh[v][threadIdx.x] = acc[v];
  __syncthreads();
  for (int s = kBlock / 2; s > 0; s >>= 1) {
    if (int(threadIdx.x) < s)
      for (int v = 0; v < kBoundsValues; ++v)
        sh[v][threadIdx.x] = fold_bound(v, sh[v][threadIdx.x], sh[v][threadIdx.x + s]);
    __syncthreads();
  }
  if (threadIdx.x == 0) {
    for (int k = 0; k < 3; ++k) {
      partial[blockIdx.x].lo[k] = sh[k][0];
      partial[blockIdx.x].hi[k] = sh[3 + k][0];
      partial[blockIdx.x].r_sum[k] = sh[7 + k][0];
    }
    partial[blockIdx.x].r_max = sh[6][0];
  }
}

// One block of kBoundsFold threads folds the partials (count <= kBoundsFold) into partial[0].
constexpr int kBoundsFold = 512;
__global__ void __launch_bounds__(kBoundsFold) bounds_final_kernel(BoundsPartial* partial, int count) {
  __shared__ double sh[kBoundsValues][kBoundsFold];
  const int t = threadIdx.x;
  if (t < count) {
    for (int k = 0; k < 3; ++k) {
      sh[k][t] = partial[t].lo[k];
      sh[3 + k][t] = partial[t].hi[k];
      sh[7 + k][t] = partial[t].r_sum[k];
    }
    sh[6][t] = partial[t].r_max;
  } else {
    for (int k = 0; k < 3; ++k) {
      sh[k][t] = INFINITY;
      sh[3 + k][t] = -INFINITY;
      sh[7 + k][t] = 0.0;
    }
    sh[6][t] = 0.0;
  }
  __syncthreads();
  for (int s = kBoundsFold / 2; s > 0; s >>= 1) {
    if (t < s)
      for (int v = 0; v < kBoundsValues; ++v) sh[v][t] = fold_bound(v, sh[v][t], sh[v][t + s]);
    __syncthreads();
  }
  if (t == 0) {
    for (int k = 0; k < 3; ++k) {
      partial[0].lo[k] = sh[k][0];
      partial[0].hi[k] = sh[3 + k][0];
      partial[0].r_sum[k] = sh[7 + k][0];
    }
    partial[0].r_max = sh[6][0];
  }
}

// Locality key of a body: the layer of cells along z (the slowest axis of the cell key) holding its
// lowest cell, coarsened by `shift` to at most 256 layers so that the renumbering sort is one radix
// pass. The pair stage walks the cells in key order, z slowest, so the bodies it reads at any moment
// lie in a few consecutive layers, a few MiB that stay in L2 (the order within a layer matters
// little then: against a 4x4x4-cell block key and its two-pass sort, H100 2^24 cell 5, the pair stage
// was 3 % slower, 1.83 vs 1.78 ms, and pack 0.16 ms faster, 1.12 vs 1.28 ms). It changes no result:
// decisions are symmetric in the two bodies, and pairs are emitted and sorted by their original
// indices.
template <class Key>
__device__ __forceinline__ Key home_layer_key(const BodyCells& bc, int shift) {
  return Key(bc.lo[2] >> shift);
}

// pack: world (double) → local Real sphere `Real(p - origin)` in input order, and the (locality key,
// index) pairs of the renumbering sort. Invalid bodies → c->bad.
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    pack_kernel(const double* __restrict__ pos, const double* __restrict__ rad, std::uint32_t n,
                Vec3<double> origin, GridParams<Real> g, Sphere<Real>* __restrict__ spheres, int layer_shift,
                Key* __restrict__ home_key, std::uint32_t* __restrict__ home_index,
                Counters* __restrict__ c) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= n) return;
  const std::uint64_t i3 = 3 * std::uint64_t(i);
  const double px = pos[i3], py = pos[i3 + 1], pz = pos[i3 + 2], r = rad[i];
  if (body_is_bad(px, py, pz, r)) atomicMax(&c->bad, static_cast<unsigned long long>(n - i));
  const Sphere<Real> s{static_cast<Real>(px - origin.x), static_cast<Real>(py - origin.y),
                       static_cast<Real>(pz - origin.z), static_cast<Real>(r)};
  spheres[i] = s;
  home_key[i] = home_layer_key<Key>(body_cells(s, g), layer_shift);
  home_index[i] = i;
}

// True when a body with control byte `ctrl` overlaps a cell of type `type` (at most one: along each
// axis the cell is lo when its parity is the type's, else lo + 1, which needs the spill).
__host__ __device__ __forceinline__ bool has_type(std::uint32_t ctrl, std::uint32_t type) {
  return ((type ^ ctrl) & ~(ctrl >> 3) & 7u) == 0u;
}

// reorder: cell-ordered copy of the spheres (body j = input body perm[j]), control bytes, and per
// block the sum of the entry counts (block_entries[blockIdx.x]; total added to c->entries).
// Type-pass path (base != nullptr): also the super-cell index of the body's lowest even cell
// (cell_key of lo & ~1, type bits 0) and per block the number of bodies having a cell of each
// type (type_blocks[t * gridDim.x + blockIdx.x]; totals added to c->type_entries[t]).
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    reorder_kernel(const Sphere<Real>* __restrict__ spheres, std::uint32_t n, GridParams<Real> g,
                   const std::uint32_t* __restrict__ sorted_index, Sphere<Real>* __restrict__ cell_spheres,
                   std::uint8_t* __restrict__ ctrl, std::uint32_t* __restrict__ perm,
                   std::uint32_t* __restrict__ block_entries, Counters* __restrict__ c,
                   Key* __restrict__ base, std::uint32_t* __restrict__ type_blocks,
                   const std::uint8_t* __restrict__ report) {
  using Reduce = cub::BlockReduce<std::uint32_t, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  __shared__ std::uint32_t s_types[8];
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  if (base && threadIdx.x < 8) s_types[threadIdx.x] = 0;
  std::uint32_t count = 0, cb = 0;
  bool live = false;
  if (j < n) {
    const std::uint32_t i = sorted_index[j];
    const Sphere<Real> s = spheres[i];
    cell_spheres[j] = s;
    perm[j] = i;
    const BodyCells bc = body_cells(s, g);
    const std::uint32_t m = report ? report[i] : 0u;
    cb = control_bits(bc) | ((m & kReportedBit) ? kReportBit : 0u) | ((m & kPairedBit) ? kPairedCtrlBit : 0u);
    ctrl[j] = static_cast<std::uint8_t>(cb);
    count = entry_count(bc);
    live = true;
    if (base) base[j] = cell_key<Key>(bc.lo[0] & ~1u, bc.lo[1] & ~1u, bc.lo[2] & ~1u, g);
  }
  const std::uint32_t total = Reduce(tmp).Sum(count);
  if (base) {
    __syncthreads();  // s_types zeroed
    if (live)
      for (std::uint32_t t = 0; t < 8; ++t)
        if (has_type(cb, t)) atomicAdd(&s_types[t], 1u);
    __syncthreads();
    if (threadIdx.x < 8) {
      type_blocks[threadIdx.x * gridDim.x + blockIdx.x] = s_types[threadIdx.x];
      atomicAdd(&c->type_entries[threadIdx.x], static_cast<unsigned long long>(s_types[threadIdx.x]));
    }
  }
  if (threadIdx.x == 0) {
    block_entries[blockIdx.x] = total;
    atomicAdd(&c->entries, static_cast<unsigned long long>(total));
  }
}

// entries of one cell type (type-pass path): (super-cell index, body) of the cell-ordered bodies that
// overlap a cell of type `type`, body-ascending, at block_offset[blockIdx.x] - start + the body's rank
// among its block's such bodies (same block layout as reorder_kernel). The key is the lin part of
// cell_key (type bits dropped): base + one super-cell step along each axis where lo is odd and the
// type's parity even (the cell lo + 1 then starts the next super-cell).
template <class Key>
__global__ void __launch_bounds__(kBlock)
    fill_type_entries_kernel(const std::uint8_t* __restrict__ ctrl, const Key* __restrict__ base,
                             std::uint32_t n, std::uint32_t type, Key step_y, Key step_z,
                             const std::uint32_t* __restrict__ block_offset, std::uint32_t start,
                             Key* __restrict__ keys, std::uint32_t* __restrict__ body) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  std::uint32_t has = 0;
  Key key{};
  if (j < n) {
    const std::uint32_t cb = ctrl[j];
    if (has_type(cb, type)) {
      has = 1;
      const std::uint32_t d = cb & ~type & 7u;
      key = base[j] + Key(d & 1u) + ((d & 2u) ? step_y : Key(0)) + ((d & 4u) ? step_z : Key(0));
    }
  }
  std::uint32_t rank;
  Scan(tmp).ExclusiveSum(has, rank);
  if (has) {
    const std::uint32_t w = block_offset[blockIdx.x] - start + rank;
    keys[w] = key;
    body[w] = j;
  }
}

// entries: (cell key, body) of the cell-ordered bodies, body-ascending; body j's entries start at
// its block's scanned total plus its exclusive rank in the block (same block layout as
// reorder_kernel). Staged in shared memory so that the block writes its entries coalesced.
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    fill_entries_kernel(const Sphere<Real>* __restrict__ spheres, std::uint32_t n, GridParams<Real> g,
                        const std::uint32_t* __restrict__ block_offset, Key* __restrict__ keys,
                        std::uint32_t* __restrict__ body) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  __shared__ Key s_keys[8 * kBlock];
  __shared__ std::uint32_t s_body[8 * kBlock];
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  BodyCells bc{};
  std::uint32_t count = 0;
  if (i < n) {
    bc = body_cells(spheres[i], g);  // the same Real sphere and function as reorder: the same cells
    count = entry_count(bc);
  }
  std::uint32_t rank, total;
  Scan(tmp).ExclusiveSum(count, rank, total);
  for (std::uint32_t m = 0; m < count; ++m) {
    s_keys[rank + m] = body_cell_key<Key>(bc, m, g);
    s_body[rank + m] = i;
  }
  __syncthreads();
  const std::uint64_t base = block_offset[blockIdx.x];
  for (std::uint32_t t = threadIdx.x; t < total; t += kBlock) {
    keys[base + t] = s_keys[t];
    body[base + t] = s_body[t];
  }
}

// The host's for_each_contact for sorted entry e: tests against the later entries f >= f0 of its cell
// (f0 = e + 1 for the whole walk). Bodies are cell-ordered indices; perm maps them to input indices.
// The host visits a pair (a, b) of input indices a < b from a's entry and skips it when report[a] is
// 0; here the entry order within a cell follows the cell order, so the report flag of the smaller
// input index of the two decides (kReportBit of its control byte, set by reorder from the mask). Both tests
// are symmetric in the two bodies (bit for bit), so the decisions are the host's.
template <class Real>
struct EntryBody {  // what a visit needs of the first body of a pair
  std::uint32_t a, type, pa;
  std::uint8_t ca;
  Sphere<Real> sa;
};

template <class Real, class Emit>
__device__ __forceinline__ void visit(const EntryBody<Real>& x, std::uint32_t b, std::uint8_t cb,
                                      const Sphere<Real>& sb, std::uint32_t pb, const std::uint8_t* report,
                                      std::uint32_t& tests, Emit& emit) {
  // the report flag of the smaller input index; no pair of two bodies paired elsewhere
  if (report && (!((x.pa < pb ? x.ca : cb) & kReportBit) || (x.ca & cb & kPairedCtrlBit))) return;
  if (!test_in_cell(x.ca, cb, x.type)) return;
  ++tests;
  if (spheres_touch(x.sa, sb)) emit(x.a, b);
}

template <class Real, class Key, class Emit>
__device__ __forceinline__ std::uint32_t walk_from_memory(
    std::uint32_t f0, Key k, const EntryBody<Real>& x, const Key* __restrict__ keys,
    const std::uint32_t* __restrict__ body, std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
    const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
    const std::uint8_t* __restrict__ report, Emit&& emit) {
  std::uint32_t tests = 0;
  for (std::uint32_t f = f0; f < n_entries && keys[f] == k; ++f) {
    const std::uint32_t b = body[f];
    visit(x, b, ctrl[b], spheres[b], report ? perm[b] : 0u, report, tests, emit);
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
// last entry). Without the halo, the cell that straddles the block's end was walked from memory by
// up to a cell's worth of threads, a chain of dependent global loads that kept the whole block
// resident (the block's tail).
// Direct write: the block takes the range [base, base + block total) of the pair cursor c->pairs (one
// atomicAdd) and, when the range ends at or below `cap`, writes its pairs (pair_a[w], pair_b[w]) of
// input indices, a < b, there, each thread at base + its exclusive rank (same walk, emitting). When
// the cursor ends above cap, the host discards those writes and runs the scan → fill_pairs path
// from the masks instead. The pairs' order is the blocks' arrival order; the order stage sorts them.
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock, kPairsMinBlocks)
    count_pairs_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ body,
                       std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
                       const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
                       const std::uint8_t* __restrict__ report, int half_bits, std::uint32_t pass_type,
                       std::uint32_t* __restrict__ mask, std::uint32_t* __restrict__ block_pairs,
                       Counters* __restrict__ c, std::uint32_t* __restrict__ pair_a,
                       std::uint32_t* __restrict__ pair_b, unsigned long long cap) {
  using Reduce = cub::BlockReduce<unsigned long long, kBlock>;
  using Scan = cub::BlockScan<unsigned long long, kBlock>;
  __shared__ union {
    typename Reduce::TempStorage reduce;
    typename Scan::TempStorage scan;
  } tmp;
  __shared__ unsigned long long s_base;
  __shared__ Key s_key[kStaged];
  __shared__ std::uint32_t s_body[kStaged];
  __shared__ Sphere<Real> s_sphere[kStaged];
  __shared__ std::uint32_t s_perm[kStaged];
  __shared__ std::uint8_t s_ctrl[kStaged];
  const std::uint32_t base = blockIdx.x * kBlock;
  const std::uint32_t t = threadIdx.x;
  const std::uint32_t e = base + t;
  const bool valid = e < n_entries;
  const std::uint32_t end = n_entries - base < kStaged ? n_entries - base : kStaged;  // staged entries
  Key k{};
  EntryBody<Real> x{};
  if (valid) {
    k = keys[e];
    x.a = body[e];
    x.type = key_type(k, half_bits) | pass_type;  // type-pass path: keys hold no type bits
    x.ca = ctrl[x.a];
    x.sa = spheres[x.a];
    x.pa = report ? perm[x.a] : 0u;
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
    s_perm[h] = report ? perm[b] : 0u;
  }
  __syncthreads();
  std::uint32_t found = 0, tests = 0, bits = 0;
  if (valid) {
    const std::uint32_t lim = end < t + 32 ? end : t + 32;  // staged entries e + 1 .. e + 31
    std::uint32_t f = t + 1;
    auto mark_one = [&](std::uint32_t, std::uint32_t) {
      ++found;
      bits |= 1u << (f - t);
    };
    for (; f < lim && s_key[f] == k; ++f)
      visit(x, 0u, s_ctrl[f], s_sphere[f], s_perm[f], report, tests, mark_one);
    if (f == lim) {  // the cell may go on past the staged window: walk the rest from memory
      const std::uint32_t before = found;
      tests += walk_from_memory(base + f, k, x, keys, body, n_entries, ctrl, spheres, perm, report,
                                [&](std::uint32_t, std::uint32_t) { ++found; });
      if (found != before) bits |= 1u;
    }
    mask[e] = bits;
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
  unsigned long long w = s_base + rank;
  const std::uint32_t pa = report ? x.pa : perm[x.a];
  auto emit = [&](std::uint32_t, std::uint32_t b) {
    const std::uint32_t pb = perm[b];  // input indices, a < b as the host
    pair_a[w] = pa < pb ? pa : pb;
    pair_b[w] = pa < pb ? pb : pa;
    ++w;
  };
  if (bits & 1u) {
    walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report, emit);
  } else {
    for (std::uint32_t m = bits; m != 0; m &= m - 1) emit(x.a, s_body[t + __ffs(m) - 1]);
  }
}

// pairs, fill: pairs (pair_a[w], pair_b[w]) of input indices, a < b, at w = the block's scanned total +
// the entry's rank, from the contact masks of count_pairs_kernel (entries flagged in bit 0: the cell
// is walked from memory again, counting then emitting).
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    fill_pairs_kernel(const Key* __restrict__ keys, const std::uint32_t* __restrict__ body,
                      std::uint32_t n_entries, const std::uint8_t* __restrict__ ctrl,
                      const Sphere<Real>* __restrict__ spheres, const std::uint32_t* __restrict__ perm,
                      const std::uint8_t* __restrict__ report, int half_bits,
                      const std::uint32_t* __restrict__ mask, const std::uint32_t* __restrict__ block_offset,
                      std::uint32_t* __restrict__ pair_a, std::uint32_t* __restrict__ pair_b) {
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
    x.pa = report ? perm[x.a] : 0u;
    walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report,
                     [&](std::uint32_t, std::uint32_t) { ++mine; });
  } else {
    mine = __popc(bits);
  }
  std::uint32_t rank;
  Scan(tmp).ExclusiveSum(mine, rank);
  if (mine == 0) return;
  std::uint32_t w = block_offset[blockIdx.x] + rank;
  auto emit = [&](std::uint32_t a, std::uint32_t b) {
    const std::uint32_t pa = perm[a], pb = perm[b];  // input indices, a < b as the host
    pair_a[w] = pa < pb ? pa : pb;
    pair_b[w] = pa < pb ? pb : pa;
    ++w;
  };
  if (bits & 1u) {
    walk_from_memory(e + 1, k, x, keys, body, n_entries, ctrl, spheres, perm, report, emit);
  } else {
    const std::uint32_t a = body[e];
    for (std::uint32_t m = bits; m != 0; m &= m - 1) emit(a, body[e + __ffs(m) - 1]);
  }
}

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

// narrow: contact data of each sorted pair, world frame as the host: Real(double(origin) + double(v)).
template <class Real>
__global__ void __launch_bounds__(kBlock)
    narrow_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                  std::uint32_t n_pairs, const Sphere<Real>* __restrict__ spheres, Vec3<double> origin,
                  ContactPtrs<Real> out, bool full) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = pair_a[k], b = pair_b[k];
  const Sphere<Real> sa = spheres[a], sb = spheres[b];
  const ContactRow<Real> row = sphere_contact_row(sa, sb, origin, full);  // core/contact.hpp
  out.id_a[k] = a;
  out.id_b[k] = b;
  out.position_on_a[k] = row.position_on_a;
  out.position_on_b[k] = row.position_on_b;
  out.normal_on_b[k] = row.normal_on_b;
  out.distance[k] = row.distance;
  if (full) {
    out.local_point_a[k] = row.local_point_a;
    out.local_point_b[k] = row.local_point_b;
    out.dir1[k] = row.lateral_friction_dir1;
    out.dir2[k] = row.lateral_friction_dir2;
  }
}

}  // namespace cg::cuda
