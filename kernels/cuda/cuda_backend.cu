// The CUDA backend: Le Grand's stages on one GPU, the same stages, math and order as the CPU backend
// (kernels/host/), so that results are bit-identical to it. This file is the class and the sequence;
// each stage's kernels and host code are in their own header, included here (one translation unit:
// no relocatable device code):
//   bounds.cuh     device-array API: validation and bounds of DEVICE bodies
//   transfer.cuh   upload (host-array path: positions, radii, report mask → device), download
//                  (contacts → pinned staging or page-locked result vectors, or left on the device)
//   skin.cuh       candidates kept across calls (EngineOptions::skin): the motion check, the kept list
//   pack.cuh       world double → local Real spheres; renumbering by z layer of cells (locality
//                  only, when the spheres outgrow the L2); control bytes, per-block entry totals
//   entries.cuh    scan of the block totals → fill (cell key, body) in body order
//   sort.cuh       cub::DeviceRadixSort::SortPairs over bits [0, key_bits)
//   pair_estimate.cuh  the pair tests estimated from the sorted keys (a max-scan and a reduction, one
//                  wait), checked before the pair stage (pair_estimate.hpp); counted in pairs
//   pairs.cuh      candidate pairs: count per sorted entry (block-staged walk) and direct write of
//                  the (a, b) u32 pairs at a block-aggregated atomic cursor; on overflow scan → fill
//   type_passes.cuh  opt-in (Tuning::type_passes): entries, sort and pairs as Le Grand's 8 passes
//   levels.cuh     BroadPhase::levels: a grid per size class (entries, sort and the pair walk above),
//                  then the pairs across levels from the smaller body's side
//   sweep.cuh      BroadPhase::sweep: the boxes sorted along an axis, a warp sweeps each
//   brute.cuh      BroadPhase::brute: every pair, tiled (broad.cuh: what these three share)
//   order.cuh      candidates in (a, b) order: grouped by a (counting or radix sort), runs by b
//   shapes.cuh     scenes with ellipsoids: shape check (device-array API), shape upload, pack_shapes
//   narrow.cuh     narrow_decide + contact rows of the requested fields, world frame (scenes with
//                  ellipsoids and precision mixed: count → scan → fill; fp64 and mixed read the world
//                  doubles of the upload buffer or the caller's DeviceBodiesView)
//   history.cuh    EngineOptions::history on device bodies: age and previous_row of each row from the
//                  previous step's keys (Thrust's lower_bound), which it then replaces
// Around them: workspace.cuh (the named DEVICE buffers, their aliases, cub_run), tuning.hpp (the
// environment knobs, read in one place), stage_events.cuh (event timing by typed EngineStage).
//
// One stream, owned by the backend (blocking: ordered after work on the legacy default stream).
// The persistent workspace grows geometrically and never shrinks: a caller that detects many frames
// allocates nothing after the first (EngineStats::device_allocations). The host synchronises twice
// per call, where it needs a count: after pack (entries total, bad-data status) and after the pair
// count (pairs total), once more after the pair stage's estimate when it is wanted (pair_estimate.cuh:
// a limit or a callback); and once at the end (a rejecting narrow whose rows go to host memory waits once
// more, for their count: narrow.cuh).
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <map>
#include <sstream>
#include <type_traits>

#include "backend.hpp"
#include "cuda/bounds.cuh"
#include "cuda/brute.cuh"
#include "cuda/cell_order.cuh"
#include "cuda/device_buffer.cuh"
#include "cuda/entries.cuh"
#include "cuda/history.cuh"
#include "cuda/levels.cuh"
#include "cuda/narrow.cuh"
#include "cuda/order.cuh"
#include "cuda/pack.cuh"
#include "cuda/pair_estimate.cuh"
#include "cuda/pairs.cuh"
#include "cuda/resident_extent.cuh"
#include "cuda/resident_rows.cuh"
#include "cuda/run_state.cuh"
#include "cuda/shapes.cuh"
#include "cuda/skin.cuh"
#include "cuda/sort.cuh"
#include "cuda/splice.cuh"
#include "cuda/stage_events.cuh"
#include "cuda/sweep.cuh"
#include "cuda/thrust_alloc.cuh"
#include "cuda/transfer.cuh"
#include "cuda/tuning.hpp"
#include "cuda/type_passes.cuh"
#include "cuda/workspace.cuh"

namespace cg {

namespace cuda {
void throw_cuda_error(cudaError_t e, const char* call, const char* file, int line) {
  std::ostringstream m;
  m << file << ":" << line << ": " << call << ": " << cudaGetErrorString(e);
  throw CudaError(m.str());
}
}  // namespace cuda

namespace cuda {
PinnedRing& pinned_ring(int device) {
  static std::mutex mutex;
  static std::map<int, PinnedRing*>* rings = new std::map<int, PinnedRing*>;  // never freed: the
  // process's pinned memory goes with it, after the CUDA context (no teardown-order hazard)
  const std::lock_guard<std::mutex> lock(mutex);
  PinnedRing*& ring = (*rings)[device];
  if (!ring) ring = new PinnedRing;
  return *ring;
}
}  // namespace cuda

int cuda_device_count() {
  static const int count = [] {
    int n = 0;
    if (cudaGetDeviceCount(&n) != cudaSuccess) {
      cudaGetLastError();  // clear the error state of the failed query
      return 0;
    }
    return n;
  }();
  return count;
}

bool cuda_available() { return cuda_device_count() > 0; }

namespace detail {

class CudaBackend {
 public:
  CudaBackend(int device, std::uint64_t memory_limit, bool high_priority) : m_memory_limit(memory_limit) {
    if (device < 0) CG_CUDA_CHECK(cudaGetDevice(&device));
    m_device = device;
    CG_CUDA_CHECK(cudaSetDevice(m_device));
    int least = 0, greatest = 0;
    CG_CUDA_CHECK(cudaDeviceGetStreamPriorityRange(&least, &greatest));
    CG_CUDA_CHECK(
        cudaStreamCreateWithPriority(&m_stream, cudaStreamDefault, high_priority ? greatest : least));
    int l2 = 0;
    CG_CUDA_CHECK(cudaDeviceGetAttribute(&l2, cudaDevAttrL2CacheSize, m_device));
    m_l2_bytes = static_cast<std::size_t>(l2);
    m_events.create();
    m_ws.device = m_device;
    refresh_tuning();
  }
  ~CudaBackend() {
    cudaSetDevice(m_device);
    if (m_stream) cudaStreamSynchronize(m_stream);
    if (m_stream) cudaStreamDestroy(m_stream);
  }  // then the members: events and buffers freed on this device
  CudaBackend(const CudaBackend&) = delete;
  CudaBackend& operator=(const CudaBackend&) = delete;

  // The knobs of tuning.hpp, read at construction and again at the start of each call (a knob set
  // between two calls on one engine takes effect, as the tests of the paths rely on).
  void refresh_tuning() {
    m_tuning = read_tuning();
    m_ws.memory_limit = m_tuning.memory_limit;
    if (m_memory_limit > 0)  // EngineOptions::device_memory_limit: the smaller cap holds
      m_ws.memory_limit = std::min<std::size_t>(m_ws.memory_limit.value_or(m_memory_limit), m_memory_limit);
  }

  // One detection: the stages in order (see the file comment).
  // Real: the broad phase's real type, Narrow: the narrow stage's and the output's (mixed: float, double).
  template <class Real, class Narrow, class Key>
  void run(const DetectJob<Real, Narrow>& job, Contacts<Narrow>& out, StageTimes& times, EngineStats& stats) {
    CG_CUDA_CHECK(cudaSetDevice(m_device));
    refresh_tuning();
    m_ws.allocations = 0;
    m_thrust.allocations = 0;
    const std::uint64_t n64 = job.body_count();
    if (n64 >= (std::uint64_t(1) << 32))
      throw InputError("more than 2^32 - 1 bodies on one rank; use more MPI ranks");
    m_h_counters.reserve(sizeof(cuda::Counters));
    RunState<Real, Key, Narrow> r{job,
                                  m_ws,
                                  m_tuning,
                                  m_events,
                                  m_stream,
                                  m_l2_bytes,
                                  reinterpret_cast<cuda::Counters*>(m_h_counters.data()),
                                  stats};
    r.n64 = n64;
    r.n = static_cast<std::uint32_t>(n64);
    r.g = job.grid;
    r.origin = job.plan.frame.origin;
    r.device_in = job.device_bodies != nullptr;
    r.full = job.fields == Fields::full;
    r.history = job.history && job.device_bodies;
    r.type_passes = m_tuning.type_passes && job.broad == BroadPhase::grid;
    r.filter = m_tuning.candidates;
    // Scenes with ellipsoids: bounding-sphere candidates less the centre cut (core/centre_cut.hpp), the
    // narrow stage decides (shapes.cuh); a skin (EngineOptions::skin): inflated bounding-sphere
    // candidates, kept across calls, less the centre cut with the skin as its margin (scene_filter,
    // core/narrow.hpp; CONTACTGRID_SKIN_CUT=0: not cut). mixed, sphere
    // scenes: the pair stage takes fp64's decision on its enlarged floats (Fp64Touch, pairs.cuh), so
    // the candidates are fp64's contacts and the narrow stage writes one row each.
    const bool skin = job.skin > 0;
    r.filter = scene_filter(r.filter, job.ellipsoids, n64, skin, skin_cut_enabled());
    if (skin && r.filter == CandidateFilter::centre_cut) r.cut_skin = static_cast<float>(2 * job.inflation);
    // the resident steps' fp32 spheres: the kept candidates and the spheres in cell order (cell_order.cuh)
    const bool cell_order = cell_order_wanted(r);
    r.cell_order = cell_order;

    reserve_pack(r);
    m_events.start(m_stream);
    upload_stage(r, cuda::pinned_ring(m_device));
    // a skin: the kept candidates (of this call's order) still hold every contact? (a cell-order list:
    // checked and packed in one pass, skin_pack_cell_stage)
    const bool fused = cell_order && m_ws.kept_cell_order && !m_tuning.step_pack_separate;
    const bool reuse = fused ? skin_pack_cell_stage(r) : skin_stage(r) && m_ws.kept_cell_order == cell_order;
    // (scenes with ellipsoids: their shapes packed first; the broad phases but the grid: the spheres
    // alone, in input order, broad.cuh)
    if (reuse && cell_order) {
      if (!fused) pack_cell_stage(r);
    } else {
      pack_stage(r, reuse || job.broad != BroadPhase::grid);
    }
    if (reuse) {
      reuse_candidates(r);
    } else {
      if (job.broad == BroadPhase::grid) {
        scan_body_blocks(r);
        if (!r.type_passes) {
          entries_stage(r);
          sort_stage(r);
          if (r.job.pair_limits.wanted()) estimate_stage(r);  // may refuse the scene (max_pair_tests)
          pairs_stage(r);
        } else {
          type_pass_stages(r);
        }
      } else if (job.broad == BroadPhase::levels) {
        levels_stages(r);
      } else if (job.broad == BroadPhase::sweep) {
        sweep_stages(r);
      } else {
        if (r.job.pair_limits.wanted()) {  // brute force tests every pair
          const std::uint64_t n = r.n64;
          check_pair_estimate(PairEstimate{n * (n - 1) / 2, n, n, n, kDevicePairTestsPerSecond},
                              r.job.pair_limits);
        }
        brute_stages(r);
      }
      m_ws.last_pairs = r.np;  // (a first skin build's room: core/kept_room.hpp, kept_room_basis)
      if (cell_order) {
        keep_cell_candidates(r);  // instead of the order stage: the walk's order, cell-order indices
      } else {
        order_stage(r);
        if (skin) keep_candidates(r);
      }
    }
    if (skin) ++(reuse ? stats.candidate_reuses : stats.candidate_builds);
    if (cell_order) {
      narrow_cell_stage(r);  // (a skin: never the 16-byte upload of narrow_fp64_rows)
    } else {
      narrow_stage(r);
      narrow_fp64_rows(r, cuda::pinned_ring(m_device));  // fp32's 16-byte upload: the rows it cannot make
    }
    m_ws.rows_cell_order = cell_order;  // download_contacts sorts such rows by (a, b)
    history_stage(r, m_thrust);
    const DownloadHostTimes host =
        download_stage(r, m_h_staging, cuda::pinned_ring(m_device), out, !m_downloaded);
    m_downloaded = m_downloaded || !job.device_out;
    if (reuse) check_shapes_read(r);  // (read with the last counters: the reuse path has no other wait)
    m_events.collect(times, host.overlap_s, host.extra_s);  // all events complete: the stream synced
    m_events.narrow_split(stats.narrow_triage_s, stats.narrow_settle_s, stats.narrow_hard_s);
    stats.fp64_rows = r.h_counters->fp64_rows;  // copied after the narrow stage
    stats.peak_device_bytes = m_ws.held_bytes() + m_thrust.held_bytes();
    stats.device_allocations = m_ws.allocations + m_thrust.allocations;
  }

  Bounds bounds(const DeviceBodiesView& v, std::size_t& ellipsoids) {
    if (v.count > 0) {  // (no bodies: nothing touched)
      CG_CUDA_CHECK(cudaSetDevice(m_device));
      refresh_tuning();
    }
    cuda::Counters c{};  // the read-back counters (all zero without bodies)
    const Bounds b = bounds_stage(
        m_ws, m_h_counters, m_stream, v,
        [&](cuda::Counters* d) {
          if (v.shape) shape_count_queue(m_stream, v, d);
        },
        c);
    ellipsoids = v.shape ? shape_check_result(c, v) : 0;
    return b;
  }

  int m_device = 0;
  cudaStream_t m_stream = nullptr;
  std::size_t m_l2_bytes = 0;  // the device's L2 cache
  Tuning m_tuning;
  StageEvents m_events;
  Workspace m_ws;                                // DEVICE buffers (workspace.cuh)
  ThrustAllocator m_thrust;                      // DEVICE temporary storage of Thrust calls
  cuda::PinnedBuffer m_h_counters, m_h_staging;  // pinned HOST staging
  cuda::PinnedBuffer m_h_gather, m_h_scatter;    // pinned HOST packed rows (Engine::gather_rows, ...)
  bool m_downloaded = false;                     // a download to host memory was made (download_transfer)
  std::uint64_t m_memory_limit = 0;              // EngineOptions::device_memory_limit (0: none)
};

std::unique_ptr<CudaBackend> make_cuda_backend(int device, std::uint64_t memory_limit, bool high_priority) {
  if (!cuda_available()) throw CudaError("no CUDA device is available to this process");
  return std::make_unique<CudaBackend>(device, memory_limit, high_priority);
}

void destroy(CudaBackend* backend) { delete backend; }

Bounds device_bounds(CudaBackend& backend, const DeviceBodiesView& bodies, std::size_t& ellipsoids) {
  return backend.bounds(bodies, ellipsoids);
}

namespace {
// Host ranges into the resident DEVICE arrays, by Tuning::upload as the upload stage chooses
// (streamed through the pinned ring from 1 MiB: the host threads fill its slots while the copy engine
// moves the previous one; else pageable copies), then the stream's end.
void upload_resident(CudaBackend& b, const std::vector<HostDevice>& ranges) {
  std::size_t total = 0;
  for (const HostDevice& h : ranges) total += h.bytes;
  if (upload_transfer(b.m_tuning, total) == HostTransfer::streamed) {
    streamed_upload(cuda::pinned_ring(b.m_device), b.m_tuning.transfer_slot_bytes, ranges, b.m_stream);
  } else {
    for (const HostDevice& h : ranges)
      if (h.bytes > 0)
        CG_CUDA_CHECK(cudaMemcpyAsync(h.device, h.host, h.bytes, cudaMemcpyHostToDevice, b.m_stream));
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

HostDevice host_device(void* device, const void* host, std::size_t bytes) {
  return {static_cast<std::byte*>(const_cast<void*>(host)), static_cast<std::byte*>(device), bytes};
}
}  // namespace

void resident_upload(CudaBackend& b, const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  b.refresh_tuning();
  Workspace& ws = b.m_ws;
  const bool shapes = !bodies.shape.empty();
  ws.reserve({{&ws.res_pos, n * sizeof(Vec3<double>)},
              {&ws.res_rad, n * sizeof(double)},
              {&ws.res_report, bodies.report.empty() ? 0 : n},
              {&ws.res_shape, shapes ? n * sizeof(Shape) : 0},
              {&ws.res_semi, shapes ? n * sizeof(Vec3<double>) : 0},
              {&ws.res_orient, shapes ? n * sizeof(Quat<double>) : 0},
              {&ws.res_id, bodies.id.empty() ? 0 : n * sizeof(std::int64_t)}},
             "resident bodies");
  ws.res_count = n;
  ws.res_ided = !bodies.id.empty();
  ws.res_reported = !bodies.report.empty();
  ws.res_shaped = shapes;
  if (n == 0) return;
  std::vector<HostDevice> ranges{
      host_device(ws.res_pos.data(), bodies.position.data(), n * sizeof(Vec3<double>)),
      host_device(ws.res_rad.data(), bodies.radius.data(), n * sizeof(double))};
  if (!bodies.report.empty()) ranges.push_back(host_device(ws.res_report.data(), bodies.report.data(), n));
  if (!bodies.id.empty())
    ranges.push_back(host_device(ws.res_id.data(), bodies.id.data(), n * sizeof(std::int64_t)));
  if (shapes) {
    ranges.push_back(host_device(ws.res_shape.data(), bodies.shape.data(), n * sizeof(Shape)));
    ranges.push_back(host_device(ws.res_semi.data(), bodies.semi_axes.data(), n * sizeof(Vec3<double>)));
    ranges.push_back(host_device(ws.res_orient.data(), bodies.orientation.data(), n * sizeof(Quat<double>)));
  }
  upload_resident(b, ranges);
}

void resident_splice(CudaBackend& b, std::span<const std::size_t> leaving, std::span<const std::size_t> at,
                     const BodiesView& arrivals) {
  static_assert(sizeof(std::size_t) == sizeof(std::uint64_t));
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t n = ws.res_count, l = leaving.size(), m = at.size(), out = n - l + m;
  struct Field {
    Bytes* rows;
    const void* host;  // the arrivals'
    std::size_t row_bytes;
  };
  std::vector<Field> fields{{&ws.res_pos, arrivals.position.data(), sizeof(Vec3<double>)},
                            {&ws.res_rad, arrivals.radius.data(), sizeof(double)}};
  if (ws.res_reported) fields.push_back({&ws.res_report, arrivals.report.data(), 1});
  if (ws.res_ided) fields.push_back({&ws.res_id, arrivals.id.data(), sizeof(std::int64_t)});
  if (ws.res_shaped) {
    fields.push_back({&ws.res_shape, arrivals.shape.data(), sizeof(Shape)});
    fields.push_back({&ws.res_semi, arrivals.semi_axes.data(), sizeof(Vec3<double>)});
    fields.push_back({&ws.res_orient, arrivals.orientation.data(), sizeof(Quat<double>)});
  }
  // temp: the leaving rows, the places, then the arrivals' rows of the field being spliced
  std::size_t arrival_bytes = 0;
  for (const Field& f : fields) arrival_bytes = std::max(arrival_bytes, cuda::align16(m * f.row_bytes));
  const std::size_t index_bytes =
      cuda::align16(l * sizeof(std::uint64_t)) + cuda::align16(m * sizeof(std::uint64_t));
  ws.reserve({{&ws.temp, index_bytes + arrival_bytes}}, "resident splice");
  auto* d_leaving = reinterpret_cast<std::uint64_t*>(ws.temp.data());
  auto* d_at = reinterpret_cast<std::uint64_t*>(ws.temp.data() + cuda::align16(l * sizeof(std::uint64_t)));
  std::byte* d_arrivals = ws.temp.data() + index_bytes;
  if (l > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(d_leaving, leaving.data(), l * sizeof(std::uint64_t),
                                  cudaMemcpyHostToDevice, b.m_stream));
  if (m > 0)
    CG_CUDA_CHECK(
        cudaMemcpyAsync(d_at, at.data(), m * sizeof(std::uint64_t), cudaMemcpyHostToDevice, b.m_stream));
  for (const Field& f : fields) {
    // the old rows and the arrivals into canon_field (a download's scratch), then back into the
    // field's storage (grown when the rows grow; its old contents are in canon_field by then)
    if (m > 0)
      CG_CUDA_CHECK(cudaMemcpyAsync(d_arrivals, f.host, m * f.row_bytes, cudaMemcpyHostToDevice, b.m_stream));
    ws.reserve({{&ws.canon_field, out * f.row_bytes}}, "resident splice");
    if (n + m > 0) {
      if (f.row_bytes % sizeof(std::uint64_t) == 0) {
        using W = unsigned long long;
        cuda::splice_kernel<W><<<cuda::blocks_for(n + m), cuda::kBlock, 0, b.m_stream>>>(
            reinterpret_cast<const W*>(f.rows->data()), n, reinterpret_cast<const W*>(d_arrivals), m,
            d_leaving, l, d_at, f.row_bytes / sizeof(W), reinterpret_cast<W*>(ws.canon_field.data()));
      } else {
        using W = unsigned char;
        cuda::splice_kernel<W><<<cuda::blocks_for(n + m), cuda::kBlock, 0, b.m_stream>>>(
            reinterpret_cast<const W*>(f.rows->data()), n, reinterpret_cast<const W*>(d_arrivals), m,
            d_leaving, l, d_at, f.row_bytes, reinterpret_cast<W*>(ws.canon_field.data()));
      }
      CG_CUDA_CHECK_LAUNCH("splice_kernel");
    }
    // (the arrivals' upload of the next field waits for this kernel: one stream)
    CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
    ws.reserve({{f.rows, out * f.row_bytes}}, "resident bodies");
    cuda::device_copy(f.rows->data(), ws.canon_field.data(), out * f.row_bytes, b.m_stream);
  }
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  ws.res_count = out;
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

DeviceBodiesView resident_view(const CudaBackend& b) {
  DeviceBodiesView v;
  v.position = reinterpret_cast<const double*>(b.m_ws.res_pos.data());
  v.radius = reinterpret_cast<const double*>(b.m_ws.res_rad.data());
  v.report = b.m_ws.res_reported ? reinterpret_cast<const std::uint8_t*>(b.m_ws.res_report.data()) : nullptr;
  v.count = b.m_ws.res_count;
  if (b.m_ws.res_shaped) {  // else null: the sphere-only path
    v.shape = reinterpret_cast<const Shape*>(b.m_ws.res_shape.data());
    v.semi_axes = reinterpret_cast<const double*>(b.m_ws.res_semi.data());
    v.orientation = reinterpret_cast<const double*>(b.m_ws.res_orient.data());
  }
  if (b.m_ws.res_ided) v.id = reinterpret_cast<const std::int64_t*>(b.m_ws.res_id.data());
  return v;
}

void resident_mark(CudaBackend& b) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  mark_stage(b.m_ws, b.m_ws.res_mark, b.m_stream, reinterpret_cast<const double*>(b.m_ws.res_pos.data()),
             b.m_ws.res_count);
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

Bounds resident_extent(CudaBackend& b, std::span<const std::int64_t> ids, bool marked, double& displacement) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const Workspace& ws = b.m_ws;
  return extent_stage(b.m_ws, b.m_h_counters, b.m_stream, reinterpret_cast<const double*>(ws.res_pos.data()),
                      reinterpret_cast<const double*>(ws.res_rad.data()),
                      marked ? reinterpret_cast<const double*>(ws.res_mark.data()) : nullptr, ws.res_count,
                      ids, displacement);
}

// Rows [first, first + count) of positions and radii between the resident DEVICE arrays and host
// memory (page-locked when the caller pinned it: Engine::pin_host).
void resident_copy(CudaBackend& b, std::size_t first, std::size_t count, Vec3<double>* position,
                   double* radius, bool to_device) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  auto* d_pos = reinterpret_cast<Vec3<double>*>(b.m_ws.res_pos.data()) + first;
  auto* d_rad = reinterpret_cast<double*>(b.m_ws.res_rad.data()) + first;
  if (to_device) {
    upload_resident(b, {host_device(d_pos, position, count * sizeof(Vec3<double>)),
                        host_device(d_rad, radius, count * sizeof(double))});
    return;
  }
  CG_CUDA_CHECK(
      cudaMemcpyAsync(position, d_pos, count * sizeof(Vec3<double>), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaMemcpyAsync(radius, d_rad, count * sizeof(double), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

// Rows [first, first + count) of the resident semi-axes and orientations (a null host pointer: that
// field is not copied), as resident_copy.
void resident_shape_copy(CudaBackend& b, std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                         Quat<double>* orientation, bool to_device) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  std::vector<HostDevice> ranges;
  auto copy = [&](void* host, std::byte* device, std::size_t row_bytes) {
    if (!host) return;
    void* d = device + first * row_bytes;
    if (to_device)
      ranges.push_back(host_device(d, host, count * row_bytes));
    else
      CG_CUDA_CHECK(cudaMemcpyAsync(host, d, count * row_bytes, cudaMemcpyDeviceToHost, b.m_stream));
  };
  copy(semi_axes, b.m_ws.res_semi.data(), sizeof(Vec3<double>));
  copy(orientation, b.m_ws.res_orient.data(), sizeof(Quat<double>));
  if (to_device)
    upload_resident(b, ranges);
  else
    CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

namespace {
std::size_t packed_bytes(bool orientations) { return orientations ? 64 : 32; }
const double* doubles(const Bytes& b) { return reinterpret_cast<const double*>(b.data()); }
double* doubles(Bytes& b) { return reinterpret_cast<double*>(b.data()); }
const std::uint32_t* list_rows(const Workspace& ws, int list) {
  return reinterpret_cast<const std::uint32_t*>(ws.row_lists[list].data());
}
}  // namespace

void rows_set_list(CudaBackend& b, int list, std::span<const std::size_t> rows) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const std::size_t m = rows.size();
  std::vector<std::uint32_t> u32(m);
  for (std::size_t k = 0; k < m; ++k) u32[k] = static_cast<std::uint32_t>(rows[k]);
  b.m_ws.reserve({{&b.m_ws.row_lists[list], m * sizeof(std::uint32_t)}}, "row lists");
  if (m > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(b.m_ws.row_lists[list].data(), u32.data(), m * sizeof(std::uint32_t),
                                  cudaMemcpyHostToDevice, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

std::span<const std::byte> rows_gather(CudaBackend& b, int list, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t bytes = count * packed_bytes(orientations);
  b.m_h_gather.reserve(std::max<std::size_t>(bytes, 1));
  if (count == 0) return {b.m_h_gather.data(), 0};
  ws.reserve({{&ws.row_pack, bytes}}, "row gather");
  cuda::pack_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, b.m_stream>>>(
      doubles(ws.res_pos), doubles(ws.res_rad), orientations ? doubles(ws.res_orient) : nullptr,
      list_rows(ws, list), count, doubles(ws.row_pack));
  CG_CUDA_CHECK_LAUNCH("pack_rows_kernel");
  CG_CUDA_CHECK(
      cudaMemcpyAsync(b.m_h_gather.data(), ws.row_pack.data(), bytes, cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  return {b.m_h_gather.data(), bytes};
}

std::span<std::byte> rows_scatter_buffer(CudaBackend& b, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  const std::size_t bytes = count * packed_bytes(orientations);
  b.m_h_scatter.reserve(std::max<std::size_t>(bytes, 1));
  return {b.m_h_scatter.data(), bytes};
}

void rows_scatter(CudaBackend& b, int list, std::size_t count, bool orientations) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t bytes = count * packed_bytes(orientations);
  if (count == 0) return;
  ws.reserve({{&ws.row_pack, bytes}}, "row scatter");
  CG_CUDA_CHECK(
      cudaMemcpyAsync(ws.row_pack.data(), b.m_h_scatter.data(), bytes, cudaMemcpyHostToDevice, b.m_stream));
  cuda::unpack_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, b.m_stream>>>(
      doubles(ws.row_pack), list_rows(ws, list), count, doubles(ws.res_pos), doubles(ws.res_rad),
      orientations ? doubles(ws.res_orient) : nullptr);
  CG_CUDA_CHECK_LAUNCH("unpack_rows_kernel");
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

void rows_copy(CudaBackend& to, CudaBackend& from, int from_list, int to_list, std::size_t count,
               bool orientations) {
  if (to.m_device != from.m_device)
    throw UsageError("copy_rows: the engines are on CUDA devices " + std::to_string(from.m_device) + " and " +
                     std::to_string(to.m_device));
  CG_CUDA_CHECK(cudaSetDevice(to.m_device));
  if (count == 0) return;
  Workspace& ws = to.m_ws;
  const Workspace& fs = from.m_ws;
  cuda::copy_rows_kernel<<<cuda::blocks_for(count), cuda::kBlock, 0, to.m_stream>>>(
      doubles(fs.res_pos), doubles(fs.res_rad), orientations ? doubles(fs.res_orient) : nullptr,
      list_rows(fs, from_list), list_rows(ws, to_list), count, doubles(ws.res_pos), doubles(ws.res_rad),
      orientations ? doubles(ws.res_orient) : nullptr);
  CG_CUDA_CHECK_LAUNCH("copy_rows_kernel");
  CG_CUDA_CHECK(cudaStreamSynchronize(to.m_stream));
}

std::vector<std::size_t> rows_outside(CudaBackend& b, int axis, double lo, double hi) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  Workspace& ws = b.m_ws;
  const std::size_t n = ws.res_count;
  if (n == 0) return {};
  if (n >= (std::size_t(1) << 31)) throw InputError("rows_outside: more than 2^31 - 1 resident rows");
  ws.reserve({{&ws.row_selected, 16 + n * sizeof(std::uint32_t)}}, "rows outside");
  auto* d_count = reinterpret_cast<std::uint32_t*>(ws.row_selected.data());
  auto* d_rows = reinterpret_cast<std::uint32_t*>(ws.row_selected.data() + 16);
  const cuda::OutsideInterval outside{doubles(ws.res_pos), axis, lo, hi};
  cub_run(ws, "rows outside", [&](void* t, std::size_t& bytes) {
    return cub::DeviceSelect::If(t, bytes, thrust::counting_iterator<std::uint32_t>(0), d_rows, d_count,
                                 int(n), outside, b.m_stream);
  });
  std::uint32_t count = 0;
  CG_CUDA_CHECK(cudaMemcpyAsync(&count, d_count, sizeof(count), cudaMemcpyDeviceToHost, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  std::vector<std::uint32_t> u32(count);
  if (count > 0)
    CG_CUDA_CHECK(cudaMemcpyAsync(u32.data(), d_rows, count * sizeof(std::uint32_t), cudaMemcpyDeviceToHost,
                                  b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
  return std::vector<std::size_t>(u32.begin(), u32.end());
}

template <class Broad, class Narrow>
void run_stages(CudaBackend& backend, const DetectJob<Broad, Narrow>& job, Contacts<Narrow>& out,
                StageTimes& times, EngineStats& stats) {
  if (job.plan.key64)
    backend.run<Broad, Narrow, std::uint64_t>(job, out, times, stats);
  else
    backend.run<Broad, Narrow, std::uint32_t>(job, out, times, stats);
}

template void run_stages(CudaBackend&, const DetectJob<float>&, Contacts<float>&, StageTimes&, EngineStats&);
template void run_stages(CudaBackend&, const DetectJob<double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);
template void run_stages(CudaBackend&, const DetectJob<float, double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);

}  // namespace detail
}  // namespace cg
