#pragma once
// The integration stages of the granular dynamics on the device: kick_drift and kick of every body
// (core/dem_body.hpp), one thread per body.
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

template <bool kDrift>
__global__ void dem_integrate_kernel(dem::BodyArrays b, double dt) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  dem::BodyState s = b.state(i);
  if (kDrift)
    dem::kick_drift(s, b.props[i], b.ellipsoid(i), dt);
  else
    dem::kick(s, b.props[i], b.ellipsoid(i), dt);
  b.store(i, s);
}

}  // namespace cg::cuda

namespace cg::detail {

template <bool kDrift>
void dem_integrate_stage(CudaDem& d, double dt) {
  if (d.count == 0) return;
  cuda::dem_integrate_kernel<kDrift><<<cuda::blocks_for(d.count), cuda::kBlock>>>(d.arrays(), dt);
  CG_CUDA_CHECK_LAUNCH("dem_integrate");
}

}  // namespace cg::detail
