#pragma once
// Internal interface between the engine (engine.cpp: bounds, frame, plan, id mapping) and its
// backends. A backend runs the stages from packing to the narrow phase; it returns contacts whose
// id_a/id_b are *local* body indices (a < b), sorted, with points in the world frame.
#include <cstddef>
#include <cstdint>

#include "core/ellipsoid_contact.hpp"
#include "core/grid.hpp"
#include "core/narrow.hpp"
#include "core/skin.hpp"
#include "engine.hpp"
#include "host/stages.hpp"

namespace cg::detail {

// One detection for the backends. Broad: the real type of the broad phase (pack … order: local
// spheres, grid); Narrow: of the narrow phase and the output (precision_of<Broad, Narrow>(): fp32
// float/float, fp64 double/double, mixed float/double).
template <class Broad, class Narrow = Broad>
struct DetectJob {
  using BroadReal = Broad;
  using NarrowReal = Narrow;
  BodiesView bodies;       // host, world frame, ascending ids
  GridPlan plan;           // the frame's grid (BroadPhase::levels: key_bits and key64 are the levels')
  GridParams<Broad> grid;  // of plan (its radius_margin is every broad phase's)
  Fields fields = Fields::basic;
  // CUDA only. device_bodies set: read the bodies from DEVICE memory (bodies is then empty).
  // device_out set: leave the contacts on the device and describe them there (out stays empty).
  const DeviceBodiesView* device_bodies = nullptr;
  DeviceContactsView<Narrow>* device_out = nullptr;
  // Shapes: the number of ellipsoids (0: the sphere-only path, which runs no shape code) and
  // the ellipsoid solver's settings (from EngineOptions).
  std::size_t ellipsoids = 0;
  SolverSettings<Narrow> solver{};
  // Candidates kept across calls (EngineOptions::skin > 0; skin 0: neither field is read).
  // inflation: world length added to every radius in the pair stage (cells and the sphere test) when
  // the list is built. check: the bodies match the kept list's (count, ids, shape presence, frame
  // bound; engine.cpp): measure the motion since its build, reuse it when skin_covers(), else build.
  double skin = 0, inflation = 0;
  bool check = false;
  // The caller takes the rows in any order (Engine::detect_resident: resident_contacts() downloads
  // them): the CUDA backend may keep a skin's candidates in cell order (cuda/cell_order.cuh).
  bool any_row_order = false;
  // EngineOptions::history on DEVICE bodies (CUDA): the history stage runs on the device after the
  // narrow stage, keyed by device_bodies->id (or the indices), against the backend's device history
  // (history_upload / history_download move it between host and device).
  bool history = false;
  // What the broad phase does with its estimate of the pair tests before its pair stage
  // (check_pair_estimate, pair_estimate.hpp; from EngineOptions).
  PairLimits pair_limits{};
  // The broad phase (resolved: never automatic) and what levels and sweep need.
  BroadPhase broad = BroadPhase::grid;
  LevelParams<Broad> levels{};
  int sweep_axis = 0;
  std::size_t body_count() const { return device_bodies ? device_bodies->count : bodies.size(); }
};

template <class Real>
GridParams<Real> grid_params(const GridPlan& plan, double radius_margin = 0) {
  GridParams<Real> g{};
  g.inv_cell = static_cast<Real>(1.0 / plan.frame.cell_size);
  g.radius_margin = static_cast<Real>(radius_margin);
  for (int k = 0; k < 3; ++k) {
    g.base[k] = plan.base[k];
    g.dims[k] = plan.dims[k];
    g.half[k] = plan.half[k];
  }
  g.half_bits = plan.half_bits;
  return g;
}

// Host copies of several (dst, src, bytes) blocks, split into equal pieces over OpenMP threads
// (defined in engine.cpp, an OpenMP translation unit, so the CUDA backend's host code can use it).
// A block with src == nullptr has one byte of each 4 KiB page of dst zeroed: the first touch of
// fresh memory spread over the threads (before cudaHostRegister, which faults pages on one thread).
struct CopyBlock {
  void* dst;
  const void* src;
  std::size_t bytes;
};
void parallel_copy(const CopyBlock* blocks, std::size_t count, int threads);

// Bits needed to hold values 0 … n-1 (0 for n <= 1).
inline int bits_for(std::uint64_t n) {
  int b = 0;
  while (b < 64 && (n - 1) >> b) ++b;
  return n <= 1 ? 0 : b;
}

// The CPU backend (kernels/host/): OpenMP threads, the oracle for the CUDA backend.
struct HostBackend {
  explicit HostBackend(int threads_ = 0, CandidateFilter candidates_ = CandidateFilter::spheres_touch)
      : threads(threads_), candidates(candidates_) {}
  int threads = 0;
  // The pair stage's filter: spheres_touch (default; narrow then writes one row per candidate) or
  // cells (every pair the cell rule assigns: narrow rejects the non-touching ones; same contacts).
  CandidateFilter candidates = CandidateFilter::spheres_touch;
  host::KeptCandidates kept;  // EngineOptions::skin > 0: the list kept across calls
};

template <class Broad, class Narrow>
void run_stages(HostBackend& backend, const DetectJob<Broad, Narrow>& job, Contacts<Narrow>& out,
                StageTimes& times, EngineStats& stats);

// The CUDA backend (kernels/cuda/): owns persistent device buffers; defined only in CUDA builds.
class CudaBackend;
// high_priority: its stream at the device's highest priority (EngineOptions::high_priority)
std::unique_ptr<CudaBackend> make_cuda_backend(int device, std::uint64_t memory_limit,
                                               bool high_priority);  // throws CudaError without CUDA
template <class Broad, class Narrow>
void run_stages(CudaBackend& backend, const DetectJob<Broad, Narrow>& job, Contacts<Narrow>& out,
                StageTimes& times, EngineStats& stats);
void destroy(CudaBackend* backend);
// Resident bodies of Engine::set_resident (DEVICE rows kept between calls, shape rows included).
void resident_upload(CudaBackend& backend, const BodiesView& bodies);
// Engine::splice_resident on the DEVICE rows (the arrivals carry the fields the rows have).
void resident_splice(CudaBackend& backend, std::span<const std::size_t> leaving,
                     std::span<const std::size_t> at, const BodiesView& arrivals);
DeviceBodiesView resident_view(const CudaBackend& backend);
// The contacts of a DeviceContactsView copied into `out` (sized here).
template <class Real>
void download_contacts(CudaBackend& backend, const DeviceContactsView<Real>& view, Contacts<Real>& out);
bool pin_host(CudaBackend& backend, void* p, std::size_t bytes);
void unpin_host(CudaBackend& backend, void* p);
void resident_copy(CudaBackend& backend, std::size_t first, std::size_t count, Vec3<double>* position,
                   double* radius, bool to_device);
// The same for the semi-axes and orientations of resident shape rows (a null pointer: skipped).
void resident_shape_copy(CudaBackend& backend, std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                         Quat<double>* orientation, bool to_device);
// Engine::set_row_list / gather_rows / scatter_buffer / scatter_rows / copy_rows / rows_outside on the
// DEVICE rows (cuda/resident_rows.cuh): the lists on the device, the packed rows through the backend's
// page-locked gather and scatter buffers; `count`: the list's length (the engine keeps it).
void rows_set_list(CudaBackend& backend, int list, std::span<const std::size_t> rows);
std::span<const std::byte> rows_gather(CudaBackend& backend, int list, std::size_t count, bool orientations);
std::span<std::byte> rows_scatter_buffer(CudaBackend& backend, std::size_t count, bool orientations);
void rows_scatter(CudaBackend& backend, int list, std::size_t count, bool orientations);
void rows_copy(CudaBackend& to, CudaBackend& from, int from_list, int to_list, std::size_t count,
               bool orientations);
std::vector<std::size_t> rows_outside(CudaBackend& backend, int axis, double lo, double hi);
// The contact history of the device path (EngineOptions::history): the previous step's keys and ages
// copied into the backend's DEVICE history, or out of it.
void history_upload(CudaBackend& backend, const ContactHistory& history);
void history_download(CudaBackend& backend, ContactHistory& history);
// The host-array path's bodies streamed into the backend's DEVICE input rows before any bounds
// (cuda/tuning.hpp: HostPath::device); the view holds until the next call on the backend.
// upload_seconds: the copies' time on the device's stream (waits for them).
DeviceBodiesView upload_bodies(CudaBackend& backend, const BodiesView& bodies);
double upload_seconds(CudaBackend& backend);
// Validation and bounds of DEVICE bodies (same results and InputError texts as compute_bounds), and
// where bodies.shape is set their shape rows checked as validate_shapes (same texts, after the bodies'
// own) and the ellipsoids counted into `ellipsoids` (0 without shapes); one wait for both.
Bounds device_bounds(CudaBackend& backend, const DeviceBodiesView& bodies, std::size_t& ellipsoids);
// Engine::mark_resident / resident_extent on the DEVICE rows (cuda/resident_extent.cuh): the resident
// centres copied aside on the device; the rows' bounds (a bad row named by ids[row], or its index
// without ids) and, when `marked`, the largest displacement from the copy, in one pass and one wait.
void resident_mark(CudaBackend& backend);
Bounds resident_extent(CudaBackend& backend, std::span<const std::int64_t> ids, bool marked,
                       double& displacement);

}  // namespace cg::detail

// unique_ptr<CudaBackend> works where CudaBackend is incomplete (engine.cpp): it deletes through
// destroy(), defined with the complete type in the CUDA backend (or engine.cpp's fallback).
template <>
struct std::default_delete<cg::detail::CudaBackend> {
  void operator()(cg::detail::CudaBackend* p) const { cg::detail::destroy(p); }
};
