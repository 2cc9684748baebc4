#pragma once
// One rank's rows of a granular run over several ranks on the device (kernels/dem_backend.hpp): the
// state of chosen rows gathered into DemRow records (the ghosts a rank sends) and scattered
// from them (the ghosts it receives), one thread per record; a log row's terms of chosen rows (their
// energies and the runs of their contacts as A: DemLogRow), one thread per row; the largest squared
// displacement of a row since the mark, one value per row reduced by Thrust (max: exact, any order).
#include <thrust/execution_policy.h>
#include <thrust/functional.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/transform_reduce.h>

#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

// Records j of rows[j] (rows[j] < b.count, checked on the host): a sphere's momentum and orientation
// as its state holds them (unread).
__global__ void dem_gather_rows_kernel(dem::BodyArrays b, const std::uint32_t* rows, std::size_t n,
                                       DemRow* out) {
  const std::size_t j = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (j >= n) return;
  const std::size_t i = rows[j];
  out[j] = DemRow{b.position[i],    b.velocity[i], b.omega[i], b.momentum[i],
                  b.orientation[i], b.force[i],    b.torque[i]};
}

__global__ void dem_scatter_rows_kernel(dem::BodyArrays b, const std::uint32_t* rows, std::size_t n,
                                        const DemRow* in) {
  const std::size_t j = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (j >= n) return;
  const std::size_t i = rows[j];
  const DemRow r = in[j];
  b.position[i] = r.position;
  b.velocity[i] = r.velocity;
  b.omega[i] = r.omega;
  b.momentum[i] = r.momentum;
  b.orientation[i] = r.orientation;
  b.force[i] = r.force;
  b.torque[i] = r.torque;
}

// A sphere's halo record j of rows[j] (DemSphereRow: no momentum, no orientation) out and in.
__global__ void dem_gather_spheres_kernel(dem::BodyArrays b, const std::uint32_t* rows, std::size_t n,
                                          DemSphereRow* out) {
  const std::size_t j = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (j >= n) return;
  const std::size_t i = rows[j];
  out[j] = DemSphereRow{b.position[i], b.velocity[i], b.omega[i], b.force[i], b.torque[i]};
}

__global__ void dem_scatter_spheres_kernel(dem::BodyArrays b, const std::uint32_t* rows, std::size_t n,
                                           const DemSphereRow* in) {
  const std::size_t j = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (j >= n) return;
  const std::size_t i = rows[j];
  const DemSphereRow r = in[j];
  b.position[i] = r.position;
  b.velocity[i] = r.velocity;
  b.omega[i] = r.omega;
  b.force[i] = r.force;
  b.torque[i] = r.torque;
}

// The log row's terms of rows[j] (rows[j] < b.count, checked on the host); a_begin: the body index's
// (count + 1 entries), wall_energy: each row's (null: no walls).
__global__ void dem_log_rows_kernel(dem::BodyArrays b, Vec3<double> gravity, const double* wall_energy,
                                    const std::uint32_t* a_begin, const std::uint32_t* rows, std::size_t n,
                                    DemLogRow* out) {
  const std::size_t j = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (j >= n) return;
  const std::size_t i = rows[j];
  const dem::BodyEnergy e = dem::body_energy(i, b, gravity);
  out[j] = DemLogRow{e.kinetic, e.gravity, wall_energy ? wall_energy[i] : 0.0, a_begin[i], a_begin[i + 1]};
}

// |x_i − mark_i|² of row i.
struct DemMovedSq {
  const Vec3<double>* position;
  const Vec3<double>* mark;
  __device__ double operator()(std::size_t i) const {
    const Vec3<double> d = position[i] - mark[i];
    return dot(d, d);
  }
};

}  // namespace cg::cuda

namespace cg::detail {

inline void dem_gather_rows(CudaDem& d, const std::vector<std::uint32_t>& rows, std::vector<DemRow>& out) {
  const std::size_t n = rows.size();
  out.resize(n);
  if (n == 0) return;
  d.row_index.reserve(n, true);
  d.row_records.reserve(n, true);
  CG_CUDA_CHECK(
      cudaMemcpy(d.row_index.data(), rows.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice));
  cuda::dem_gather_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(d.arrays(), d.row_index.data(), n,
                                                                      d.row_records.data());
  CG_CUDA_CHECK_LAUNCH("dem_gather_rows");
  CG_CUDA_CHECK(cudaMemcpy(out.data(), d.row_records.data(), n * sizeof(DemRow), cudaMemcpyDeviceToHost));
}

inline void dem_scatter_rows(CudaDem& d, const std::vector<std::uint32_t>& rows,
                             const std::vector<DemRow>& in) {
  const std::size_t n = rows.size();
  if (n == 0) return;
  d.row_index.reserve(n, true);
  d.row_records.reserve(n, true);
  CG_CUDA_CHECK(
      cudaMemcpy(d.row_index.data(), rows.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice));
  CG_CUDA_CHECK(cudaMemcpy(d.row_records.data(), in.data(), n * sizeof(DemRow), cudaMemcpyHostToDevice));
  cuda::dem_scatter_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(d.arrays(), d.row_index.data(), n,
                                                                       d.row_records.data());
  CG_CUDA_CHECK_LAUNCH("dem_scatter_rows");
}

// The halo's rows on the device (the same rows every step until the rows are set again).
inline void dem_set_halo(CudaDem& d, const std::vector<std::uint32_t>& send,
                         const std::vector<std::uint32_t>& receive, bool spheres) {
  d.halo_spheres = spheres;
  d.halo_sends = send.size();
  d.halo_receives = receive.size();
  const std::size_t most = std::max(send.size(), receive.size());
  d.halo_send.reserve(std::max<std::size_t>(send.size(), 1), false);
  d.halo_receive.reserve(std::max<std::size_t>(receive.size(), 1), false);
  d.halo_records.reserve(std::max<std::size_t>(most, 1), false);
  d.halo_out.reserve(std::max<std::size_t>(send.size(), 1) * sizeof(DemRow));
  d.halo_in.reserve(std::max<std::size_t>(receive.size(), 1) * sizeof(DemRow));
  if (!send.empty())
    CG_CUDA_CHECK(cudaMemcpy(d.halo_send.data(), send.data(), send.size() * sizeof(std::uint32_t),
                             cudaMemcpyHostToDevice));
  if (!receive.empty())
    CG_CUDA_CHECK(cudaMemcpy(d.halo_receive.data(), receive.data(), receive.size() * sizeof(std::uint32_t),
                             cudaMemcpyHostToDevice));
  // the overlapped step's edge (dem_overlap.cuh): the flags of the rows sent or received, those rows
  std::vector<std::uint8_t> flags(d.count, 0);
  for (const auto* rows : {&send, &receive})
    for (const std::uint32_t r : *rows) flags[r] = 1;
  std::vector<std::uint32_t> edge_rows;
  for (std::size_t i = 0; i < flags.size(); ++i)
    if (flags[i]) edge_rows.push_back(static_cast<std::uint32_t>(i));
  d.edge_count = edge_rows.size();
  d.edge.reserve(std::max<std::size_t>(d.count, 1), false);
  d.edge_rows.reserve(std::max<std::size_t>(edge_rows.size(), 1), false);
  if (!flags.empty())
    CG_CUDA_CHECK(cudaMemcpy(d.edge.data(), flags.data(), flags.size(), cudaMemcpyHostToDevice));
  if (!edge_rows.empty())
    CG_CUDA_CHECK(cudaMemcpy(d.edge_rows.data(), edge_rows.data(), edge_rows.size() * sizeof(std::uint32_t),
                             cudaMemcpyHostToDevice));
  d.halo_stream.create();
}

inline std::size_t dem_halo_record_bytes(const CudaDem& d) {
  return d.halo_spheres ? sizeof(DemSphereRow) : sizeof(DemRow);
}

// The sent rows' records gathered into the device's staging buffer on `stream`.
inline void dem_gather_halo_records(CudaDem& d, cudaStream_t stream) {
  const std::size_t n = d.halo_sends;
  if (d.halo_spheres)
    cuda::dem_gather_spheres_kernel<<<cuda::blocks_for(n), cuda::kBlock, 0, stream>>>(
        d.arrays(), d.halo_send.data(), n, reinterpret_cast<DemSphereRow*>(d.halo_records.data()));
  else
    cuda::dem_gather_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock, 0, stream>>>(
        d.arrays(), d.halo_send.data(), n, d.halo_records.data());
  CG_CUDA_CHECK_LAUNCH("dem_gather_halo");
}

// The staging buffer's received records scattered into their rows on `stream`.
inline void dem_scatter_halo_records(CudaDem& d, cudaStream_t stream) {
  const std::size_t n = d.halo_receives;
  if (d.halo_spheres)
    cuda::dem_scatter_spheres_kernel<<<cuda::blocks_for(n), cuda::kBlock, 0, stream>>>(
        d.arrays(), d.halo_receive.data(), n, reinterpret_cast<const DemSphereRow*>(d.halo_records.data()));
  else
    cuda::dem_scatter_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock, 0, stream>>>(
        d.arrays(), d.halo_receive.data(), n, d.halo_records.data());
  CG_CUDA_CHECK_LAUNCH("dem_scatter_halo");
}

// The sent rows' records, gathered on the device and downloaded into the page-locked buffer.
inline const std::byte* dem_gather_halo(CudaDem& d) {
  std::byte* out = d.halo_out.data();
  const std::size_t n = d.halo_sends;
  if (n == 0) return out;
  dem_gather_halo_records(d, cudaStreamLegacy);
  CG_CUDA_CHECK(cudaMemcpy(out, d.halo_records.data(), n * dem_halo_record_bytes(d), cudaMemcpyDeviceToHost));
  return out;
}

// The received rows' records (in the page-locked inbox) uploaded and scattered into their rows.
inline void dem_scatter_halo(CudaDem& d) {
  const std::size_t n = d.halo_receives;
  if (n == 0) return;
  CG_CUDA_CHECK(cudaMemcpy(d.halo_records.data(), d.halo_in.data(), n * dem_halo_record_bytes(d),
                           cudaMemcpyHostToDevice));
  dem_scatter_halo_records(d, cudaStreamLegacy);
}

// The log row's terms of `rows` (after a step's body stage: its index) and the last step's `contacts`
// contact energies, downloaded.
inline void dem_log_rows(CudaDem& d, const std::vector<std::uint32_t>& rows, Vec3<double> gravity,
                         std::size_t contacts, std::vector<DemLogRow>& out, std::vector<double>& energy) {
  const std::size_t n = rows.size();
  out.resize(n);
  energy.resize(contacts);
  if (n > 0) {
    d.row_index.reserve(n, true);
    d.log_rows.reserve(n, true);
    CG_CUDA_CHECK(
        cudaMemcpy(d.row_index.data(), rows.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice));
    cuda::dem_log_rows_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(
        d.arrays(), gravity, d.wall_count > 0 ? d.wall_energy.data() : nullptr, d.a_begin.data(),
        d.row_index.data(), n, d.log_rows.data());
    CG_CUDA_CHECK_LAUNCH("dem_log_rows");
    CG_CUDA_CHECK(cudaMemcpy(out.data(), d.log_rows.data(), n * sizeof(DemLogRow), cudaMemcpyDeviceToHost));
  }
  if (contacts > 0)
    CG_CUDA_CHECK(cudaMemcpy(energy.data(), d.contact_energy.data(), contacts * sizeof(double),
                             cudaMemcpyDeviceToHost));
}

inline void dem_mark_rows(CudaDem& d) {
  d.mark.reserve(std::max<std::size_t>(d.count, 1), false);
  if (d.count > 0)
    CG_CUDA_CHECK(cudaMemcpy(d.mark.data(), d.position.data(), d.count * sizeof(Vec3<double>),
                             cudaMemcpyDeviceToDevice));
}

inline double dem_rows_moved(CudaDem& d) {
  if (d.count == 0) return 0;
  auto policy = thrust::cuda::par(d.thrust).on(cudaStreamLegacy);
  const double sq = thrust::transform_reduce(
      policy, thrust::counting_iterator<std::size_t>(0), thrust::counting_iterator<std::size_t>(d.count),
      cuda::DemMovedSq{d.position.data(), d.mark.data()}, 0.0, thrust::maximum<double>());
  return std::sqrt(sq);
}

}  // namespace cg::detail
