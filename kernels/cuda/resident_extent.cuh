#pragma once
// Engine::mark_resident / resident_extent on the DEVICE (a step loop's frame and rebuild check): the
// resident centres copied aside at a mark; then, in one pass over the resident rows, the bounds of
// compute_bounds (box of p ± r, r_max, r_min, the radius moments), the largest squared displacement
// from the marked centres and the first invalid row; one small read back. No centre crosses to the host.
#include <cstring>
#include <span>

#include "cuda/bounds.cuh"
#include "cuda/common.cuh"
#include "cuda/device_buffer.cuh"
#include "cuda/workspace.cuh"

namespace cg::cuda {

// Per-block partial extent: values 0-2 lo (min), 3-5 hi (max), 6 r_max (max), 7 moved² (max), 8 r_min
// (min), 9-11 Σ r, Σ r², Σ r³ (sums).
constexpr int kExtentValues = 12;
constexpr int kExtentBlocks = 256;  // partials, folded by one block of as many threads
struct ExtentPartial {
  double v[kExtentValues];
};

__device__ __forceinline__ double fold_extent(int v, double a, double b) {
  if (v < 3 || v == 8) return b < a ? b : a;
  if (v < 8) return b > a ? b : a;
  return a + b;
}

__device__ __forceinline__ double extent_identity(int v) {
  if (v < 3 || v == 8) return INFINITY;
  if (v < 6) return -INFINITY;
  return 0.0;
}

// Folds the kBlock values of sh (one per thread) into sh[v][0] (blockDim.x == width, a power of two).
template <int Width>
__device__ __forceinline__ void fold_extent_block(double (&sh)[kExtentValues][Width]) {
  for (int s = Width / 2; s > 0; s >>= 1) {
    if (int(threadIdx.x) < s)
      for (int v = 0; v < kExtentValues; ++v)
        sh[v][threadIdx.x] = fold_extent(v, sh[v][threadIdx.x], sh[v][threadIdx.x + s]);
    __syncthreads();
  }
}

// One partial per block (grid-stride). `mark`: the marked centres, or null (no displacement). Records
// the first invalid row in c->bad (as bounds_partial_kernel). min / max are exact (the same bits as
// the host); the squared displacement is rounded as the host's (no contraction: --fmad=false).
__global__ void extent_partial_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                                      const double* __restrict__ mark, std::uint64_t n,
                                      ExtentPartial* __restrict__ partial, Counters* __restrict__ c) {
  __shared__ double sh[kExtentValues][kBlock];
  double acc[kExtentValues];
  for (int v = 0; v < kExtentValues; ++v) acc[v] = extent_identity(v);
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
    if (mark) {
      const double dx = p[0] - mark[3 * i], dy = p[1] - mark[3 * i + 1], dz = p[2] - mark[3 * i + 2];
      const double d2 = dx * dx + dy * dy + dz * dz;
      acc[7] = d2 > acc[7] ? d2 : acc[7];
    }
    acc[8] = r < acc[8] ? r : acc[8];
    acc[9] += r;
    acc[10] += r * r;
    acc[11] += r * r * r;
  }
  for (int v = 0; v < kExtentValues; ++v) sh[v][threadIdx.x] = acc[v];
  __syncthreads();
  fold_extent_block<kBlock>(sh);
  if (threadIdx.x == 0)
    for (int v = 0; v < kExtentValues; ++v) partial[blockIdx.x].v[v] = sh[v][0];
}

// One block of kExtentBlocks threads folds the partials (count <= kExtentBlocks) into partial[0].
__global__ void __launch_bounds__(kExtentBlocks) extent_final_kernel(ExtentPartial* partial, int count) {
  __shared__ double sh[kExtentValues][kExtentBlocks];
  const int t = threadIdx.x;
  for (int v = 0; v < kExtentValues; ++v) sh[v][t] = t < count ? partial[t].v[v] : extent_identity(v);
  __syncthreads();
  fold_extent_block<kExtentBlocks>(sh);
  if (t == 0)
    for (int v = 0; v < kExtentValues; ++v) partial[0].v[v] = sh[v][0];
}

}  // namespace cg::cuda

namespace cg::detail {

// The resident centres (n rows of `pos`) copied into `mark` (grown to fit), on the stream.
inline void mark_stage(Workspace& ws, Bytes& mark, cudaStream_t st, const double* pos, std::size_t n) {
  const std::size_t bytes = n * 3 * sizeof(double);
  ws.reserve({{&mark, bytes}}, "resident mark");
  if (bytes > 0) CG_CUDA_CHECK(cudaMemcpyAsync(mark.data(), pos, bytes, cudaMemcpyDeviceToDevice, st));
}

// The extent of n resident rows (`mark`: the marked centres, or null): partials, one folding block,
// one read back (synchronises the stream). A bad row throws compute_bounds' text naming ids[row]
// (row index without ids). `displacement`: the largest distance from the mark (0 without one).
inline Bounds extent_stage(Workspace& ws, cuda::PinnedBuffer& h_staging, cudaStream_t st, const double* pos,
                           const double* rad, const double* mark, std::size_t n,
                           std::span<const std::int64_t> ids, double& displacement) {
  using cuda::Counters;
  using cuda::ExtentPartial;
  Bounds b;
  b.count = n;
  displacement = 0;
  if (n == 0) return b;
  ws.reserve({{&ws.partials, cuda::kExtentBlocks * sizeof(ExtentPartial)}, {&ws.counters, sizeof(Counters)}},
             "resident extent");
  h_staging.reserve(sizeof(Counters) + sizeof(ExtentPartial));
  auto* d_partials = ws.partials.span_as<ExtentPartial>(cuda::kExtentBlocks).data();
  auto* d_counters = ws.counters.span_as<Counters>(1).data();
  const int grid = static_cast<int>(std::min<std::uint64_t>(cuda::kExtentBlocks, cuda::blocks_for(n)));
  CG_CUDA_CHECK(cudaMemsetAsync(d_counters, 0, sizeof(Counters), st));
  cuda::extent_partial_kernel<<<grid, cuda::kBlock, 0, st>>>(pos, rad, mark, n, d_partials, d_counters);
  CG_CUDA_CHECK_LAUNCH("extent_partial");
  cuda::extent_final_kernel<<<1, cuda::kExtentBlocks, 0, st>>>(d_partials, grid);
  CG_CUDA_CHECK_LAUNCH("extent_final");
  std::byte* h = h_staging.data();
  CG_CUDA_CHECK(cudaMemcpyAsync(h, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, st));
  CG_CUDA_CHECK(
      cudaMemcpyAsync(h + sizeof(Counters), d_partials, sizeof(ExtentPartial), cudaMemcpyDeviceToHost, st));
  CG_CUDA_CHECK(cudaStreamSynchronize(st));
  Counters c;
  ExtentPartial p;
  std::memcpy(&c, h, sizeof(c));
  std::memcpy(&p, h + sizeof(Counters), sizeof(p));
  if (c.bad) {
    const std::uint64_t i = n - c.bad;
    throw_bad_body(pos, rad, i, ids.empty() ? static_cast<std::int64_t>(i) : ids[i]);
  }
  b.lo = {p.v[0], p.v[1], p.v[2]};
  b.hi = {p.v[3], p.v[4], p.v[5]};
  b.r_max = p.v[6];
  b.r_min = p.v[8];
  for (int k = 0; k < 3; ++k) b.r_sum[k] = p.v[9 + k];
  if (mark) displacement = std::sqrt(p.v[7]);
  return b;
}

}  // namespace cg::detail
