#pragma once
// CUDA transfers: the upload of host bodies, the download of the contact rows (or their description
// in DEVICE memory), and the copies of the device-array API (download_contacts, resident bodies).
#include <chrono>
#include <string_view>
#include <vector>

#include "cuda/narrow.cuh"
#include "cuda/run_state.cuh"

namespace cg::detail {

// f(host vector, device array) for each contact field the run produces (the optional ones only
// with Fields::full), in table order: the order of the device layout (layout_contacts).
template <class Real, class F>
void for_each_field(Contacts<Real>& out, const cuda::ContactPtrs<Real>& cp, bool full, F&& f) {
  zip_contact_fields(out, cp, full,
                     [&](auto, auto& vec, auto* d_ptr) { f(vec, static_cast<const void*>(d_ptr)); });
}

// upload: the DEVICE bodies of the call: the caller's arrays (device-array API), or the host arrays
// copied into ws.pos / rad / report (stage "upload"). Large input arrays are page-locked in place for
// the copy (they are already resident, so that only pins them) and unpinned once it is done: a
// pageable copy is staged by the driver on one thread.
// A range the driver refuses (e.g. a page shared with an array already registered) is copied
// pageable. Tuning::upload_registered forces one.
template <class Real, class Key, class Narrow>
void upload_stage(RunState<Real, Key, Narrow>& r) {
  if (r.device_in) {
    r.d_pos = r.job.device_bodies->position;
    r.d_rad = r.job.device_bodies->radius;
    r.d_report = r.job.device_bodies->report;
    return;
  }
  Workspace& ws = r.ws;
  const std::uint64_t n64 = r.n64;
  const std::size_t lock_from = r.tuning.upload_registered == Forced::on    ? 1
                                : r.tuning.upload_registered == Forced::off ? SIZE_MAX
                                                                            : std::size_t(64) << 20;
  std::vector<void*> locked;
  auto upload = [&](void* dst, const void* src, std::size_t bytes) {
    if (bytes >= lock_from) {
      void* p = const_cast<void*>(src);  // page-locking does not write to the range
      if (cudaHostRegister(p, bytes, cudaHostRegisterDefault) == cudaSuccess)
        locked.push_back(p);
      else
        (void)cudaGetLastError();  // refused: the copy below is pageable
    }
    if (bytes > 0) CG_CUDA_CHECK(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyHostToDevice, r.st));
  };
  upload(ws.pos.data(), r.job.bodies.position.data(), n64 * sizeof(Vec3<double>));
  upload(ws.rad.data(), r.job.bodies.radius.data(), n64 * sizeof(double));
  r.d_pos = reinterpret_cast<const double*>(ws.pos.data());
  r.d_rad = reinterpret_cast<const double*>(ws.rad.data());
  r.d_report = nullptr;
  if (!r.job.bodies.report.empty()) {
    upload(ws.report.data(), r.job.bodies.report.data(), n64);
    r.d_report = reinterpret_cast<const std::uint8_t*>(ws.report.data());
  }
  r.events.mark(EngineStage::upload, r.st);
  if (!locked.empty()) {
    CG_CUDA_CHECK(cudaStreamSynchronize(r.st));  // the copies read the locked ranges until here
    for (void* p : locked) CG_CUDA_CHECK(cudaHostUnregister(p));
  }
}

// Host seconds of the download that the events do not see (StageEvents::collect).
struct DownloadHostTimes {
  double overlap_s = 0;  // host work that overlapped the transfer
  double extra_s = 0;    // host work after it
};

// download: the contact rows described in DEVICE memory (job.device_out), or copied into `out`.
// Large results go straight into the result vectors, page-locked in place (cudaHostRegister: that is
// their first touch); small ones, and any range the driver will not register, through the pinned
// staging buffer and a parallel host copy (for large results the staged path pays a first touch of
// the staging buffer and another of the vectors). Tuning::download_registered forces one.
template <class Real, class Key, class Narrow>
DownloadHostTimes download_stage(RunState<Real, Key, Narrow>& r, cuda::PinnedBuffer& h_staging,
                                 Contacts<Narrow>& out) {
  using clock_type = std::chrono::steady_clock;
  const cuda::ContactPtrs<Narrow>& cp = r.cp;
  const bool full = r.full;
  cudaStream_t st = r.st;
  DownloadHostTimes ht;
  if (r.job.device_out) {
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    r.take_narrow_counters();  // the row count of a rejecting narrow comes with this wait
    DeviceContactsView<Narrow>& v = *r.job.device_out;
    v = DeviceContactsView<Narrow>{};
    v.count = r.n_rows;
    v.full = full;
    zip_contact_fields(v, cp, full, [](auto, auto& view, auto* d_ptr) { view = d_ptr; });
    return ht;
  }
  const std::uint32_t np = r.n_rows;  // (a rejecting narrow has read it for its tight layout)
  const std::size_t at = r.out_bytes;
  const std::byte* o = r.ws.out.data();
  bool registered = false;
  if (tuned(r.tuning.download_registered, at >= (std::size_t(64) << 20)) && np > 0) {
    const auto t0 = clock_type::now();
    out.resize(np, full);
    std::vector<std::pair<void*, const void*>> fields;  // (host, device)
    std::vector<std::size_t> sizes;
    for_each_field(out, cp, full, [&](auto& vec, const void* d_ptr) {
      fields.push_back({vec.data(), d_ptr});
      sizes.push_back(vec.size() * sizeof(vec[0]));
    });
    // First touch on every host thread: registering would fault the pages in on one thread, several
    // times slower than the parallel touch (BENCHMARKS.md §4).
    std::vector<CopyBlock> touch;
    for (std::size_t f = 0; f < fields.size(); ++f) touch.push_back({fields[f].first, nullptr, sizes[f]});
    parallel_copy(touch.data(), touch.size(), 0);
    std::size_t locked = 0;
    for (; locked < fields.size(); ++locked)
      if (cudaHostRegister(fields[locked].first, sizes[locked], cudaHostRegisterDefault) != cudaSuccess)
        break;
    registered = locked == fields.size();
    if (registered) {
      const auto t1 = clock_type::now();
      for (std::size_t f = 0; f < fields.size(); ++f)
        CG_CUDA_CHECK(
            cudaMemcpyAsync(fields[f].first, fields[f].second, sizes[f], cudaMemcpyDeviceToHost, st));
      r.events.mark(EngineStage::download, st);
      CG_CUDA_CHECK(cudaStreamSynchronize(st));
      ht.overlap_s = std::chrono::duration<double>(t1 - t0).count();  // registering, before the copy
    } else {
      (void)cudaGetLastError();  // clear the refusal; the staged path below does the download
    }
    const auto t2 = clock_type::now();
    for (std::size_t f = 0; f < locked; ++f) CG_CUDA_CHECK(cudaHostUnregister(fields[f].first));
    ht.extra_s = std::chrono::duration<double>(clock_type::now() - t2).count();  // unregistering
  }
  if (!registered) {
    h_staging.reserve(std::max<std::size_t>(at, 1));
    if (at > 0) CG_CUDA_CHECK(cudaMemcpyAsync(h_staging.data(), o, at, cudaMemcpyDeviceToHost, st));
    r.events.mark(EngineStage::download, st);
    // The result vectors are sized (no fill: HostVector) while the transfer runs.
    const auto t0 = clock_type::now();
    out.resize(np, full);
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    const auto t1 = clock_type::now();
    const std::byte* h = h_staging.data();
    auto from = [&](const void* d_ptr) { return h + (static_cast<const std::byte*>(d_ptr) - o); };
    std::vector<CopyBlock> blocks;
    for_each_field(out, cp, full, [&](auto& vec, const void* d_ptr) {
      if (np) blocks.push_back({vec.data(), from(d_ptr), vec.size() * sizeof(vec[0])});
    });
    parallel_copy(blocks.data(), blocks.size(), 0);  // pinned staging → result vectors, all host threads
    const auto t2 = clock_type::now();
    ht.overlap_s = std::chrono::duration<double>(t1 - t0).count();
    ht.extra_s = std::chrono::duration<double>(t2 - t1).count();
  }
  r.take_narrow_counters();  // the stream has synced (the counters were queued before the rows' copy)
  return ht;
}

}  // namespace cg::detail
