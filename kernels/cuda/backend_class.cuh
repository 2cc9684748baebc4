#pragma once
// The CUDA backend's class: the device, its stream, the knobs, the DEVICE workspace and the pinned
// staging it owns; run (one detection: the stages in order) and bounds (the device-array API's
// check). Apart from cuda_backend.cu (the one translation unit that includes it, with the stage
// headers listed there) so that the class reads as the sequence alone; its calls outside a detection
// are backend_copies.cuh (history, contacts, pinning) and backend_resident.cuh (resident bodies, rows).
#include <algorithm>
#include <cstdint>

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

namespace cg::detail {

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
    CG_CUDA_CHECK(cudaEventCreate(&m_upload_events[0]));
    CG_CUDA_CHECK(cudaEventCreate(&m_upload_events[1]));
    m_ws.device = m_device;
    refresh_tuning();
  }
  ~CudaBackend() {
    cudaSetDevice(m_device);
    if (m_stream) cudaStreamSynchronize(m_stream);
    if (m_stream) cudaStreamDestroy(m_stream);
    for (cudaEvent_t e : m_upload_events)
      if (e) cudaEventDestroy(e);
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

  // One detection: the stages in order (see cuda_backend.cu's file comment).
  // Real: the broad phase's real type, Narrow: the narrow stage's and the output's (mixed: float, double).
  template <class Real, class Narrow, class Key>
  void run(const DetectJob<Real, Narrow>& job, Contacts<Narrow>& out, StageTimes& times, EngineStats& stats) {
    const auto entry = std::chrono::steady_clock::now();
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
    r.filter = scene_filter(r.filter, job.ellipsoids, n64, skin, skin_cut_wanted(m_ws.skin_turning));
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
    if (!reuse && r.filter == CandidateFilter::centre_cut && skin && !skin_cut_wanted(m_ws.skin_turning)) {
      r.filter = CandidateFilter::bounding_spheres;  // this check saw a body turn (core/skin.hpp)
      r.cut_skin = 0;
    }
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
    if (m_tuning.trace) {
      m_events.trace(entry, times);
      std::fprintf(stderr,
                   "cuda trace: the download's host work %.3f ms before or beside the copy, %.3f after\n",
                   host.overlap_s * 1e3, host.extra_s * 1e3);
    }
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
  cudaEvent_t m_upload_events[2] = {};           // around upload_bodies' copies (upload_seconds)
  bool m_downloaded = false;                     // a download to host memory was made (download_transfer)
  std::uint64_t m_memory_limit = 0;              // EngineOptions::device_memory_limit (0: none)
};

}  // namespace cg::detail
