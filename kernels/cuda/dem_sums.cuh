#pragma once
// The body stage of the granular dynamics on the device: the rows' order by B (a stable radix sort of
// (B, row), over the bits of the body count: CUB, whose bit range Thrust's sort does not take), where
// each body's rows begin (Thrust's vectorised lower_bound of every body id in the rows' A and in the
// sorted Bs), then body_terms of every body (core/dem_step.hpp: its sums in a fixed order, walls,
// gravity), one thread per body. No atomics: the same sums as the CPU's, bit for bit.
#include <thrust/binary_search.h>
#include <thrust/execution_policy.h>
#include <thrust/iterator/counting_iterator.h>

#include <cub/device/device_radix_sort.cuh>

#include "backend.hpp"
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

// (B, row) of every contact row: the sort's keys and values.
__global__ void dem_b_keys_kernel(const std::int64_t* id_b, std::size_t k, std::uint32_t* keys,
                                  std::uint32_t* rows) {
  const std::size_t r = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (r >= k) return;
  keys[r] = static_cast<std::uint32_t>(id_b[r]);
  rows[r] = static_cast<std::uint32_t>(r);
}

__global__ void dem_body_kernel(dem::BodyArrays b, dem::StepConstants c, dem::ContactTerms t,
                                dem::BodyRowIndex index, dem::WallTerms w) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  dem::body_terms(i, b, c, t, index, w);
}

}  // namespace cg::cuda

namespace cg::detail {

template <class Real>
void dem_body_stage(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c) {
  const std::size_t n = d.count, k = rows.count;
  if (n == 0) return;
  auto policy = thrust::cuda::par_nosync(d.thrust).on(cudaStreamLegacy);
  d.a_begin.reserve(n + 1, true);
  d.b_begin.reserve(n + 1, true);
  const std::uint32_t* by_b = nullptr;
  if (k > 0) {
    for (int h = 0; h < 2; ++h) {
      d.b_keys[h].reserve(k, true);
      d.by_b[h].reserve(k, true);
    }
    cuda::dem_b_keys_kernel<<<cuda::blocks_for(k), cuda::kBlock>>>(rows.id_b, k, d.b_keys[0].data(),
                                                                   d.by_b[0].data());
    CG_CUDA_CHECK_LAUNCH("dem_b_keys");
    cub::DoubleBuffer<std::uint32_t> keys(d.b_keys[0].data(), d.b_keys[1].data());
    cub::DoubleBuffer<std::uint32_t> vals(d.by_b[0].data(), d.by_b[1].data());
    const int bits = std::max(1, bits_for(n));
    std::size_t temp = 0;
    CG_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(nullptr, temp, keys, vals, int(k), 0, bits, cudaStreamLegacy));
    d.sort_temp.reserve(std::max<std::size_t>(temp, 1), true);
    CG_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(d.sort_temp.data(), temp, keys, vals, int(k), 0, bits,
                                                  cudaStreamLegacy));
    by_b = vals.Current();
    const std::uint32_t* sorted_b = keys.Current();
    thrust::lower_bound(policy, rows.id_a, rows.id_a + k, thrust::counting_iterator<std::int64_t>(0),
                        thrust::counting_iterator<std::int64_t>(std::int64_t(n) + 1), d.a_begin.data());
    thrust::lower_bound(policy, sorted_b, sorted_b + k, thrust::counting_iterator<std::uint32_t>(0),
                        thrust::counting_iterator<std::uint32_t>(std::uint32_t(n) + 1), d.b_begin.data());
  } else {
    CG_CUDA_CHECK(cudaMemsetAsync(d.a_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
    CG_CUDA_CHECK(cudaMemsetAsync(d.b_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
  }
  const dem::ContactTerms t{d.contact_force.data(),
                            d.torque_a.data(),
                            d.torque_b.data(),
                            d.contact_energy.data(),
                            nullptr,
                            nullptr,
                            nullptr,
                            nullptr};
  const dem::BodyRowIndex index{d.a_begin.data(), d.b_begin.data(), by_b};
  const dem::WallTerms w{d.wall_xi.data(), d.wall_energy.data()};
  dem::StepConstants on_device = c;
  on_device.walls = d.walls.data();
  cuda::dem_body_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(d.arrays(), on_device, t, index, w);
  CG_CUDA_CHECK_LAUNCH("dem_body");
}

}  // namespace cg::detail
