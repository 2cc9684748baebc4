#pragma once
// The state one CUDA detection hands from stage to stage: the call's sizes and knobs, the DEVICE
// pointers each stage produces (views of the workspace, see workspace.cuh) and the host's copies of
// the counters. Built by CudaBackend::run (backend_class.cuh), which calls the stages in order.
#include <chrono>
#include <sstream>
#include <thread>

#include "backend.hpp"
#include "core/centre_cut.hpp"
#include "core/shape.hpp"
#include "cuda/common.cuh"
#include "cuda/device_buffer.cuh"
#include "cuda/stage_events.cuh"
#include "cuda/tuning.hpp"
#include "cuda/workspace.cuh"

namespace cg::detail {

// Real: the broad phase's real type (pack … order); Narrow: the narrow stage's and the output's
// (precision_of<Real, Narrow>(): mixed is float, double).
template <class Real, class Key, class Narrow = Real>
struct RunState {
  // the call
  const DetectJob<Real, Narrow>& job;
  Workspace& ws;
  const Tuning& tuning;
  StageEvents& events;
  cudaStream_t st;
  std::size_t l2_bytes;        // the device's L2 cache
  cuda::Counters* h_counters;  // pinned HOST copy of the counters
  EngineStats& stats;
  // sizes
  std::uint64_t n64 = 0;
  std::uint32_t n = 0, nb = 0;  // bodies, blocks of bodies
  GridParams<Real> g{};
  Vec3<double> origin{};
  bool device_in = false, full = false, type_passes = false;
  bool history = false;  // the history stage runs (DetectJob::history): its two columns are laid out
  FieldSet fields() const { return {full, history}; }  // the columns of the output rows
  std::size_t body_block_words = 0;
  // upload: the bodies (DEVICE; read again by the narrow stage, NarrowBodies)
  const double* d_pos = nullptr;
  const double* d_rad = nullptr;
  const std::uint8_t* d_report = nullptr;
  // fp32's 16-byte upload (transfer.cuh, packed_upload_stage): the spheres the host packed, read by
  // pack instead of d_pos / d_rad (null until rows need the world doubles: narrow_fp64_rows)
  const Sphere<float>* d_packed_in = nullptr;
  // pack
  Sphere<Real>* d_spheres = nullptr;        // input order
  PackedShape<Narrow>* d_shapes = nullptr;  // input order; scenes with ellipsoids only (shapes.cuh)
  ShapeRowsView shape_rows{};               // the world shape rows packed from (DEVICE): fp32's fp64 pairs
  Sphere<Real>* d_cell_spheres = nullptr;   // cell order
  CutShape* d_cell_cut = nullptr;           // cell order; CandidateFilter::centre_cut only (pack.cuh)
  // a skin's build of the centre cut: the cut's margin (CentreCut::skin, 2·inflation; 0 without a skin)
  float cut_skin = 0;
  // the cut shapes whose boxes give the bodies' cells (cut_cells): a fresh call's centre cut; a skin's
  // build keeps the inflated bounding spheres' cells (core/centre_cut.hpp)
  const CutShape* box_cut() const { return cut_skin > 0 ? nullptr : d_cell_cut; }
  std::uint32_t* d_perm = nullptr;  // cell order → input index
  bool renumbered = false;          // the bodies are in cell order (else d_perm is the identity)
  // the pair stage's permutation: none where it is the identity (cuda/pairs.cuh: input_index)
  const std::uint32_t* pair_perm() const { return renumbered ? d_perm : nullptr; }
  std::uint8_t* d_ctrl = nullptr;  // cell order
  std::uint32_t* d_body_totals = nullptr;
  std::uint32_t* d_body_offsets = nullptr;  // single-sort path
  std::uint32_t* d_type_totals = nullptr;   // type-pass path: [8][nb] totals, then offsets
  std::uint32_t* d_type_offsets = nullptr;
  Key* d_base = nullptr;    // type passes: super-cell index of each body's lowest even cell
  Key* d_lo_key = nullptr;  // single sort: key of each body's lowest cell (cell order)
  cuda::Counters* d_counters = nullptr;
  std::uint64_t n_entries = 0;
  std::uint64_t type_entries[8] = {};
  // entries, sort
  cub::DoubleBuffer<Key> keys{nullptr, nullptr};
  cub::DoubleBuffer<std::uint32_t> body{nullptr, nullptr};
  // pairs: the candidate pairs (input indices a < b), in (a, b) order after the order stage
  cub::DoubleBuffer<std::uint32_t> pair_a{nullptr, nullptr}, pair_b{nullptr, nullptr};
  std::uint32_t np = 0;
  // a cell-order skin call (cuda/cell_order.cuh: cell_order_wanted), and at its build whether the pair
  // stage wrote the kept list itself (cell-order indices in ws.kept_pairs, pair_a / pair_b point there)
  bool cell_order = false;
  bool kept_written = false;
  CandidateFilter filter = CandidateFilter::spheres_touch;  // Tuning::candidates
  // narrow: the contact rows (DEVICE; n_rows <= np, the accepted candidates) and their bytes from
  // ws.out.data()
  cuda::ContactPtrs<Narrow> cp{};
  std::size_t out_bytes = 0;
  std::uint32_t n_rows = 0;
  // the rejecting narrow (narrow.cuh): n_rows and its stats are in h_counters once the stream has synced
  // (take_narrow_counters)
  bool rows_pending = false;

  // Bytes of the contact rows of `pairs` pairs (the layout of narrow_stage).
  std::size_t out_bytes_for(std::uint64_t pairs) const {
    const std::size_t v3 = cuda::align16(pairs * sizeof(Vec3<Narrow>)),
                      ids = cuda::align16(pairs * sizeof(std::int64_t)),
                      reals = cuda::align16(pairs * sizeof(Narrow));
    return 2 * ids + 3 * v3 + reals + (full ? 4 * v3 : 0) + (history ? 2 * ids : 0);
  }
  // After the stream has synced: the rejecting narrow's counters (queued by it) into the stats, and its
  // row count into n_rows.
  void take_narrow_counters() {
    if (!rows_pending) return;
    rows_pending = false;
    const cuda::Counters& c = *h_counters;
    stats.narrow_fallbacks = c.fallbacks;
    stats.narrow_unconverged = c.unconverged;
    stats.fp64_rows = c.fp64_rows;
    stats.narrow_unsettled = c.unsettled;
    stats.narrow_hard = c.hard;
    stats.narrow_solver_runs = c.solver_runs;
    stats.narrow_evaluations = c.evaluations;
    stats.narrow_max_evaluations = c.max_evaluations;
    n_rows = static_cast<std::uint32_t>(c.rows);
  }
  // The counters copied to h_counters (synchronises the stream).
  void read_counters() {
    CG_CUDA_CHECK(
        cudaMemcpyAsync(h_counters, d_counters, sizeof(cuda::Counters), cudaMemcpyDeviceToHost, st));
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
  }

  // The pair stage was estimated far above the usual (pair_work_unusual) and a caller follows its
  // progress (PairLimits::on_progress): set by the broad phase's estimate.
  bool pair_progress = false;

  // read_counters after a pair stage's kernel, whose blocks each add their tests to Counters::tests
  // when they finish. With pair_progress, while the kernel runs the tests done so far go to
  // PairLimits::on_progress every 100 ms (a copy on a stream of its own reads the counter the blocks
  // add to), then the whole count, finished. Without it, read_counters: the usual call pays nothing.
  void read_counters_reporting_tests() {
    if (!pair_progress) return read_counters();
    const auto& report = *job.pair_limits.on_progress;
    cudaStream_t probe_stream = nullptr;
    CG_CUDA_CHECK(cudaStreamCreateWithFlags(&probe_stream, cudaStreamNonBlocking));
    struct StreamGuard {
      cudaStream_t s;
      ~StreamGuard() { cudaStreamDestroy(s); }
    } guard{probe_stream};
    cuda::PinnedBuffer probe;
    probe.reserve(sizeof(unsigned long long));
    auto* done = reinterpret_cast<unsigned long long*>(probe.data());
    for (;;) {
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
      const cudaError_t state = cudaStreamQuery(st);
      if (state != cudaErrorNotReady) {
        CG_CUDA_CHECK(state);
        break;
      }
      CG_CUDA_CHECK(
          cudaMemcpyAsync(done, &d_counters->tests, sizeof *done, cudaMemcpyDeviceToHost, probe_stream));
      CG_CUDA_CHECK(cudaStreamSynchronize(probe_stream));
      report(*done, false);
    }
    read_counters();
    report(h_counters->tests, true);
  }
};

inline void check_pairs(std::uint64_t n_pairs) {
  if (n_pairs >= (std::uint64_t(1) << 31)) {
    std::ostringstream m;
    m << n_pairs << " contacting pairs exceed the 2^31 - 1 items one CUB sort handles; use more MPI ranks";
    throw ResourceError(m.str());
  }
}

}  // namespace cg::detail
