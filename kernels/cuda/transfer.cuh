#pragma once
// CUDA transfers: the upload of host bodies, the download of the contact rows (or their description
// in DEVICE memory), and the copies of the device-array API (download_contacts, resident bodies).
#include <chrono>
#include <string_view>
#include <vector>

#include "cuda/narrow.cuh"
#include "cuda/run_state.cuh"
#include "cuda/tuning.hpp"
#include "host_vector.hpp"
#include "upload_pack.hpp"

namespace cg::detail {

// f(host vector, device array) for each contact field the run produces (the optional ones only
// in `fields`), in table order: the order of the device layout (layout_contacts).
template <class Real, class F>
void for_each_field(Contacts<Real>& out, const cuda::ContactPtrs<Real>& cp, FieldSet fields, F&& f) {
  zip_contact_fields(out, cp, fields,
                     [&](auto, auto& vec, auto* d_ptr) { f(vec, static_cast<const void*>(d_ptr)); });
}

// A host range and the device range it is copied to or from.
struct HostDevice {
  std::byte* host;
  std::byte* device;
  std::size_t bytes;
};

// The parts of `ranges`, laid end to end, that fall in bytes [from, from + len) of the stream: f(host
// part, device part, bytes, offset of the part in the window).
template <class F>
void for_each_in_window(const std::vector<HostDevice>& ranges, std::size_t from, std::size_t len, F&& f) {
  std::size_t at = 0;
  for (const HostDevice& h : ranges) {
    const std::size_t lo = std::max(from, at), hi = std::min(from + len, at + h.bytes);
    if (lo < hi) f(h.host + (lo - at), h.device + (lo - at), hi - lo, lo - from);
    at += h.bytes;
    if (at >= from + len) break;
  }
}

// Host → device through the pinned ring: slot k is filled by all host threads (parallel_copy) and
// its copies queued on `st`, while the copy engine still moves slot k − 1. The host returns when the
// last slot is queued; the ring's events guard the slots against the next transfer.
inline void streamed_upload(cuda::PinnedRing& ring, std::size_t slot_bytes,
                            const std::vector<HostDevice>& ranges, cudaStream_t st) {
  const std::lock_guard<std::mutex> lock(ring.mutex());
  ring.ready(slot_bytes);
  std::size_t total = 0;
  for (const HostDevice& h : ranges) total += h.bytes;
  std::vector<CopyBlock> fill;
  for (std::size_t k = 0, from = 0; from < total; ++k, from += slot_bytes) {
    const std::size_t len = std::min(slot_bytes, total - from);
    ring.wait(k);  // the slot's previous copy has left it
    std::byte* slot = ring.slot(k);
    fill.clear();
    for_each_in_window(ranges, from, len,
                       [&](std::byte* host, std::byte*, std::size_t bytes, std::size_t at) {
                         fill.push_back({slot + at, host, bytes});
                       });
    parallel_copy(fill.data(), fill.size(), 0);
    for_each_in_window(ranges, from, len,
                       [&](std::byte*, std::byte* device, std::size_t bytes, std::size_t at) {
                         CG_CUDA_CHECK(cudaMemcpyAsync(device, slot + at, bytes, cudaMemcpyHostToDevice, st));
                       });
    CG_CUDA_CHECK(cudaEventRecord(ring.done(k), st));
  }
}

// With CONTACTGRID_CUDA_HOST_PATH=packed, fp32 sphere calls from host arrays go up as the 16-byte
// spheres fp32's pack makes (upload_pack.hpp) instead of the 32-byte world doubles: no ellipsoids, no
// skin (its reference positions are the doubles), no report mask, a narrow stage that writes every
// candidate (narrow_fp64_rows reruns it), the streamed or automatic upload.
template <class Real, class Key, class Narrow>
bool packed_upload_fits(const RunState<Real, Key, Narrow>& r) {
  return std::is_same_v<Real, float> && std::is_same_v<Narrow, float> && !r.device_in && r.n64 > 0 &&
         r.job.ellipsoids == 0 && !(r.job.skin > 0) && r.job.bodies.report.empty() &&
         !narrow_may_reject(r.filter) &&
         (r.tuning.upload == HostTransfer::automatic || r.tuning.upload == HostTransfer::streamed) &&
         host_path() == HostPath::packed;
}

// Host → device of the 16-byte spheres through the pinned ring: slot k is packed from the caller's
// doubles by all host threads while the copy engine moves slot k − 1. The spheres land in ws.pos
// (24 bytes a body of room); pack reads them (r.d_packed_in), the doubles stay on the host.
template <class Real, class Key, class Narrow>
void packed_upload_stage(RunState<Real, Key, Narrow>& r, cuda::PinnedRing& ring) {
  const BodiesView& b = r.job.bodies;
  auto* d_spheres = reinterpret_cast<Sphere<float>*>(r.ws.pos.data());
  // whole spheres a slot, slots 256-byte aligned (the knob may ask for any size)
  const std::size_t slot_bytes = std::max<std::size_t>(4096, r.tuning.transfer_slot_bytes / 256 * 256);
  const std::size_t per_slot = slot_bytes / sizeof(Sphere<float>);
  {
    const std::lock_guard<std::mutex> lock(ring.mutex());
    ring.ready(slot_bytes);
    for (std::size_t k = 0, first = 0; first < r.n64; ++k, first += per_slot) {
      const std::size_t count = std::min<std::size_t>(per_slot, r.n64 - first);
      ring.wait(k);  // the slot's previous copy has left it
      auto* slot = reinterpret_cast<Sphere<float>*>(ring.slot(k));
      pack_upload_spheres(b.position.data(), b.radius.data(), r.origin, first, first + count, slot, 0);
      CG_CUDA_CHECK(cudaMemcpyAsync(d_spheres + first, slot, count * sizeof(Sphere<float>),
                                    cudaMemcpyHostToDevice, r.st));
      CG_CUDA_CHECK(cudaEventRecord(ring.done(k), r.st));
    }
  }
  r.d_packed_in = d_spheres;
  r.d_pos = nullptr;  // (read by nothing until narrow_fp64_rows uploads them)
  r.d_rad = nullptr;
  r.d_report = nullptr;
  r.events.mark(EngineStage::upload, r.st);
}

// upload: the DEVICE bodies of the call: the caller's arrays (device-array API), or the host arrays
// copied into ws.pos / rad / report and, with ellipsoids, ws.shape_kind / semi / orient (stage
// "upload"), by Tuning::upload: streamed through the pinned
// ring (automatic from 1 MiB), the arrays page-locked in place for the copy and unpinned once it is
// done (registered), or one pageable copy that the driver stages on one thread (below 1 MiB). A range
// the driver refuses to page-lock is copied pageable.
template <class Real, class Key, class Narrow>
void upload_stage(RunState<Real, Key, Narrow>& r, cuda::PinnedRing& ring) {
  if (r.device_in) {
    r.d_pos = r.job.device_bodies->position;
    r.d_rad = r.job.device_bodies->radius;
    r.d_report = r.job.device_bodies->report;
    return;
  }
  if (packed_upload_fits(r)) {
    packed_upload_stage(r, ring);
    return;
  }
  Workspace& ws = r.ws;
  const std::uint64_t n64 = r.n64;
  auto range = [](void* device, const void* host, std::size_t bytes) {
    return HostDevice{static_cast<std::byte*>(const_cast<void*>(host)), static_cast<std::byte*>(device),
                      bytes};
  };
  std::vector<HostDevice> ranges{
      range(ws.pos.data(), r.job.bodies.position.data(), n64 * sizeof(Vec3<double>)),
      range(ws.rad.data(), r.job.bodies.radius.data(), n64 * sizeof(double))};
  r.d_pos = reinterpret_cast<const double*>(ws.pos.data());
  r.d_rad = reinterpret_cast<const double*>(ws.rad.data());
  r.d_report = nullptr;
  if (!r.job.bodies.report.empty()) {
    ranges.push_back(range(ws.report.data(), r.job.bodies.report.data(), n64));
    r.d_report = reinterpret_cast<const std::uint8_t*>(ws.report.data());
  }
  if (r.job.ellipsoids > 0) {  // the shape rows (reserve_pack), packed by the pack stage (shapes.cuh)
    const BodiesView& b = r.job.bodies;
    ranges.push_back(range(ws.shape_kind.data(), b.shape.data(), n64 * sizeof(Shape)));
    ranges.push_back(range(ws.shape_semi.data(), b.semi_axes.data(), n64 * sizeof(Vec3<double>)));
    ranges.push_back(range(ws.shape_orient.data(), b.orientation.data(), n64 * sizeof(Quat<double>)));
  }
  std::size_t total = 0;
  for (const HostDevice& h : ranges) total += h.bytes;
  const HostTransfer how = upload_transfer(r.tuning, total);
  if (how == HostTransfer::streamed) {
    streamed_upload(ring, r.tuning.transfer_slot_bytes, ranges, r.st);
    r.events.mark(EngineStage::upload, r.st);
    return;
  }
  std::vector<void*> locked;
  for (const HostDevice& h : ranges) {
    if (h.bytes == 0) continue;
    if (how == HostTransfer::registered) {  // page-locking does not write to the range
      if (cudaHostRegister(h.host, h.bytes, cudaHostRegisterDefault) == cudaSuccess)
        locked.push_back(h.host);
      else
        (void)cudaGetLastError();  // refused: the copy below is pageable
    }
    CG_CUDA_CHECK(cudaMemcpyAsync(h.device, h.host, h.bytes, cudaMemcpyHostToDevice, r.st));
  }
  r.events.mark(EngineStage::upload, r.st);
  if (!locked.empty()) {
    CG_CUDA_CHECK(cudaStreamSynchronize(r.st));  // the copies read the locked ranges until here
    for (void* p : locked) CG_CUDA_CHECK(cudaHostUnregister(p));
  }
}

// After the narrow stage of a call that uploaded the 16-byte spheres: the rows whose normal fp32
// cannot resolve (core/narrow.hpp: fp32_resolves) take the world doubles, which the device lacks. The
// narrow stage counted them and left them empty; where there are any (near-coincident centres), the
// doubles go up into ws.pos / ws.rad (the spheres there were read by pack) and the narrow stage runs
// again with them: every row as the doubles' upload gives it, bit for bit. Its time counts as the
// narrow stage's.
template <class Real, class Key, class Narrow>
void narrow_fp64_rows(RunState<Real, Key, Narrow>& r, cuda::PinnedRing& ring) {
  if (!r.d_packed_in || r.np == 0) return;
  CG_CUDA_CHECK(cudaStreamSynchronize(r.st));  // the counters came down with the narrow stage
  if (r.h_counters->fp64_rows == 0) return;
  const std::uint64_t n64 = r.n64;
  const std::vector<HostDevice> ranges{
      {reinterpret_cast<std::byte*>(const_cast<Vec3<double>*>(r.job.bodies.position.data())), r.ws.pos.data(),
       n64 * sizeof(Vec3<double>)},
      {reinterpret_cast<std::byte*>(const_cast<double*>(r.job.bodies.radius.data())), r.ws.rad.data(),
       n64 * sizeof(double)}};
  streamed_upload(ring, r.tuning.transfer_slot_bytes, ranges, r.st);
  r.d_pos = reinterpret_cast<const double*>(r.ws.pos.data());
  r.d_rad = reinterpret_cast<const double*>(r.ws.rad.data());
  r.d_packed_in = nullptr;
  CG_CUDA_CHECK(cudaMemsetAsync(&r.d_counters->fp64_rows, 0, sizeof(r.d_counters->fp64_rows), r.st));
  narrow_stage(r);
}

// Host seconds of the download that the events do not see (StageEvents::collect).
struct DownloadHostTimes {
  double overlap_s = 0;  // host work that overlapped the transfer
  double extra_s = 0;    // host work after it
};

// Device → host through the pinned ring: the copies of the first slots are queued at once; as each
// slot's copy completes, all host threads move it into the ranges' host parts and the slot takes the
// next window. `queued_all` is called once the last copy is queued (the stage's event goes there).
// Returns the host seconds spent moving the last slot, after every copy is done.
template <class F>
double streamed_download(cuda::PinnedRing& ring, std::size_t slot_bytes,
                         const std::vector<HostDevice>& ranges, cudaStream_t st, F&& queued_all) {
  using clock_type = std::chrono::steady_clock;
  const std::lock_guard<std::mutex> lock(ring.mutex());
  ring.ready(slot_bytes);
  std::size_t total = 0;
  for (const HostDevice& h : ranges) total += h.bytes;
  const std::size_t slots = (total + slot_bytes - 1) / slot_bytes;
  auto queue = [&](std::size_t k) {
    const std::size_t from = k * slot_bytes, len = std::min(slot_bytes, total - from);
    std::byte* slot = ring.slot(k);
    for_each_in_window(ranges, from, len,
                       [&](std::byte*, std::byte* device, std::size_t bytes, std::size_t at) {
                         CG_CUDA_CHECK(cudaMemcpyAsync(slot + at, device, bytes, cudaMemcpyDeviceToHost, st));
                       });
    CG_CUDA_CHECK(cudaEventRecord(ring.done(k), st));
    if (k + 1 == slots) queued_all();
  };
  for (std::size_t k = 0; k < std::min(slots, cuda::PinnedRing::kSlots); ++k) queue(k);
  std::vector<CopyBlock> drain;
  double last_s = 0;
  for (std::size_t k = 0; k < slots; ++k) {
    ring.wait(k);
    const auto t0 = clock_type::now();
    const std::size_t from = k * slot_bytes, len = std::min(slot_bytes, total - from);
    const std::byte* slot = ring.slot(k);
    drain.clear();
    for_each_in_window(ranges, from, len,
                       [&](std::byte* host, std::byte*, std::size_t bytes, std::size_t at) {
                         drain.push_back({host, slot + at, bytes});
                       });
    parallel_copy(drain.data(), drain.size(), 0);
    if (k + cuda::PinnedRing::kSlots < slots) queue(k + cuda::PinnedRing::kSlots);
    last_s = std::chrono::duration<double>(clock_type::now() - t0).count();
  }
  return last_s;
}

// The result vectors' pool blocks page-locked once and kept so (HostPool::lock_block): the rows come
// down straight into them at the pinned rate, no staging copy, no locking a call.
inline bool lock_for_cuda(void* p, std::size_t bytes) {
  if (cudaHostRegister(p, bytes, cudaHostRegisterPortable) == cudaSuccess) return true;
  (void)cudaGetLastError();  // refused: the caller takes another download
  return false;
}
inline void unlock_for_cuda(void* p) {
  if (cudaHostUnregister(p) != cudaSuccess) (void)cudaGetLastError();  // (the context may be gone)
}

// The download straight into `out` (np > 0 rows): every field's vector in a pooled host block that is
// page-locked (on its first use, after a first touch of its pages on every host thread: locking would
// fault them in on one). False, `out` sized, when a field is too small for the pool (below 1 MiB), the
// driver refuses to lock, or a block would have to be locked when `may_lock` is false: the caller
// downloads another way.
template <class Real, class Key, class Narrow>
bool direct_download(RunState<Real, Key, Narrow>& r, Contacts<Narrow>& out, DownloadHostTimes& ht,
                     bool may_lock) {
  using clock_type = std::chrono::steady_clock;
  const auto t0 = clock_type::now();
  const FieldSet set = r.fields();
  out.resize(r.n_rows, set);
  std::vector<HostDevice> fields;
  for_each_field(out, r.cp, set, [&](auto& vec, const void* d_ptr) {
    fields.push_back({reinterpret_cast<std::byte*>(vec.data()),
                      static_cast<std::byte*>(const_cast<void*>(d_ptr)), vec.size() * sizeof(vec[0])});
  });
  HostPool& pool = HostPool::instance();
  std::vector<CopyBlock> touch;
  for (const HostDevice& f : fields) {
    if (f.bytes < HostPool::k_pooled_min) return false;
    if (!pool.block_locked(f.host)) {
      if (!may_lock) return false;
      touch.push_back({f.host, nullptr, f.bytes});
    }
  }
  if (!touch.empty()) parallel_copy(touch.data(), touch.size(), 0);
  for (const HostDevice& f : fields)
    if (pool.lock_block(f.host, lock_for_cuda, unlock_for_cuda) < f.bytes) return false;
  const auto t1 = clock_type::now();
  for (const HostDevice& f : fields)
    CG_CUDA_CHECK(cudaMemcpyAsync(f.host, f.device, f.bytes, cudaMemcpyDeviceToHost, r.st));
  r.events.mark(EngineStage::download, r.st);
  CG_CUDA_CHECK(cudaStreamSynchronize(r.st));
  ht.overlap_s = std::chrono::duration<double>(t1 - t0).count();  // sizing and locking, before the copy
  r.take_narrow_counters();  // the stream has synced (the counters were queued before the rows' copy)
  return true;
}

// download: the contact rows described in DEVICE memory (job.device_out), straight into `out`'s
// page-locked pool blocks (direct_download: the automatic download but an engine's first of fewer
// than 64 MiB, not with CONTACTGRID_CUDA_HOST_PATH=old), or copied into `out` by Tuning::download
// (download_transfer): through one whole pinned staging buffer and a parallel host copy (single; also where
// the driver refuses to register), streamed through the pinned ring (the host copy out of one slot overlaps
// the transfer of the next), or straight into the result vectors page-locked in place (registered: a parallel
// first touch, then cudaHostRegister).
template <class Real, class Key, class Narrow>
DownloadHostTimes download_stage(RunState<Real, Key, Narrow>& r, cuda::PinnedBuffer& h_staging,
                                 cuda::PinnedRing& ring, Contacts<Narrow>& out, bool first_download) {
  using clock_type = std::chrono::steady_clock;
  const cuda::ContactPtrs<Narrow>& cp = r.cp;
  const FieldSet set = r.fields();
  cudaStream_t st = r.st;
  DownloadHostTimes ht;
  if (r.job.device_out) {
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    r.take_narrow_counters();  // the row count of a rejecting narrow comes with this wait
    DeviceContactsView<Narrow>& v = *r.job.device_out;
    v = DeviceContactsView<Narrow>{};
    v.count = r.n_rows;
    v.full = set.full;
    v.history = set.history;
    zip_contact_fields(v, cp, set, [](auto, auto& view, auto* d_ptr) { view = d_ptr; });
    return ht;
  }
  const std::uint32_t np = r.n_rows;  // (a rejecting narrow has read it for its tight layout)
  // Blocks are locked on an engine's later downloads, and on a first one where the automatic download
  // would lock the rows anyway (registered, from 64 MiB: locked once and kept, they spare the unlock).
  // An engine's first download of fewer rows locks nothing: locking for one call costs more than the
  // copy it speeds up (BENCHMARKS.md §20; the CLI and Python's detect() make one download an engine).
  const bool may_lock = !first_download || download_transfer(r.tuning, h_staging.bytes(), r.out_bytes,
                                                             true) == HostTransfer::registered;
  if (np > 0 && r.tuning.download == HostTransfer::automatic && host_path() != HostPath::old &&
      direct_download(r, out, ht, may_lock))
    return ht;
  const std::size_t at = r.out_bytes;
  const std::byte* o = r.ws.out.data();
  const HostTransfer how = download_transfer(r.tuning, h_staging.bytes(), at, first_download);
  if (how == HostTransfer::streamed && np > 0) {
    const auto t0 = clock_type::now();
    out.resize(np, set);
    std::vector<HostDevice> ranges;
    for_each_field(out, cp, set, [&](auto& vec, const void* d_ptr) {
      ranges.push_back({reinterpret_cast<std::byte*>(vec.data()),
                        static_cast<std::byte*>(const_cast<void*>(d_ptr)), vec.size() * sizeof(vec[0])});
    });
    ht.extra_s = streamed_download(ring, r.tuning.transfer_slot_bytes, ranges, st,
                                   [&] { r.events.mark(EngineStage::download, st); });
    ht.overlap_s = std::chrono::duration<double>(clock_type::now() - t0).count() - ht.extra_s;
    r.take_narrow_counters();  // every copy is done (the counters were queued before the rows')
    return ht;
  }
  bool registered = false;
  if (how == HostTransfer::registered && np > 0) {
    const auto t0 = clock_type::now();
    out.resize(np, set);
    std::vector<std::pair<void*, const void*>> fields;  // (host, device)
    std::vector<std::size_t> sizes;
    for_each_field(out, cp, set, [&](auto& vec, const void* d_ptr) {
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
    out.resize(np, set);
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    const auto t1 = clock_type::now();
    const std::byte* h = h_staging.data();
    auto from = [&](const void* d_ptr) { return h + (static_cast<const std::byte*>(d_ptr) - o); };
    std::vector<CopyBlock> blocks;
    for_each_field(out, cp, set, [&](auto& vec, const void* d_ptr) {
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
