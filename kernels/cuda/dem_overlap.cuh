#pragma once
// The overlapped step on the device (kernels/dem.hpp: Simulation::finish_step_sending): the halo's
// records cross the link while the interior's forces run.
//
//   legacy stream   body index → edge contacts → edge bodies (+ kick, kick_drift) ─[edge]─→
//                   interior contacts → interior bodies (+ kick, kick_drift) → ... waits [received]
//   halo stream     waits [edge] → gather the sent rows → download ─[sent]
//   host            waits [sent] → the records to the other ranks (caller) → upload → scatter
//                   into the ghosts' rows ─[received]
//
// The edge is every halo row (sent or received) and every contact touching one: the interior's
// passes read and write no row the halo's gather or scatter touches, so the halo's stream and the
// interior's passes run side by side without a race, and each contact and body is computed once by
// the same function as in one pass (dem_forces.cuh, dem_sums.cuh): the same bits.
#include "cuda/dem_forces.cuh"
#include "cuda/dem_rows.cuh"
#include "cuda/dem_sums.cuh"

namespace cg::detail {

inline bool dem_can_overlap(const CudaDem& d) { return !d.a_sums && d.halo_stream.stream != nullptr; }

template <class Real>
const std::byte* dem_forces_sending(CudaDem& d, const dem::ContactRows<Real>& rows,
                                    const dem::StepConstants& c) {
  DemHaloStream& h = d.halo_stream;
  const std::size_t k = rows.count, m = d.edge_count;
  const std::uint32_t* by_b = d.count > 0 ? dem_body_index(d, rows) : nullptr;
  d.events.mark(DemStage::body_index);
  d.contact_energy.reserve(std::max<std::size_t>(k, 1), true);  // a relayout's state reads it
  const DemContactOutputs<Real> o = dem_contact_outputs(d, rows, c, false);
  if (m > 0 && k > 0) {
    const dem::BodyRowIndex index{d.a_begin.data(), d.b_begin.data(), by_b};
    const unsigned blocks = cuda::blocks_for(m);
    const dem::BodyArrays b = d.arrays();
    if (d.min_blocks >= 3)
      cuda::dem_edge_contact_kernel<Real, 3><<<blocks, cuda::kBlock>>>(
          rows, b, c, o.t, o.normal, o.old_normal, index, d.edge_rows.data(), m, d.edge.data());
    else if (d.min_blocks == 2)
      cuda::dem_edge_contact_kernel<Real, 2><<<blocks, cuda::kBlock>>>(
          rows, b, c, o.t, o.normal, o.old_normal, index, d.edge_rows.data(), m, d.edge.data());
    else
      cuda::dem_edge_contact_kernel<Real, 1><<<blocks, cuda::kBlock>>>(
          rows, b, c, o.t, o.normal, o.old_normal, index, d.edge_rows.data(), m, d.edge.data());
    CG_CUDA_CHECK_LAUNCH("dem_edge_contact");
  }
  dem_body_launch(d, rows, c, DemThen::kick_and_drift, by_b, dem::Pass::edge, d.edge.data());
  CG_CUDA_CHECK(cudaEventRecord(h.edge, cudaStreamLegacy));
  // the halo's stream after the edge (the gather reads the sent rows' new state; the scatter,
  // even of a rank that sends nothing, writes the received rows after the edge's passes did)
  CG_CUDA_CHECK(cudaStreamWaitEvent(h.stream, h.edge, 0));
  std::byte* out = d.halo_out.data();
  const std::size_t sends = d.halo_sends;
  if (sends > 0) {
    dem_gather_halo_records(d, h.stream);
    CG_CUDA_CHECK(cudaMemcpyAsync(out, d.halo_records.data(), sends * dem_halo_record_bytes(d),
                                  cudaMemcpyDeviceToHost, h.stream));
    CG_CUDA_CHECK(cudaEventRecord(h.sent, h.stream));
  }
  // the interior's passes behind the edge's
  d.interior_timed = d.events.on();
  if (d.interior_timed) CG_CUDA_CHECK(cudaEventRecord(h.interior_begin, cudaStreamLegacy));
  dem_contact_launch(d, rows, c, o, dem::Pass::interior, d.edge.data());
  dem_contact_done(d, o);
  d.events.mark(DemStage::contact_terms);
  dem_body_launch(d, rows, c, DemThen::kick_and_drift, by_b, dem::Pass::interior, d.edge.data());
  d.events.mark(DemStage::body_terms);
  if (d.interior_timed) CG_CUDA_CHECK(cudaEventRecord(h.interior_end, cudaStreamLegacy));
  if (sends > 0) CG_CUDA_CHECK(cudaEventSynchronize(h.sent));
  return out;
}

// The inbox uploaded and scattered into the ghosts' rows on the halo's stream; the legacy stream's
// later work (the next step's extent and detection) waits for it.
inline void dem_receive_halo(CudaDem& d) {
  DemHaloStream& h = d.halo_stream;
  const std::size_t n = d.halo_receives;
  if (n == 0) return;
  CG_CUDA_CHECK(cudaMemcpyAsync(d.halo_records.data(), d.halo_in.data(), n * dem_halo_record_bytes(d),
                                cudaMemcpyHostToDevice, h.stream));
  dem_scatter_halo_records(d, h.stream);
  CG_CUDA_CHECK(cudaEventRecord(h.received, h.stream));
  CG_CUDA_CHECK(cudaStreamWaitEvent(cudaStreamLegacy, h.received, 0));
}

// The interior's passes' device time after the records were downloaded (what the exchange between
// the ranks can hide behind; stage times).
inline double dem_interior_seconds(CudaDem& d) {
  if (!d.interior_timed) return 0;
  DemHaloStream& h = d.halo_stream;
  CG_CUDA_CHECK(cudaEventSynchronize(h.interior_end));
  float all = 0, before = 0;
  CG_CUDA_CHECK(cudaEventElapsedTime(&all, h.interior_begin, h.interior_end));
  if (d.halo_sends > 0) CG_CUDA_CHECK(cudaEventElapsedTime(&before, h.interior_begin, h.sent));
  return std::max(0.0f, all - std::max(0.0f, before)) * 1e-3;
}

}  // namespace cg::detail
