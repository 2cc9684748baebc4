#pragma once
// The integration stage of the granular dynamics on the device that has a pass of its own: kick_drift
// of every body (core/dem_body.hpp), one thread per body, where the last step's body stage has not
// done it already. The second half kick runs in the body stage's pass (dem_sums.cuh: DemThen).
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

__global__ void dem_kick_drift_kernel(dem::BodyArrays b, double dt) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  dem::BodyState s = b.state(i);
  dem::kick_drift(s, b.props[i], b.ellipsoid(i), dt);
  b.store(i, s);
}

}  // namespace cg::cuda

namespace cg::detail {

inline void dem_kick_drift_stage(CudaDem& d, double dt) {
  if (d.count == 0) return;
  cuda::dem_kick_drift_kernel<<<cuda::blocks_for(d.count), cuda::kBlock>>>(d.arrays(), dt);
  CG_CUDA_CHECK_LAUNCH("dem_kick_drift");
}

}  // namespace cg::detail
