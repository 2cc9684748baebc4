// The CUDA backend: Le Grand's stages on one GPU, the same stages, math and order as the CPU backend
// (kernels/host/), so that results are bit-identical to it. This file is the one translation unit (no
// relocatable device code) and the backend's entry points: the class and the sequence are
// backend_class.cuh, its calls outside a detection backend_copies.cuh (history, contacts, pinning) and
// backend_resident.cuh (resident bodies, row lists); each stage's kernels and host code are in their
// own header, included by the class's:
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
//   narrow_shapes.cuh  scenes with ellipsoids: the narrow's count passes (triage, settle, the whole
//                  start set: a list each, WarpRuns), fp32's pairs in fp64
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
#include <map>
#include <sstream>

#include "backend.hpp"
#include "cuda/backend_class.cuh"
#include "cuda/backend_copies.cuh"
#include "cuda/backend_resident.cuh"

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

std::unique_ptr<CudaBackend> make_cuda_backend(int device, std::uint64_t memory_limit, bool high_priority) {
  if (!cuda_available()) throw CudaError("no CUDA device is available to this process");
  return std::make_unique<CudaBackend>(device, memory_limit, high_priority);
}

void destroy(CudaBackend* backend) { delete backend; }

Bounds device_bounds(CudaBackend& backend, const DeviceBodiesView& bodies, std::size_t& ellipsoids) {
  return backend.bounds(bodies, ellipsoids);
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
