#pragma once
// The body stage of the granular dynamics on the device: where each body's rows lie (BodyRowIndex:
// its rows as A are contiguous, the rows being sorted by A; its rows as B, in ascending row order),
// then body_terms of every body (core/dem_step.hpp: its sums in a fixed order, walls, gravity), one
// thread per body, and in the same pass the body's kick (and the next step's kick_drift: DemThen). No
// floating-point atomics: the same sums as the CPU's, bit for bit.
//
// The index, two ways to the same arrays (tuning: CONTACTGRID_DEM_SUMS):
//   counts (default)  one pass over the rows counts each body's rows as A and as B (integer atomics;
//                     each row keeps its rank among its B's rows), an exclusive scan of each count
//                     gives the begins, one pass puts each row at its B's begin plus its rank, and
//                     each body's thread sorts its few rows (sort_rows), restoring the ascending row
//                     order that the atomics' ranks do not fix (CONTACTGRID_DEM_SEGMENTS=cub: CUB's
//                     segmented sort, which reads its partition back to the host each call).
//                     O(rows + bodies) streaming passes, every read of a row coalesced but the scatter.
//   sort              a stable radix sort of (B, row) over the bits of the body count (CUB), then
//                     Thrust's vectorised lower_bound of every body id in the rows' A and in the
//                     sorted Bs (a binary search per body over the rows).
#include <thrust/binary_search.h>
#include <thrust/execution_policy.h>
#include <thrust/iterator/counting_iterator.h>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_segmented_sort.cuh>
#include <type_traits>

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

// Each body's rows as A and as B (a_count, b_count: zero on entry), and each row's rank among its B's
// rows (in the order the atomics come: the segmented sort fixes the order).
__global__ void dem_count_kernel(const std::int64_t* id_a, const std::int64_t* id_b, std::size_t k,
                                 std::uint32_t* a_count, std::uint32_t* b_count, std::uint32_t* b_rank) {
  const std::size_t r = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (r >= k) return;
  atomicAdd(a_count + id_a[r], 1u);
  b_rank[r] = atomicAdd(b_count + id_b[r], 1u);
}

// Row r at its B's begin plus its rank.
__global__ void dem_place_kernel(const std::int64_t* id_b, std::size_t k, const std::uint32_t* b_begin,
                                 const std::uint32_t* b_rank, std::uint32_t* by_b) {
  const std::size_t r = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (r >= k) return;
  by_b[b_begin[id_b[r]] + b_rank[r]] = static_cast<std::uint32_t>(r);
}

// Each body's rows as B into ascending row order, in place (core/dem_step.hpp: sort_rows).
__global__ void dem_sort_b_rows_kernel(const std::uint32_t* b_begin, std::size_t n, std::uint32_t* by_b) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= n) return;
  const std::uint32_t begin = b_begin[i], end = b_begin[i + 1];
  if (end > begin + 1) dem::sort_rows(by_b + begin, end - begin);
}

// body_terms of body i (a_force null: its sums over its rows as A too; else those sums are
// a_force[i], a_torque[i], stored by the contact stage where it has such rows: dem_forces.cuh;
// points: no torque stored, each from its row's point: contact_sums_from_points), then (kThen:
// DemThen) its kick and the next step's kick_drift: a body's step reads and writes only its own state
// (the contact stage has read every body's), so the integration needs no pass of its own.
// kMinBlocks: as the contact stage's (dem_forces.cuh: __launch_bounds__, CONTACTGRID_DEM_BLOCKS).
template <int kThen, class Real, int kMinBlocks>
__global__ void __launch_bounds__(kBlock, kMinBlocks)
    dem_body_kernel(dem::BodyArrays b, dem::StepConstants c, dem::ContactTerms t, dem::BodyRowIndex index,
                    dem::WallTerms w, const Vec3<double>* a_force, const Vec3<double>* a_torque,
                    dem::ContactRows<Real> rows, bool points, const std::uint8_t* edge, dem::Pass pass) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  if (!dem::body_in_pass(i, edge, pass)) return;  // the overlapped step's other pass (dem_overlap.cuh)
  Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
  if (points) {
    dem::contact_sums_from_points(i, b, rows, t, index, f, tau);
    dem::body_terms_after_contacts(i, b, c, w, f, tau);
  } else {
    if (!a_force) {
      dem::a_sums(i, t, index, f, tau);
    } else if (index.a_begin[i] < index.a_begin[i + 1]) {
      f = a_force[i];
      tau = a_torque[i];
    }
    dem::body_terms_after_a(i, b, c, t, index, w, f, tau);
  }
  if (kThen == int(detail::DemThen::nothing)) return;
  dem::BodyState s = b.state(i);
  const dem::BodyProps& p = b.props[i];
  const bool ell = b.ellipsoid(i);
  dem::kick(s, p, ell, c.dt);
  if (kThen == int(detail::DemThen::kick_and_drift)) dem::kick_drift(s, p, ell, c.dt);
  b.store(i, s);
}

}  // namespace cg::cuda

namespace cg::detail {

// The index by the radix sort (file comment); returns by_b.
template <class Real>
const std::uint32_t* dem_index_by_sort(CudaDem& d, const dem::ContactRows<Real>& rows) {
  const std::size_t n = d.count, k = rows.count;
  auto policy = thrust::cuda::par_nosync(d.thrust).on(cudaStreamLegacy);
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
  const std::uint32_t* sorted_b = keys.Current();
  thrust::lower_bound(policy, rows.id_a, rows.id_a + k, thrust::counting_iterator<std::int64_t>(0),
                      thrust::counting_iterator<std::int64_t>(std::int64_t(n) + 1), d.a_begin.data());
  thrust::lower_bound(policy, sorted_b, sorted_b + k, thrust::counting_iterator<std::uint32_t>(0),
                      thrust::counting_iterator<std::uint32_t>(std::uint32_t(n) + 1), d.b_begin.data());
  return vals.Current();
}

// The index by counts, scans and a segmented sort (file comment); returns by_b.
template <class Real>
const std::uint32_t* dem_index_by_counts(CudaDem& d, const dem::ContactRows<Real>& rows) {
  const std::size_t n = d.count, k = rows.count;
  d.b_rank.reserve(k, true);
  for (int h = 0; h < 2; ++h) d.by_b[h].reserve(k, true);
  CG_CUDA_CHECK(cudaMemsetAsync(d.a_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
  CG_CUDA_CHECK(cudaMemsetAsync(d.b_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
  cuda::dem_count_kernel<<<cuda::blocks_for(k), cuda::kBlock>>>(rows.id_a, rows.id_b, k, d.a_begin.data(),
                                                                d.b_begin.data(), d.b_rank.data());
  CG_CUDA_CHECK_LAUNCH("dem_count");
  // the counts' exclusive scans in place (n + 1 entries: the last begin is the row count)
  std::size_t scan_temp = 0, sort_temp = 0;
  CG_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, scan_temp, d.a_begin.data(), d.a_begin.data(), n + 1,
                                              cudaStreamLegacy));
  const std::uint32_t* begin = d.b_begin.data();
  if (d.segments_cub)
    CG_CUDA_CHECK(cub::DeviceSegmentedSort::SortKeys(nullptr, sort_temp, d.by_b[0].data(), d.by_b[1].data(),
                                                     std::int64_t(k), std::int64_t(n), begin, begin + 1,
                                                     cudaStreamLegacy));
  std::size_t temp = std::max(scan_temp, sort_temp);
  d.sort_temp.reserve(std::max<std::size_t>(temp, 1), true);
  temp = d.sort_temp.capacity();
  CG_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(d.sort_temp.data(), temp, d.a_begin.data(), d.a_begin.data(),
                                              n + 1, cudaStreamLegacy));
  temp = d.sort_temp.capacity();
  CG_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(d.sort_temp.data(), temp, d.b_begin.data(), d.b_begin.data(),
                                              n + 1, cudaStreamLegacy));
  cuda::dem_place_kernel<<<cuda::blocks_for(k), cuda::kBlock>>>(rows.id_b, k, d.b_begin.data(),
                                                                d.b_rank.data(), d.by_b[0].data());
  CG_CUDA_CHECK_LAUNCH("dem_place");
  if (!d.segments_cub) {  // each body's few rows sorted by its own thread: no host synchronisation
    cuda::dem_sort_b_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(d.b_begin.data(), n,
                                                                        d.by_b[0].data());
    CG_CUDA_CHECK_LAUNCH("dem_sort_b_rows");
    return d.by_b[0].data();
  }
  temp = d.sort_temp.capacity();
  CG_CUDA_CHECK(cub::DeviceSegmentedSort::SortKeys(d.sort_temp.data(), temp, d.by_b[0].data(),
                                                   d.by_b[1].data(), std::int64_t(k), std::int64_t(n), begin,
                                                   begin + 1, cudaStreamLegacy));
  return d.by_b[1].data();
}

// Where each body's rows lie (the begins; by_b returned), before any body's terms.
template <class Real>
const std::uint32_t* dem_body_index(CudaDem& d, const dem::ContactRows<Real>& rows) {
  const std::size_t n = d.count, k = rows.count;
  d.a_begin.reserve(n + 1, true);
  d.b_begin.reserve(n + 1, true);
  if (k > 0) return d.sums_by_sort ? dem_index_by_sort(d, rows) : dem_index_by_counts(d, rows);
  CG_CUDA_CHECK(cudaMemsetAsync(d.a_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
  CG_CUDA_CHECK(cudaMemsetAsync(d.b_begin.data(), 0, (n + 1) * sizeof(std::uint32_t), cudaStreamLegacy));
  return nullptr;
}

// body_terms (then `then`) of the bodies of `pass` (edge: the rows' edge flags) on the legacy stream.
template <class Real>
void dem_body_launch(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                     DemThen then, const std::uint32_t* by_b, dem::Pass pass, const std::uint8_t* edge) {
  const std::size_t n = d.count, k = rows.count;
  if (n == 0) return;
  const bool points = d.torques_from_points && k > 0;
  const dem::ContactTerms t{d.contact_force.data(),
                            d.a_sums || d.torques_from_points ? nullptr : d.torque_a.data(),
                            d.torques_from_points ? nullptr : d.torque_b.data(),
                            d.contact_energy.data(),
                            nullptr,
                            nullptr,
                            nullptr,
                            nullptr};
  const dem::BodyRowIndex index{d.a_begin.data(), d.b_begin.data(), by_b};
  const dem::WallTerms w{d.wall_xi.data(), d.wall_energy.data()};
  dem::StepConstants on_device = c;
  on_device.walls = d.walls.data();
  const dem::BodyArrays b = d.arrays();
  const Vec3<double>* af = d.a_sums ? d.a_force.data() : nullptr;
  const Vec3<double>* at = d.a_sums ? d.a_torque.data() : nullptr;
  const unsigned blocks = cuda::blocks_for(n);
  auto launch = [&](auto then_c) {
    constexpr int kThen = decltype(then_c)::value;
    if (d.min_blocks >= 3)
      cuda::dem_body_kernel<kThen, Real, 3>
          <<<blocks, cuda::kBlock>>>(b, on_device, t, index, w, af, at, rows, points, edge, pass);
    else if (d.min_blocks == 2)
      cuda::dem_body_kernel<kThen, Real, 2>
          <<<blocks, cuda::kBlock>>>(b, on_device, t, index, w, af, at, rows, points, edge, pass);
    else
      cuda::dem_body_kernel<kThen, Real, 1>
          <<<blocks, cuda::kBlock>>>(b, on_device, t, index, w, af, at, rows, points, edge, pass);
  };
  if (then == DemThen::nothing)
    launch(std::integral_constant<int, int(DemThen::nothing)>{});
  else if (then == DemThen::kick)
    launch(std::integral_constant<int, int(DemThen::kick)>{});
  else
    launch(std::integral_constant<int, int(DemThen::kick_and_drift)>{});
  CG_CUDA_CHECK_LAUNCH("dem_body");
}

template <class Real>
void dem_body_stage(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                    DemThen then) {
  if (d.count == 0) return;
  const std::uint32_t* by_b = dem_body_index(d, rows);
  d.events.mark(DemStage::body_index);
  dem_body_launch(d, rows, c, then, by_b, dem::Pass::all, nullptr);
  d.events.mark(DemStage::body_terms);
}

}  // namespace cg::detail
