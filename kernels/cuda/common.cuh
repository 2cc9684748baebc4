#pragma once
// What the CUDA stages share: block size, control-byte flags, the DEVICE counters of a call, the
// contact array pointers, and small host helpers. Each stage's kernels mirror one loop of the CPU
// backend (kernels/host/) and call the same CG_HD functions of kernels/core/ in the same order, so
// every decision and every value is bit-identical to it (no FMA contraction: --fmad=false; IEEE sqrt
// and div).
//
// Thread mapping: one thread per body (pack, fill_entries), per sorted entry (count_pairs,
// fill_pairs) or per pair (narrow); blocks of kBlock threads, no grid-stride loop in the
// count → fill pairs, so that a block's count kernel and fill kernel see the same items and the
// fill places its items with a block-wide exclusive scan plus the block's scanned total.
#include <cstdint>
#include <cub/block/block_reduce.cuh>
#include <cub/block/block_scan.cuh>

#include "core/contact.hpp"
#include "core/contact_fields.hpp"
#include "core/grid.hpp"
#include "cuda/device_buffer.cuh"
#include "engine.hpp"

namespace cg::cuda {

constexpr int kBlock = 256;
constexpr int kStaged = kBlock + 32;  // count_pairs: a block's entries and the halo of its windows
// Bit 6 of a body's control byte (bits 0-5: control_bits) is its report flag when a report mask is
// given: the pair walk then reads the flag with the control byte it already holds, instead of a
// random read of the mask by input index per visit, which would cost a rank of a multi-GPU run most
// of its share of the pair stage (BENCHMARKS.md §4).
constexpr std::uint32_t kReportBit = 0x40u;
constexpr std::uint32_t kPairedCtrlBit = 0x80u;  // the mask's kPairedBit, likewise
#ifndef CG_PAIRS_MIN_BLOCKS
#define CG_PAIRS_MIN_BLOCKS 6
#endif
// count_pairs: resident blocks per SM asked of ptxas (6: at most 40 registers, 75 % occupancy, a few
// bytes of spill; the fastest pair stage on the H100, BENCHMARKS.md §11).
constexpr int kPairsMinBlocks = CG_PAIRS_MIN_BLOCKS;

// The pair stage's estimate on the device (pair_estimate.cuh): Σ m·(m − 1)/2 and the fullest cell.
struct CellWork {
  unsigned long long tests, largest;
};

// DEVICE counters of one call; zeroed (cudaMemsetAsync) before the first kernel that adds to them.
struct Counters {
  unsigned long long entries;          // sum of entry counts (pack)
  unsigned long long pairs;            // contacting pairs (count_pairs)
  unsigned long long tests;            // sphere tests made (count_pairs)
  unsigned long long bad;              // n - i of the first invalid body i (atomicMax), 0: none
  unsigned long long type_entries[8];  // entries per cell type (reorder, type-pass path only)
  // shapes (cuda/shapes.cuh, narrow.cuh): n - i of the first body with bad shape rows (atomicMax),
  // ellipsoids counted, and the ellipsoid solver's flags (narrow accept pass)
  unsigned long long bad_shape, ellipsoids, fallbacks, unconverged;
  // narrow, scenes with ellipsoids: the general pairs the screen left to the first start (`to_solve`),
  // the candidates the triage pass left to the settle pass (`unsettled`)
  // and those the settle pass left to the whole solve (`hard`) (the lengths of the lists each pass
  // appends to, read by the next kernel on the device and by the host with the other counters)
  unsigned long long to_solve, unsettled, hard;
  unsigned long long fp64_rows;   // fp32 rows recomputed in fp64 (narrow.cuh)
  unsigned long long fp64_pairs;  // fp32's pairs solved in fp64, listed for their rows (narrow_shapes.cuh)
  unsigned long long rows;        // the rejecting narrow's accepted candidates: its row count (narrow.cuh)
  // the ellipsoid solver's work (narrow_shapes.cuh: NarrowFlags, summed; the largest by atomicMax)
  unsigned long long solver_runs, evaluations, max_evaluations;
  // skin check (cuda/skin.cuh): the bits of the largest squared displacement and radius growth
  // (non-negative doubles order as their bits), and whether a report byte changed; a cut list: the
  // largest move of a body's point (turned_motion), whether a kind or semi-axes changed and whether
  // an ellipsoid turned
  unsigned long long skin_moved_sq, skin_growth, skin_report_changed;
  unsigned long long skin_turned, skin_shape_changed, skin_body_turned;
  CellWork cell_work;            // written (not added to) by the estimate's reduction
  unsigned long long long_runs;  // order: runs of equal a left to the segmented sort (order.cuh)
};

// Pointers of the contact arrays in DEVICE memory (core/contact_fields.hpp); the optional ones are
// null for Fields::basic.
template <class Real>
using ContactPtrs = ContactColumns<Real, Ptr>;

__device__ __forceinline__ bool body_is_bad(double x, double y, double z, double r) {
  return !isfinite(x) || !isfinite(y) || !isfinite(z) || !(r > 0) || !isfinite(r);
}

// True when a body with control byte `ctrl` overlaps a cell of type `type` (at most one: along each
// axis the cell is lo when its parity is the type's, else lo + 1, which needs the spill).
__host__ __device__ __forceinline__ bool has_type(std::uint32_t ctrl, std::uint32_t type) {
  return ((type ^ ctrl) & ~(ctrl >> 3) & 7u) == 0u;
}

inline std::uint32_t blocks_for(std::uint64_t n) {
  return static_cast<std::uint32_t>((n + kBlock - 1) / kBlock);
}
inline std::size_t align16(std::size_t b) { return (b + 15) & ~std::size_t(15); }

// out[k] = in[index[k]], k < m: an array gathered into another order (spheres into the sweep's or the
// cell order, a column of rows into (a, b) order).
template <class T>
__global__ void __launch_bounds__(kBlock)
    gather_kernel(const T* __restrict__ in, const std::uint32_t* __restrict__ index, std::size_t m,
                  T* __restrict__ out) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k < m) out[k] = in[index[k]];
}

// An asynchronous copy of `bytes` between device buffers on `st` (none for 0 bytes).
inline void device_copy(void* dst, const void* src, std::size_t bytes, cudaStream_t st) {
  if (bytes > 0) CG_CUDA_CHECK(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyDeviceToDevice, st));
}

}  // namespace cg::cuda
