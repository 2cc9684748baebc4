#pragma once
// The contact stage of the granular dynamics on the device: contact_terms of every contact row
// (core/dem_step.hpp), one thread per row, over the engine's device-resident contacts; then this
// step's springs become the last step's.
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

template <class Real>
__global__ void dem_contact_kernel(dem::ContactRows<Real> rows, dem::BodyArrays b, dem::StepConstants c,
                                   dem::ContactTerms t) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= rows.count) return;
  dem::contact_terms(k, rows, b, c, t);
}

}  // namespace cg::cuda

namespace cg::detail {

// The rows of the engine's view.
template <class Real>
dem::ContactRows<Real> contact_rows(const DeviceContactsView<Real>& v) {
  return {v.id_a,        v.id_b,     v.position_on_a, v.position_on_b,
          v.normal_on_b, v.distance, v.previous_row,  v.count};
}

template <class Real>
void dem_contact_stage(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c) {
  const std::size_t k = rows.count;
  const int next = 1 - d.current;
  for (DemBuffer<Vec3<double>>* b :
       {&d.contact_force, &d.torque_a, &d.torque_b, &d.xi[next], &d.normal[next]})
    b->reserve(k, true);
  d.contact_energy.reserve(k, true);
  const dem::ContactTerms t{d.contact_force.data(),  d.torque_a.data(),         d.torque_b.data(),
                            d.contact_energy.data(), d.xi[next].data(),         d.normal[next].data(),
                            d.xi[d.current].data(),  d.normal[d.current].data()};
  if (k > 0) {
    cuda::dem_contact_kernel<Real><<<cuda::blocks_for(k), cuda::kBlock>>>(rows, d.arrays(), c, t);
    CG_CUDA_CHECK_LAUNCH("dem_contact");
  }
  d.current = next;
}

}  // namespace cg::detail
