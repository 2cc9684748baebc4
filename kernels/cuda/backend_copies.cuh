#pragma once
// The CUDA backend's host <-> DEVICE copies outside a detection: the host-array path's bodies
// (upload_bodies, before the device takes their bounds), the contact history of
// EngineOptions::history (history_upload / history_download), the rows of a DeviceContactsView
// (download_contacts: a cell-order call's rows sorted into (a, b) order first) and the page-locking
// of caller memory (pin_host / unpin_host). Apart from the class (backend_class.cuh) as calls of the
// engine's API on it; included once, by cuda_backend.cu (one translation unit).
#include <algorithm>
#include <type_traits>

#include "cuda/backend_class.cuh"
#include "cuda/cell_order.cuh"
#include "cuda/transfer.cuh"

namespace cg::detail {

// Whether caller memory is page-locked already (Engine::pin_host, cudaHostRegister, cudaMallocHost):
// its first and last bytes are. Such a range is copied straight, without the ring's host copy.
inline bool host_locked(const std::byte* p, std::size_t bytes) {
  auto locked = [](const void* q) {
    cudaPointerAttributes a{};
    if (cudaPointerGetAttributes(&a, q) != cudaSuccess) {
      (void)cudaGetLastError();  // (memory the driver has never seen)
      return false;
    }
    return a.type == cudaMemoryTypeHost;
  };
  return bytes > 0 && locked(p) && locked(p + bytes - 1);
}

// The host-array path's first step (cuda/tuning.hpp: HostPath::device): the caller's arrays copied
// into the workspace's input rows (ws.pos, rad, report and the shape rows, which a call on DEVICE
// bodies leaves alone), so that the device takes their bounds and the host reads each input byte
// once: page-locked arrays straight, the others streamed through the pinned ring. Returns when the
// last copy is queued; the view is valid until the next call on this backend. upload_seconds: the
// copies' span on the stream, once they are done.
DeviceBodiesView upload_bodies(CudaBackend& b, const BodiesView& bodies) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  b.refresh_tuning();
  Workspace& ws = b.m_ws;
  const std::size_t n = bodies.size();
  const bool report = !bodies.report.empty(), shapes = !bodies.shape.empty();
  ws.reserve({{&ws.pos, n * sizeof(Vec3<double>)},
              {&ws.rad, n * sizeof(double)},
              {&ws.report, report ? n : 0},
              {&ws.shape_kind, shapes ? n * sizeof(Shape) : 0},
              {&ws.shape_semi, shapes ? n * sizeof(Vec3<double>) : 0},
              {&ws.shape_orient, shapes ? n * sizeof(Quat<double>) : 0}},
             "upload");
  DeviceBodiesView v;
  v.count = n;
  std::vector<HostDevice> streamed, straight;
  auto range = [&](Bytes& device, const void* host, std::size_t bytes) {
    const HostDevice h{static_cast<std::byte*>(const_cast<void*>(host)), device.data(), bytes};
    (host_locked(h.host, bytes) ? straight : streamed).push_back(h);
    return device.data();
  };
  v.position =
      reinterpret_cast<const double*>(range(ws.pos, bodies.position.data(), n * sizeof(Vec3<double>)));
  v.radius = reinterpret_cast<const double*>(range(ws.rad, bodies.radius.data(), n * sizeof(double)));
  if (report) v.report = reinterpret_cast<const std::uint8_t*>(range(ws.report, bodies.report.data(), n));
  if (shapes) {
    v.shape = reinterpret_cast<const Shape*>(range(ws.shape_kind, bodies.shape.data(), n * sizeof(Shape)));
    v.semi_axes = reinterpret_cast<const double*>(
        range(ws.shape_semi, bodies.semi_axes.data(), n * sizeof(Vec3<double>)));
    v.orientation = reinterpret_cast<const double*>(
        range(ws.shape_orient, bodies.orientation.data(), n * sizeof(Quat<double>)));
  }
  CG_CUDA_CHECK(cudaEventRecord(b.m_upload_events[0], b.m_stream));
  for (const HostDevice& h : straight)
    CG_CUDA_CHECK(cudaMemcpyAsync(h.device, h.host, h.bytes, cudaMemcpyHostToDevice, b.m_stream));
  if (!streamed.empty()) {
    cuda::PinnedRing& ring = cuda::pinned_ring(b.m_device);
    if (b.m_tuning.trace) {  // (the ring's first use in a process allocates it)
      const auto t0 = std::chrono::steady_clock::now();
      {
        const std::lock_guard<std::mutex> lock(ring.mutex());
        ring.ready(b.m_tuning.transfer_slot_bytes);
      }
      std::fprintf(stderr, "host path: the ring ready in %.3f ms\n",
                   std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
    streamed_upload(ring, b.m_tuning.transfer_slot_bytes, streamed, b.m_stream);
  }
  CG_CUDA_CHECK(cudaEventRecord(b.m_upload_events[1], b.m_stream));
  return v;
}

double upload_seconds(CudaBackend& b) {
  CG_CUDA_CHECK(cudaEventSynchronize(b.m_upload_events[1]));
  float ms = 0;
  CG_CUDA_CHECK(cudaEventElapsedTime(&ms, b.m_upload_events[0], b.m_upload_events[1]));
  return ms * 1e-3;
}

void history_upload(CudaBackend& b, const ContactHistory& h) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t m = h.size();
  const int at = ws.hist_current;
  ws.reserve({{&ws.hist_keys[at], m * sizeof(PairKey)}, {&ws.hist_age[at], m * sizeof(std::int64_t)}},
             "history");
  if (m > 0) {
    CG_CUDA_CHECK(cudaMemcpyAsync(ws.hist_keys[at].data(), h.keys.data(), m * sizeof(PairKey),
                                  cudaMemcpyHostToDevice, b.m_stream));
    CG_CUDA_CHECK(cudaMemcpyAsync(ws.hist_age[at].data(), h.age.data(), m * sizeof(std::int64_t),
                                  cudaMemcpyHostToDevice, b.m_stream));
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  ws.hist_count = m;
}

void history_download(CudaBackend& b, ContactHistory& h) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const Workspace& ws = b.m_ws;
  const std::size_t m = ws.hist_count;
  h.keys.resize(m);
  h.age.resize(m);
  if (m > 0) {
    CG_CUDA_CHECK(cudaMemcpyAsync(h.keys.data(), ws.hist_keys[ws.hist_current].data(), m * sizeof(PairKey),
                                  cudaMemcpyDeviceToHost, b.m_stream));
    CG_CUDA_CHECK(cudaMemcpyAsync(h.age.data(), ws.hist_age[ws.hist_current].data(), m * sizeof(std::int64_t),
                                  cudaMemcpyDeviceToHost, b.m_stream));
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

template <class Real>
void download_contacts(CudaBackend& b, const DeviceContactsView<Real>& v, Contacts<Real>& out) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  out = Contacts<Real>{};
  out.resize(v.count, v.fields());
  if (v.count == 0) return;
  cuda::ContactPtrs<Real> cp;  // the view's arrays (read only here)
  zip_contact_fields(cp, v, v.fields(), [](auto, auto*& ptr, auto* d_ptr) {
    ptr = const_cast<std::remove_reference_t<decltype(ptr)>>(d_ptr);
  });
  Workspace& ws = b.m_ws;
  // rows of a cell-order call (cell_order.cuh): each column gathered into (a, b) order, then copied
  const std::uint32_t* order =
      ws.rows_cell_order && v.count > 1
          ? canonical_rows(ws, b.m_stream, v.id_a, v.id_b, v.count, std::max(1, bits_for(ws.res_count)))
          : nullptr;
  for_each_field(out, cp, v.fields(), [&](auto& vec, const void* d_ptr) {
    using T = std::remove_cv_t<std::remove_reference_t<decltype(vec[0])>>;
    const std::size_t bytes = vec.size() * sizeof(T);
    if (order) {
      ws.reserve({{&ws.canon_field, bytes}}, "download");
      T* sorted = ws.canon_field.span_as<T>(vec.size()).data();
      cuda::gather_kernel<T><<<cuda::blocks_for(vec.size()), cuda::kBlock, 0, b.m_stream>>>(
          static_cast<const T*>(d_ptr), order, vec.size(), sorted);
      CG_CUDA_CHECK_LAUNCH("gather_rows");
      d_ptr = sorted;
    }
    CG_CUDA_CHECK(cudaMemcpyAsync(vec.data(), d_ptr, bytes, cudaMemcpyDeviceToHost, b.m_stream));
    if (order) CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));  // canon_field is the next column's
  });
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}
template void download_contacts(CudaBackend&, const DeviceContactsView<float>&, Contacts<float>&);
template void download_contacts(CudaBackend&, const DeviceContactsView<double>&, Contacts<double>&);

bool pin_host(CudaBackend& b, void* p, std::size_t bytes) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  if (cudaHostRegister(p, bytes, cudaHostRegisterDefault) == cudaSuccess) return true;
  (void)cudaGetLastError();  // refused: the copies stay pageable
  return false;
}

void unpin_host(CudaBackend& b, void* p) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  CG_CUDA_CHECK(cudaHostUnregister(p));
}

}  // namespace cg::detail
