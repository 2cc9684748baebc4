#pragma once
// Stage bounds (device-array API): validation and bounds of DEVICE bodies, as compute_bounds.
#include <cstring>
#include <string>

#include "cuda/common.cuh"
#include "cuda/workspace.cuh"

namespace cg::cuda {

// Per-block partial bounds (device_bounds): box, r_min, r_max and the radius moments Σ r, Σ r², Σ r³.
// r_min sizes the levels of BroadPhase::levels (plan_levels), enters auto's choice of broad phase and
// --precision auto's accuracy: the device's bounds carry it as compute_bounds does.
struct BoundsPartial {
  double lo[3], hi[3], r_min, r_max, r_sum[3];
};
// The values folded, in this order: lo[3], r_min (min); hi[3], r_max (max); r_sum[3] (sums).
constexpr int kBoundsValues = 11;
constexpr int kBoundsMins = 4, kBoundsMaxes = 8;  // values [0, 4): min; [4, 8): max; the rest: sum

// Folds value v of b into a.
__device__ __forceinline__ double fold_bound(int v, double a, double b) {
  if (v < kBoundsMins) return b < a ? b : a;
  if (v < kBoundsMaxes) return b > a ? b : a;
  return a + b;
}

// A partial's values in fold order, and back.
__device__ __forceinline__ void bounds_values(const BoundsPartial& p, double* v) {
  for (int k = 0; k < 3; ++k) {
    v[k] = p.lo[k];
    v[4 + k] = p.hi[k];
    v[8 + k] = p.r_sum[k];
  }
  v[3] = p.r_min;
  v[7] = p.r_max;
}
__device__ __forceinline__ void bounds_partial(const double* v, BoundsPartial& p) {
  for (int k = 0; k < 3; ++k) {
    p.lo[k] = v[k];
    p.hi[k] = v[4 + k];
    p.r_sum[k] = v[8 + k];
  }
  p.r_min = v[3];
  p.r_max = v[7];
}
// The values of no body (the identity of every fold).
__device__ __forceinline__ double bounds_identity(int v) {
  return v < kBoundsMins ? INFINITY : (v < kBoundsMaxes ? -INFINITY : 0.0);
}

// Bounds of the bodies' boxes (p ± r, as compute_bounds), r_min, r_max and the radius moments, one partial
// per block (grid-stride). Records the first invalid body in c->bad. min/max are exact: same bits as
// the host; the moments (used only to choose the cell edge) are summed in a fixed order.
__global__ void bounds_partial_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                                      std::uint64_t n, BoundsPartial* __restrict__ partial,
                                      Counters* __restrict__ c) {
  __shared__ double sh[kBoundsValues][kBlock];
  double acc[kBoundsValues];
  for (int v = 0; v < kBoundsValues; ++v) acc[v] = bounds_identity(v);
  for (std::uint64_t i = std::uint64_t(blockIdx.x) * kBlock + threadIdx.x; i < n;
       i += std::uint64_t(gridDim.x) * kBlock) {
    const double p[3] = {pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
    const double r = rad[i];
    if (body_is_bad(p[0], p[1], p[2], r)) atomicMax(&c->bad, static_cast<unsigned long long>(n - i));
    for (int k = 0; k < 3; ++k) {
      const double lo = p[k] - r, hi = p[k] + r;
      acc[k] = lo < acc[k] ? lo : acc[k];
      acc[4 + k] = hi > acc[4 + k] ? hi : acc[4 + k];
    }
    acc[3] = r < acc[3] ? r : acc[3];
    acc[7] = r > acc[7] ? r : acc[7];
    acc[8] += r;
    acc[9] += r * r;
    acc[10] += r * r * r;
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
    double v[kBoundsValues];
    for (int k = 0; k < kBoundsValues; ++k) v[k] = sh[k][0];
    bounds_partial(v, partial[blockIdx.x]);
  }
}

// One block of kBoundsFold threads folds the partials (count <= kBoundsFold) into partial[0].
constexpr int kBoundsFold = 512;
__global__ void __launch_bounds__(kBoundsFold) bounds_final_kernel(BoundsPartial* partial, int count) {
  __shared__ double sh[kBoundsValues][kBoundsFold];
  const int t = threadIdx.x;
  double v[kBoundsValues];
  if (t < count) {
    bounds_values(partial[t], v);
  } else {
    for (int k = 0; k < kBoundsValues; ++k) v[k] = bounds_identity(k);
  }
  for (int k = 0; k < kBoundsValues; ++k) sh[k][t] = v[k];
  __syncthreads();
  for (int s = kBoundsFold / 2; s > 0; s >>= 1) {
    if (t < s)
      for (int v = 0; v < kBoundsValues; ++v) sh[v][t] = fold_bound(v, sh[v][t], sh[v][t + s]);
    __syncthreads();
  }
  if (t == 0) {
    for (int k = 0; k < kBoundsValues; ++k) v[k] = sh[k][0];
    bounds_partial(v, partial[0]);
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// The first invalid body (index i of n, read back from the device): throws compute_bounds' text.
[[noreturn]] inline void throw_bad_body(const double* d_pos, const double* d_rad, std::uint64_t i,
                                        std::int64_t id) {
  Vec3<double> p{};
  double r = 0;
  CG_CUDA_CHECK(cudaMemcpy(&p, d_pos + 3 * i, sizeof(p), cudaMemcpyDeviceToHost));
  CG_CUDA_CHECK(cudaMemcpy(&r, d_rad + i, sizeof(r), cudaMemcpyDeviceToHost));
  compute_bounds(BodiesView{{&p, 1}, {&r, 1}, {&id, 1}, {}});  // throws InputError naming `id`
  throw Error("internal: the device flagged body " + std::to_string(id) + " but it is valid");
}

// Validation and bounds of DEVICE bodies (same results and InputError texts as compute_bounds):
// partials per block, one folding block, one read back (synchronises the stream). `also(d_counters)`
// queues more checks of the bodies into the same counters before the read back (the shape rows:
// shapes.cuh), so that the call waits once; `counters` is what they read back.
template <class Also>
Bounds bounds_stage(Workspace& ws, cuda::PinnedBuffer& h_staging, cudaStream_t st, const DeviceBodiesView& v,
                    const Also& also, cuda::Counters& counters) {
  using cuda::BoundsPartial;
  using cuda::Counters;
  constexpr int kBoundsBlocks = 512;  // partials (<= cuda::kBoundsFold)
  Bounds b;
  b.count = v.count;
  if (v.count == 0) return b;
  ws.reserve({{&ws.partials, kBoundsBlocks * sizeof(BoundsPartial)}, {&ws.counters, sizeof(Counters)}},
             "bounds");
  h_staging.reserve(sizeof(Counters) + sizeof(BoundsPartial));
  auto* d_partials = ws.partials.span_as<BoundsPartial>(kBoundsBlocks).data();
  auto* d_counters = ws.counters.span_as<Counters>(1).data();
  const int grid = static_cast<int>(std::min<std::uint64_t>(kBoundsBlocks, cuda::blocks_for(v.count)));
  CG_CUDA_CHECK(cudaMemsetAsync(d_counters, 0, sizeof(Counters), st));
  cuda::bounds_partial_kernel<<<grid, cuda::kBlock, 0, st>>>(v.position, v.radius, v.count, d_partials,
                                                             d_counters);
  CG_CUDA_CHECK_LAUNCH("bounds_partial");
  cuda::bounds_final_kernel<<<1, cuda::kBoundsFold, 0, st>>>(d_partials, grid);
  CG_CUDA_CHECK_LAUNCH("bounds_final");
  also(d_counters);
  std::byte* h = h_staging.data();
  CG_CUDA_CHECK(cudaMemcpyAsync(h, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, st));
  CG_CUDA_CHECK(
      cudaMemcpyAsync(h + sizeof(Counters), d_partials, sizeof(BoundsPartial), cudaMemcpyDeviceToHost, st));
  CG_CUDA_CHECK(cudaStreamSynchronize(st));
  Counters& c = counters;
  BoundsPartial p;
  std::memcpy(&c, h, sizeof(c));
  std::memcpy(&p, h + sizeof(Counters), sizeof(p));
  if (c.bad) {
    const std::uint64_t i = v.count - c.bad;
    throw_bad_body(v.position, v.radius, i, static_cast<std::int64_t>(i));
  }
  b.lo = {p.lo[0], p.lo[1], p.lo[2]};
  b.hi = {p.hi[0], p.hi[1], p.hi[2]};
  b.r_max = p.r_max;
  b.r_min = p.r_min;
  for (int k = 0; k < 3; ++k) b.r_sum[k] = p.r_sum[k];
  return b;
}

}  // namespace cg::detail
