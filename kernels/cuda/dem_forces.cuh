#pragma once
// The contact stage of the granular dynamics on the device: each contact row's terms
// (core/dem_step.hpp: contact_result), one thread per row, over the engine's device-resident
// contacts; then this step's springs become the last step's. Two ways (tuning: CONTACTGRID_DEM_TERMS):
//   sums              the kernel also sums each body's rows as A (the rows are sorted by A, so a body's
//                     rows as A are one run): a block keeps its rows' force and torque on A in shared
//                     memory, and the thread of the first row of each run adds the run's terms in row
//                     order, from zero (a run that goes on past the block's last row: its further
//                     rows computed again by that thread, the same function of the same inputs, the
//                     same bits). It stores each body's sums (a_force, a_torque) and, per row, only
//                     what the body stage still needs (the force and torque on B, the spring, the
//                     normal, the energy): no torque on A per row, and the body stage reads no rows
//                     as A (dem_sums.cuh).
//   rows (default)    contact_terms of every row (every term stored); the body stage sums both sides:
//                     on the H100 the faster of the two (the sums' runs keep a block's threads waiting
//                     on the run's first thread).
// The same sums in the same order either way: the bits of the CPU backend.
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

template <class Real>
__global__ void dem_contact_a_kernel(dem::ContactRows<Real> rows, dem::BodyArrays b, dem::StepConstants c,
                                     dem::ContactTerms t, Vec3<double>* a_force, Vec3<double>* a_torque) {
  __shared__ Vec3<double> force[kBlock], torque_a[kBlock];
  const std::size_t first = std::size_t(blockIdx.x) * kBlock, k = first + threadIdx.x;
  const std::size_t end = first + kBlock < rows.count ? first + kBlock : rows.count;
  if (k < rows.count) {
    const dem::ContactResult r = dem::contact_result(k, rows, b, c, t.old_xi, t.old_normal);
    t.force[k] = r.force;
    t.torque_b[k] = r.torque_b;
    t.energy[k] = r.energy;
    t.xi[k] = r.xi;
    t.normal[k] = r.normal;
    force[threadIdx.x] = r.force;
    torque_a[threadIdx.x] = r.torque_a;
  }
  __syncthreads();
  if (k >= rows.count) return;
  const std::int64_t a = rows.id_a[k];
  if (k > 0 && rows.id_a[k - 1] == a) return;  // not the first row of its body's run
  Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
  for (std::size_t j = k; j < rows.count && rows.id_a[j] == a; ++j) {
    if (j < end) {
      f = f + force[j - first];
      tau = tau + torque_a[j - first];
    } else {
      const dem::ContactResult r = dem::contact_result(j, rows, b, c, t.old_xi, t.old_normal);
      f = f + r.force;
      tau = tau + r.torque_a;
    }
  }
  a_force[a] = f;
  a_torque[a] = tau;
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
  for (DemBuffer<Vec3<double>>* b : {&d.contact_force, &d.torque_b, &d.xi[next], &d.normal[next]})
    b->reserve(k, true);
  if (!d.a_sums) d.torque_a.reserve(k, true);
  d.contact_energy.reserve(k, true);
  const dem::ContactTerms t{d.contact_force.data(), d.a_sums ? nullptr : d.torque_a.data(),
                            d.torque_b.data(),      d.contact_energy.data(),
                            d.xi[next].data(),      d.normal[next].data(),
                            d.xi[d.current].data(), d.normal[d.current].data()};
  if (k > 0 && d.a_sums) {
    d.a_force.reserve(std::max<std::size_t>(d.count, 1), true);
    d.a_torque.reserve(std::max<std::size_t>(d.count, 1), true);
    cuda::dem_contact_a_kernel<Real>
        <<<cuda::blocks_for(k), cuda::kBlock>>>(rows, d.arrays(), c, t, d.a_force.data(), d.a_torque.data());
    CG_CUDA_CHECK_LAUNCH("dem_contact_a");
  } else if (k > 0) {
    cuda::dem_contact_kernel<Real><<<cuda::blocks_for(k), cuda::kBlock>>>(rows, d.arrays(), c, t);
    CG_CUDA_CHECK_LAUNCH("dem_contact");
  }
  d.current = next;
}

}  // namespace cg::detail
