// The CUDA backend: Le Grand's stages on one GPU, the same stages, math and order as the CPU backend
// (kernels/host/host_backend.cpp), so that results are bit-identical to it.
//
// One stream, owned by the backend (blocking: ordered after work on the legacy default stream).
// A persistent workspace of device buffers grows geometrically and never shrinks: a caller that
// detects many frames allocates nothing after the first (EngineStats::device_allocations).
// The host synchronises twice per call, where it needs a count: after pack (entries total, bad-data
// status) and after the pair count (pairs total); and once at the end.
//
// Stages (event-timed on the stream; names as the host's plus "upload" and "download"):
//   upload    host-array path only: positions, radii, report mask → device
//   pack      world double → local Real spheres; renumber the bodies by z layer of cells (a one-pass
//             radix sort, for locality of the pair stage only, when the spheres outgrow the L2); control
//             bytes, per-block entry totals
//   entries   scan of the block totals → fill (cell key, body) in body order
//   sort      cub::DeviceRadixSort::SortPairs over bits [0, key_bits)
//   pairs     count per sorted entry (block-staged walk) and direct write of the (a, b) u32 pairs at a
//             block-aggregated atomic cursor; when they overflow the space there: scan → fill
//   order     pairs grouped by a (counting sort when its counters fit in L2, else a radix sort by
//             a), then each run of equal a sorted by b (sort_runs_kernel): the (a, b) order
//   narrow    contact data of the requested fields, world frame
//   download  contacts → pinned staging → Contacts<Real> (unless they stay on the device); the
//             result vectors are sized while the transfer runs, the copy runs on all host threads
// Opt-in type-pass path (CONTACTGRID_CUDA_TYPE_PASSES=1, for memory-bound scenes): entries, sort and
// pairs run as Le Grand's 8 passes by cell type, each over <= n entries keyed by super-cell; the
// stage times are those of the passes summed.
#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <sstream>
#include <string_view>

#include "backend.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/stage_kernels.cuh"

namespace cg {

namespace cuda {
void throw_cuda_error(cudaError_t e, const char* call, const char* file, int line) {
  std::ostringstream m;
  m << file << ":" << line << ": " << call << ": " << cudaGetErrorString(e);
  throw CudaError(m.str());
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

using cuda::BoundsPartial;
using cuda::ContactPtrs;
using cuda::Counters;
using cuda::DeviceBuffer;
using cuda::kBlock;
using cuda::PinnedBuffer;
using Bytes = DeviceBuffer<std::byte>;

namespace {
constexpr const char* kStageNames[] = {"upload", "pack",  "entries", "sort",
                                       "pairs",  "order", "narrow",  "download"};
constexpr int kStages = 8;
constexpr int kPassEvents = 1 + 3 * 8;
// Le Grand's 8 passes by cell type (one sort of <= n entries per type): opt-in, for scenes bound by
// device memory. Measured on an H200 (kernels/cuda/BENCH.md, h-cudaperf2): 65 instead of 125 B/sphere
// (fp32, excl. contacts) but slower at every size measured (2^24 fp32: 7.55 vs 6.86 ms; 2^20: 0.99 vs
// 0.59 ms: 8 compaction fills and 8 sorts cost more than the radix pass they save), so the single sort
// of all entries is the default. CONTACTGRID_CUDA_TYPE_PASSES=1 selects the type passes, =0 (or
// unset) the single sort.
bool use_type_passes(std::uint64_t) {
  const char* v = std::getenv("CONTACTGRID_CUDA_TYPE_PASSES");
  return v && v[0] == '1';
}
constexpr int kBoundsBlocks = 512;  // partials of device_bounds (<= cuda::kBoundsFold)
std::uint32_t blocks_for(std::uint64_t n) { return static_cast<std::uint32_t>((n + kBlock - 1) / kBlock); }
std::size_t align16(std::size_t b) { return (b + 15) & ~std::size_t(15); }
}  // namespace

// f(host vector, device array) for each contact field the run produces (the four `full` ones only
// with Fields::full), in the order of the device layout.
template <class Real, class F>
void for_each_field(Contacts<Real>& out, const ContactPtrs<Real>& cp, bool full, F&& f) {
  f(out.id_a, cp.id_a);
  f(out.id_b, cp.id_b);
  f(out.position_on_a, cp.position_on_a);
  f(out.position_on_b, cp.position_on_b);
  f(out.normal_on_b, cp.normal_on_b);
  f(out.distance, cp.distance);
  if (full) {
    f(out.local_point_a, cp.local_point_a);
    f(out.local_point_b, cp.local_point_b);
    f(out.lateral_friction_dir1, cp.dir1);
    f(out.lateral_friction_dir2, cp.dir2);
  }
}

class CudaBackend {
 public:
  explicit CudaBackend(int device) {
    if (device < 0) CG_CUDA_CHECK(cudaGetDevice(&device));
    m_device = device;
    CG_CUDA_CHECK(cudaSetDevice(m_device));
    CG_CUDA_CHECK(cudaStreamCreate(&m_stream));
    int l2 = 0;
    CG_CUDA_CHECK(cudaDeviceGetAttribute(&l2, cudaDevAttrL2CacheSize, m_device));
    m_l2_bytes = static_cast<std::size_t>(l2);
    for (auto& e : m_events) CG_CUDA_CHECK(cudaEventCreate(&e));
    for (auto& e : m_pass_events) CG_CUDA_CHECK(cudaEventCreate(&e));
  }
  ~CudaBackend() {
    cudaSetDevice(m_device);
    if (m_stream) cudaStreamSynchronize(m_stream);
    for (auto& e : m_events)
      if (e) cudaEventDestroy(e);
    for (auto& e : m_pass_events)
      if (e) cudaEventDestroy(e);
    if (m_stream) cudaStreamDestroy(m_stream);
  }
  CudaBackend(const CudaBackend&) = delete;
  CudaBackend& operator=(const CudaBackend&) = delete;

  struct Request {
    Bytes* buffer;
    std::size_t bytes;
  };
  // Grows the buffers of `reqs` (contents discarded) after checking that the growth fits in the
  // device's free memory: geometric growth where it fits, exact sizes where only those fit, else
  // ResourceError naming the bytes needed and available. Synchronises the device when it allocates.
  void reserve(std::initializer_list<Request> reqs, const char* what) {
    std::size_t grow_geo = 0, grow_exact = 0;
    for (const Request& r : reqs) {
      grow_geo += r.buffer->capacity_for(r.bytes, true) - r.buffer->capacity();
      grow_exact += r.buffer->capacity_for(r.bytes, false) - r.buffer->capacity();
    }
    if (grow_exact == 0) return;
    std::size_t free_b = 0, total_b = 0;
    CG_CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    // CONTACTGRID_DEVICE_MEMORY_LIMIT (bytes) caps the engine's workspace: a smaller GPU, or a GPU
    // shared with a simulation, can be imitated (and the out-of-memory path tested).
    if (const char* cap = std::getenv("CONTACTGRID_DEVICE_MEMORY_LIMIT")) {
      const std::size_t limit = std::strtoull(cap, nullptr, 10), held = held_bytes();
      free_b = std::min(free_b, limit > held ? limit - held : std::size_t(0));
    }
    const std::size_t margin = std::size_t(64) << 20;  // CUDA context, launch and allocator slack
    // Buffers that grow free their old storage first, so their current capacity is available too.
    std::size_t reclaim = 0;
    for (const Request& r : reqs)
      if (r.bytes > r.buffer->capacity()) reclaim += r.buffer->capacity();
    const std::size_t avail = free_b + reclaim > margin ? free_b + reclaim - margin : 0;
    bool geometric = true;
    if (grow_geo + reclaim > avail) geometric = false;
    if (grow_exact + reclaim > avail) {
      std::ostringstream m;
      m << "device memory: the " << what << " stage needs " << grow_exact << " more bytes (workspace "
        << held_bytes() + grow_exact << " bytes in all) but only " << free_b << " of " << total_b
        << " bytes are free on CUDA device " << m_device
        << "; use fewer bodies per rank (more MPI ranks) or a smaller scene";
      throw ResourceError(m.str());
    }
    for (const Request& r : reqs)
      if (r.buffer->reserve(r.bytes, geometric)) ++m_allocations;
  }
  std::uint64_t held_bytes() const {
    std::uint64_t s = 0;
    for (const Bytes* b :
         {&m_pos,       &m_rad,         &m_report,       &m_spheres,   &m_cell_spheres, &m_perm,
          &m_ctrl,      &m_body_blocks, &m_entry_blocks, &m_keys[0],   &m_keys[1],      &m_bodies[0],
          &m_bodies[1], &m_pairs,       &m_out,          &m_temp,      &m_counters,     &m_partials,
          &m_base,      &m_res_pos,     &m_res_rad,      &m_res_report})
      s += b->bytes();
    return s;
  }

  // CUB two-phase call: `call(temp, bytes)` is queried with temp == nullptr, then run with m_temp
  // (which the caller reserved through temp_bytes() before; asserted here).
  template <class F>
  std::size_t temp_bytes(F&& call) {
    std::size_t bytes = 0;
    CG_CUDA_CHECK(call(nullptr, bytes));
    return bytes;
  }
  template <class F>
  void run_cub(F&& call) {
    std::size_t bytes = 0;
    CG_CUDA_CHECK(call(nullptr, bytes));
    if (bytes > m_temp.bytes()) throw Error("internal: CUB temp storage not reserved");
    CG_CUDA_CHECK(call(m_temp.data(), bytes));
  }

  template <class Real, class Key>
  void run(const DetectJob<Real>& job, Contacts<Real>& out, StageTimes& times, EngineStats& stats);
  Bounds bounds(const DeviceBodiesView& v);

  // The first invalid body (index i of n, read back from the device): throws compute_bounds' text.
  [[noreturn]] void throw_bad_body(const double* d_pos, const double* d_rad, std::uint64_t i,
                                   std::int64_t id) {
    Vec3<double> p{};
    double r = 0;
    CG_CUDA_CHECK(cudaMemcpy(&p, d_pos + 3 * i, sizeof(p), cudaMemcpyDeviceToHost));
    CG_CUDA_CHECK(cudaMemcpy(&r, d_rad + i, sizeof(r), cudaMemcpyDeviceToHost));
    compute_bounds(BodiesView{{&p, 1}, {&r, 1}, {&id, 1}, {}});  // throws InputError naming `id`
    throw Error("internal: the device flagged body " + std::to_string(id) + " but it is valid");
  }

  int m_device = 0;
  cudaStream_t m_stream = nullptr;
  cudaEvent_t m_events[kStages + 1] = {};
  std::size_t m_l2_bytes = 0;                   // the device's L2 cache
  cudaEvent_t m_pass_events[kPassEvents] = {};  // type-pass path: start, then per pass fill/sort/count ends
  std::uint64_t m_allocations = 0;
  // Workspace (DEVICE): input copies (host path), packed spheres, control bytes, block totals and
  // offsets, entries (double-buffered keys and bodies), pairs (only when they do not fit in the dead
  // alternate entry-body buffer), contacts, CUB temp.
  Bytes m_pos, m_rad, m_report, m_spheres, m_cell_spheres, m_perm, m_ctrl, m_body_blocks, m_entry_blocks;
  Bytes m_keys[2], m_bodies[2], m_pairs, m_out, m_temp, m_counters, m_partials;
  Bytes m_base;  // type-pass path: per body the super-cell index of its lowest even cell
  Bytes m_res_pos, m_res_rad, m_res_report;  // resident bodies (Engine::set_resident)
  std::size_t m_res_count = 0;
  bool m_res_reported = false;             // resident report mask present
  PinnedBuffer m_h_counters, m_h_staging;  // pinned HOST staging
};

Bounds CudaBackend::bounds(const DeviceBodiesView& v) {
  Bounds b;
  b.count = v.count;
  if (v.count == 0) return b;
  CG_CUDA_CHECK(cudaSetDevice(m_device));
  reserve({{&m_partials, kBoundsBlocks * sizeof(BoundsPartial)}, {&m_counters, sizeof(Counters)}}, "bounds");
  m_h_counters.reserve(sizeof(Counters) + sizeof(BoundsPartial));
  auto* d_partials = m_partials.span_as<BoundsPartial>(kBoundsBlocks).data();
  auto* d_counters = m_counters.span_as<Counters>(1).data();
  const int grid = static_cast<int>(std::min<std::uint64_t>(kBoundsBlocks, blocks_for(v.count)));
  CG_CUDA_CHECK(cudaMemsetAsync(d_counters, 0, sizeof(Counters), m_stream));
  cuda::bounds_partial_kernel<<<grid, kBlock, 0, m_stream>>>(v.position, v.radius, v.count, d_partials,
                                                             d_counters);
  CG_CUDA_CHECK_LAUNCH("bounds_partial");
  cuda::bounds_final_kernel<<<1, cuda::kBoundsFold, 0, m_stream>>>(d_partials, grid);
  CG_CUDA_CHECK_LAUNCH("bounds_final");
  std::byte* h = m_h_counters.data();
  CG_CUDA_CHECK(cudaMemcpyAsync(h, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, m_stream));
  CG_CUDA_CHECK(cudaMemcpyAsync(h + sizeof(Counters), d_partials, sizeof(BoundsPartial),
                                cudaMemcpyDeviceToHost, m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(m_stream));
  Counters c;
  BoundsPartial p;
  std::memcpy(&c, h, sizeof(c));
  std::memcpy(&p, h + sizeof(Counters), sizeof(p));
  if (c.bad) {
    const std::uint64_t i = v.count - c.bad;
    throw_bad_body(v.position, v.radius, i, static_cast<std::int64_t>(i));
  }
  b.lo = {p.lo[0], p.lo[1], p.lo[2]};
  b.hi = {p.hi[0], p.hi[1], p.hi[2]};
  b.r_max = p.r_max;
  for (int k = 0; k < 3; ++k) b.r_sum[k] = p.r_sum[k];
  return b;
}

template <class Real, class Key>
void CudaBackend::run(const DetectJob<Real>& job, Contacts<Real>& out, StageTimes& times,
                      EngineStats& stats) {
  using clock_type = std::chrono::steady_clock;
  CG_CUDA_CHECK(cudaSetDevice(m_device));
  m_allocations = 0;
  const std::uint64_t n64 = job.body_count();
  if (n64 >= (std::uint64_t(1) << 32))
    throw InputError("more than 2^32 - 1 bodies on one rank; use more MPI ranks");
  const auto n = static_cast<std::uint32_t>(n64);
  const GridParams<Real> g = job.grid;
  const Vec3<double> origin = job.plan.frame.origin;
  const bool device_in = job.device_bodies != nullptr;
  const bool full = job.fields == Fields::full;
  cudaStream_t st = m_stream;
  bool recorded[kStages] = {};
  bool has_override[kStages] = {};  // type-pass path: entries, sort, pairs summed over the passes
  double override_ms[kStages] = {};
  bool override_tail = false;
  auto mark = [&](int stage) {
    CG_CUDA_CHECK(cudaEventRecord(m_events[stage + 1], st));
    recorded[stage] = true;
  };

  // ---- upload (host-array path) -----------------------------------------------------------------
  const std::uint32_t nb = blocks_for(n);
  const bool type_passes = use_type_passes(n64);
  // Block totals and their scan: of the entry counts (single sort), or, in the type-pass path, the
  // entry totals then [8][nb] bodies-per-type totals and their scan.
  const std::size_t body_block_words = type_passes ? 17 * std::size_t(nb) : 2 * std::size_t(nb);
  const std::size_t scan_nb_temp = temp_bytes([&](void* t, std::size_t& b) {
    return cub::DeviceScan::ExclusiveSum(t, b, static_cast<std::uint32_t*>(nullptr),
                                         static_cast<std::uint32_t*>(nullptr), int(type_passes ? 8 * nb : nb),
                                         st);
  });
  // Renumbering sort of the bodies by z layer of cells (locality only; see home_layer_key): at most
  // 8 key bits, one radix pass. Its four arrays are the entry buffers, not yet live.
  const int z_bits = std::max(1, bits_for(std::uint64_t(g.dims[2])));
  const int layer_shift = std::max(0, z_bits - 8);
  const int home_bits = z_bits - layer_shift;
  cub::DoubleBuffer<Key> home_key(nullptr, nullptr);
  cub::DoubleBuffer<std::uint32_t> home_index(nullptr, nullptr);
  auto sort_home = [&](void* t, std::size_t& b) {
    return cub::DeviceRadixSort::SortPairs(t, b, home_key, home_index, int(n), 0, home_bits, st);
  };
  if (n64 >= (std::uint64_t(1) << 31))
    throw ResourceError("more than 2^31 - 1 bodies on one GPU; use more MPI ranks");
  reserve({{&m_pos, device_in ? 0 : n64 * sizeof(Vec3<double>)},
           {&m_rad, device_in ? 0 : n64 * sizeof(double)},
           {&m_report, device_in || job.bodies.report.empty() ? 0 : n64},
           {&m_spheres, n64 * sizeof(Sphere<Real>)},
           {&m_cell_spheres, n64 * sizeof(Sphere<Real>)},
           {&m_perm, n64 * sizeof(std::uint32_t)},
           {&m_ctrl, n64},
           {&m_keys[0], n64 * sizeof(Key)},
           {&m_keys[1], n64 * sizeof(Key)},
           {&m_bodies[0], n64 * sizeof(std::uint32_t)},
           {&m_bodies[1], n64 * sizeof(std::uint32_t)},
           {&m_body_blocks, body_block_words * sizeof(std::uint32_t)},
           {&m_base, type_passes ? n64 * sizeof(Key) : 0},
           {&m_counters, sizeof(Counters)},
           {&m_temp, std::max(scan_nb_temp, temp_bytes(sort_home))}},
          "pack");
  m_h_counters.reserve(sizeof(Counters));
  CG_CUDA_CHECK(cudaEventRecord(m_events[0], st));
  const double* d_pos;
  const double* d_rad;
  const std::uint8_t* d_report;
  if (device_in) {
    d_pos = job.device_bodies->position;
    d_rad = job.device_bodies->radius;
    d_report = job.device_bodies->report;
  } else {
    // Large input arrays are page-locked in place for the copy (they are already resident, so that
    // only pins them) and unpinned once it is done: a pageable copy is staged by the driver on one
    // thread (2^26 bodies, 2 GB: 0.29 s on the H200 host). A range the driver refuses (e.g. a page
    // shared with an array already registered) is copied pageable. CONTACTGRID_CUDA_UPLOAD=pageable /
    // registered forces one (measurement and test knob).
    const char* up_env = std::getenv("CONTACTGRID_CUDA_UPLOAD");
    const std::size_t lock_from = up_env && std::string_view(up_env) == "registered" ? 1
                                  : up_env && std::string_view(up_env) == "pageable" ? SIZE_MAX
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
      if (bytes > 0) CG_CUDA_CHECK(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyHostToDevice, st));
    };
    upload(m_pos.data(), job.bodies.position.data(), n64 * sizeof(Vec3<double>));
    upload(m_rad.data(), job.bodies.radius.data(), n64 * sizeof(double));
    d_pos = reinterpret_cast<const double*>(m_pos.data());
    d_rad = reinterpret_cast<const double*>(m_rad.data());
    d_report = nullptr;
    if (!job.bodies.report.empty()) {
      upload(m_report.data(), job.bodies.report.data(), n64);
      d_report = reinterpret_cast<const std::uint8_t*>(m_report.data());
    }
    mark(0);
    if (!locked.empty()) {
      CG_CUDA_CHECK(cudaStreamSynchronize(st));  // the copies read the locked ranges until here
      for (void* p : locked) CG_CUDA_CHECK(cudaHostUnregister(p));
    }
  }

  // ---- pack -------------------------------------------------------------------------------------
  Sphere<Real>* d_spheres = m_spheres.span_as<Sphere<Real>>(n).data();            // input order
  Sphere<Real>* d_cell_spheres = m_cell_spheres.span_as<Sphere<Real>>(n).data();  // cell order
  std::uint32_t* d_perm = m_perm.span_as<std::uint32_t>(n).data();  // cell order → input index
  std::uint8_t* d_ctrl = m_ctrl.span_as<std::uint8_t>(n).data();    // cell order
  std::uint32_t* d_body_totals = m_body_blocks.span_as<std::uint32_t>(body_block_words).data();
  std::uint32_t* d_body_offsets = d_body_totals + nb;  // single-sort path
  std::uint32_t* d_type_totals = d_body_totals + nb;   // type-pass path: [8][nb] totals, then offsets
  std::uint32_t* d_type_offsets = d_type_totals + 8 * std::size_t(nb);
  Key* d_base = type_passes ? m_base.span_as<Key>(n).data() : nullptr;
  Counters* d_counters = m_counters.span_as<Counters>(1).data();
  CG_CUDA_CHECK(cudaMemsetAsync(d_counters, 0, sizeof(Counters), st));
  home_key = cub::DoubleBuffer<Key>(m_keys[0].span_as<Key>(n).data(), m_keys[1].span_as<Key>(n).data());
  home_index = cub::DoubleBuffer<std::uint32_t>(m_bodies[0].span_as<std::uint32_t>(n).data(),
                                                m_bodies[1].span_as<std::uint32_t>(n).data());
  cuda::pack_kernel<Real, Key><<<nb, kBlock, 0, st>>>(d_pos, d_rad, n, origin, g, d_spheres, layer_shift,
                                                      home_key.Current(), home_index.Current(), d_counters);
  CG_CUDA_CHECK_LAUNCH("pack");
  // The renumbering pays only when the spheres do not stay in L2 anyway (the pair stage's gathers hit
  // it either way): when they outgrow the L2. CONTACTGRID_CUDA_RENUMBER=0 / 1 forces it off / on
  // (measurement knob). Without it, reorder reads the identity written by pack: the bodies keep their
  // input order (no result changes, see home_layer_key).
  const char* renumber_env = std::getenv("CONTACTGRID_CUDA_RENUMBER");
  const bool renumber = renumber_env && (renumber_env[0] == '0' || renumber_env[0] == '1')
                            ? renumber_env[0] == '1'
                            : n64 * sizeof(Sphere<Real>) > m_l2_bytes;
  if (renumber) run_cub(sort_home);
  cuda::reorder_kernel<Real, Key><<<nb, kBlock, 0, st>>>(
      d_spheres, n, g, home_index.Current(), d_cell_spheres, d_ctrl, d_perm, d_body_totals, d_counters,
      d_base, type_passes ? d_type_totals : nullptr, d_report);
  CG_CUDA_CHECK_LAUNCH("reorder");
  mark(1);
  if (type_passes) {
    run_cub([&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, d_type_totals, d_type_offsets, int(8 * nb), st);
    });
  } else {
    run_cub([&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, d_body_totals, d_body_offsets, int(nb), st);
    });
  }
  auto* h_counters = reinterpret_cast<Counters*>(m_h_counters.data());
  CG_CUDA_CHECK(cudaMemcpyAsync(h_counters, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, st));
  CG_CUDA_CHECK(cudaStreamSynchronize(st));  // host needs the entries total and the status
  if (h_counters->bad) {
    const std::uint64_t i = n64 - h_counters->bad;
    const std::int64_t id = !device_in && !job.bodies.id.empty() ? job.bodies.id[i] : std::int64_t(i);
    throw_bad_body(d_pos, d_rad, i, id);
  }
  const std::uint64_t n_entries = h_counters->entries;
  stats.entries = n_entries;
  if (!type_passes && n_entries >= (std::uint64_t(1) << 31)) {
    std::ostringstream m;
    m << n_entries << " (cell, body) entries exceed the 2^31 - 1 items one CUB sort handles; "
      << "use fewer bodies per rank (more MPI ranks)";
    throw ResourceError(m.str());
  }
  std::uint64_t type_entries[8];
  std::copy(h_counters->type_entries, h_counters->type_entries + 8, type_entries);

  cub::DoubleBuffer<std::uint32_t> pair_a(nullptr, nullptr), pair_b(nullptr, nullptr);
  std::uint32_t np = 0;
  // order: the pairs grouped by a, then each run of equal a sorted by b. Grouped by a counting sort
  // over the bodies (count → scan → scatter; the two dead key buffers of the entry sort hold the
  // counts and the offsets) while those counters stay in half the L2 (2^20 bodies: 0.055 vs 0.076 ms
  // on an H100), else by a radix sort of (a, b) by a (the counters' random atomics in DRAM cost 5×
  // the sort at 2^24: 1.5 vs 0.32 ms).
  // CONTACTGRID_CUDA_ORDER=radix / counting forces one (measurement and test knob).
  const char* order_env = std::getenv("CONTACTGRID_CUDA_ORDER");
  const bool counting_order = order_env && std::string_view(order_env) == "radix" ? false
                              : order_env && std::string_view(order_env) == "counting"
                                  ? true
                                  : n64 * sizeof(std::uint32_t) <= m_l2_bytes / 2;
  const int id_bits = std::max(1, bits_for(n64));
  auto sort_pairs = [&](void* t, std::size_t& b) {
    return cub::DeviceRadixSort::SortPairs(t, b, pair_a, pair_b, int(np), 0, id_bits, st);
  };
  std::uint32_t* d_a_count = nullptr;
  std::uint32_t* d_a_offset = nullptr;
  auto scan_a_counts = [&](void* t, std::size_t& b) {
    return cub::DeviceScan::ExclusiveSum(t, b, d_a_count, d_a_offset, int(n), st);
  };
  auto order_temp = [&] { return counting_order ? temp_bytes(scan_a_counts) : temp_bytes(sort_pairs); };
  auto check_pairs = [&](std::uint64_t n_pairs) {
    if (n_pairs >= (std::uint64_t(1) << 31)) {
      std::ostringstream m;
      m << n_pairs << " contacting pairs exceed the 2^31 - 1 items one CUB sort handles; use more MPI ranks";
      throw ResourceError(m.str());
    }
  };
  const std::size_t v3_unit = sizeof(Vec3<Real>);
  auto out_bytes_for = [&](std::uint64_t pairs) {
    const std::size_t v3 = align16(pairs * v3_unit), ids = align16(pairs * sizeof(std::int64_t)),
                      reals = align16(pairs * sizeof(Real));
    return 2 * ids + 3 * v3 + reals + (full ? 4 * v3 : 0);
  };

  if (!type_passes) {
    const auto ne = static_cast<std::uint32_t>(n_entries);
    const std::uint32_t neb = blocks_for(ne);

    // ---- entries ----------------------------------------------------------------------------------
    cub::DoubleBuffer<Key> keys(nullptr, nullptr);
    cub::DoubleBuffer<std::uint32_t> body(nullptr, nullptr);
    const int key_bits = job.plan.key_bits;
    auto sort_entries = [&](void* t, std::size_t& b) {
      return cub::DeviceRadixSort::SortPairs(t, b, keys, body, int(ne), 0, key_bits, st);
    };
    const std::size_t sort_temp = temp_bytes(sort_entries);
    reserve({{&m_keys[0], ne * sizeof(Key)},
             {&m_keys[1], ne * sizeof(Key)},
             {&m_bodies[0], ne * sizeof(std::uint32_t)},
             {&m_bodies[1], ne * sizeof(std::uint32_t)},
             {&m_entry_blocks, 2 * std::size_t(neb) * sizeof(std::uint32_t)},
             {&m_temp, sort_temp}},
            "entries");
    keys = cub::DoubleBuffer<Key>(m_keys[0].span_as<Key>(ne).data(), m_keys[1].span_as<Key>(ne).data());
    body = cub::DoubleBuffer<std::uint32_t>(m_bodies[0].span_as<std::uint32_t>(ne).data(),
                                            m_bodies[1].span_as<std::uint32_t>(ne).data());
    cuda::fill_entries_kernel<Real, Key>
        <<<nb, kBlock, 0, st>>>(d_cell_spheres, n, g, d_body_offsets, keys.Current(), body.Current());
    CG_CUDA_CHECK_LAUNCH("fill_entries");
    mark(2);

    // ---- sort -------------------------------------------------------------------------------------
    run_cub(sort_entries);
    mark(3);

    // ---- pairs: count -----------------------------------------------------------------------------
    const Key* d_keys = keys.Current();
    const std::uint32_t* d_body = body.Current();
    // The alternate key buffer is dead after the sort: it holds the per-entry contact masks (u32).
    auto* d_pair_count = reinterpret_cast<std::uint32_t*>(keys.Alternate());
    std::uint32_t* d_entry_totals = m_entry_blocks.span_as<std::uint32_t>(2 * neb).data();
    std::uint32_t* d_entry_offsets = d_entry_totals + neb;
    // Direct write of the pairs into the alternate entry-body buffer, dead after the sort: as four u32
    // arrays (a, b, and the sort's second copies) of cap = ne / 4 pairs each.
    const std::uint64_t direct_cap = ne / 4;
    std::uint32_t* d_direct = body.Alternate();
    cuda::count_pairs_kernel<Real, Key><<<neb, kBlock, 0, st>>>(
        d_keys, d_body, ne, d_ctrl, d_cell_spheres, d_perm, d_report, g.half_bits, 0u, d_pair_count,
        d_entry_totals, d_counters, d_direct, d_direct + direct_cap, direct_cap);
    CG_CUDA_CHECK_LAUNCH("count_pairs");
    CG_CUDA_CHECK(cudaMemcpyAsync(h_counters, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, st));
    CG_CUDA_CHECK(cudaStreamSynchronize(st));  // host needs the pairs total
    const std::uint64_t n_pairs = h_counters->pairs;
    stats.pair_tests = h_counters->tests;
    check_pairs(n_pairs);
    np = static_cast<std::uint32_t>(n_pairs);

    // ---- pairs: (scan → fill) ---------------------------------------------------------------------
    // Pairs as (a, b) u32 arrays, double-buffered (16 B a pair). When they fit in the alternate entry
    // body buffer (np <= ne / 4), the count kernel has already written them there; else they are
    // placed in m_pairs by the scan of the block totals → fill_pairs (from the contact masks).
    const bool pairs_in_entries = n_pairs <= direct_cap;
    auto scan_entry_blocks = [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, d_entry_totals, d_entry_offsets, int(neb), st);
    };
    reserve({{&m_pairs, pairs_in_entries ? 0 : 4 * std::size_t(np) * sizeof(std::uint32_t)},
             {&m_out, out_bytes_for(np)},
             {&m_temp, std::max(order_temp(), temp_bytes(scan_entry_blocks))}},
            "pairs");
    const std::size_t stride = pairs_in_entries ? std::size_t(direct_cap) : std::size_t(np);
    std::uint32_t* d_pair_store =
        pairs_in_entries ? d_direct : m_pairs.span_as<std::uint32_t>(4 * std::size_t(np)).data();
    pair_a = cub::DoubleBuffer<std::uint32_t>(d_pair_store, d_pair_store + 2 * stride);
    pair_b = cub::DoubleBuffer<std::uint32_t>(d_pair_store + stride, d_pair_store + 3 * stride);
    if (!pairs_in_entries && np > 0) {
      run_cub(scan_entry_blocks);
      cuda::fill_pairs_kernel<Real, Key>
          <<<neb, kBlock, 0, st>>>(d_keys, d_body, ne, d_ctrl, d_cell_spheres, d_perm, d_report, g.half_bits,
                                   d_pair_count, d_entry_offsets, pair_a.Current(), pair_b.Current());
      CG_CUDA_CHECK_LAUNCH("fill_pairs");
    }
    mark(4);
  } else {
    // ---- type passes: entries, sort, pairs of each cell type in turn ------------------------------
    // Le Grand's 8 passes: each body has at most one entry of a given cell type, so pass t holds
    // n_t <= n entries, keyed by the super-cell index alone (half_bits bits: a radix pass fewer than
    // key_bits where that crosses a digit), in the same four entry buffers as the renumbering sort.
    // Pass t: fill (compaction of the bodies having a type-t cell) → sort → count_pairs with the
    // pass's type (the exactly-once rule unchanged: test_in_cell with type t). All passes write their
    // pairs at the one cursor c->pairs into m_pairs (cap pairs); when the total exceeds cap, m_pairs
    // grows to the total and the passes run again (counters reset), writing them all.
    std::uint32_t n_max = 0;
    std::uint64_t start[8];
    for (std::uint64_t t = 0, s = 0; t < 8; ++t) {
      start[t] = s;  // used modulo 2^32, as the u32 scan of the block totals
      s += type_entries[t];
      n_max = std::max(n_max, static_cast<std::uint32_t>(type_entries[t]));
    }
    const std::uint32_t neb_max = blocks_for(n_max);
    cub::DoubleBuffer<Key> keys(nullptr, nullptr);
    cub::DoubleBuffer<std::uint32_t> body(nullptr, nullptr);
    std::uint32_t n_sort = n_max;
    auto sort_entries = [&](void* t, std::size_t& b) {
      return cub::DeviceRadixSort::SortPairs(t, b, keys, body, int(n_sort), 0, g.half_bits, st);
    };
    std::uint64_t cap = std::max<std::uint64_t>(n64 / 2, m_pairs.bytes() / (4 * sizeof(std::uint32_t)));
    reserve({{&m_entry_blocks, std::size_t(neb_max) * sizeof(std::uint32_t)},
             {&m_pairs, 4 * std::size_t(cap) * sizeof(std::uint32_t)},
             {&m_temp, temp_bytes(sort_entries)}},
            "entries");
    std::uint32_t* d_entry_totals = m_entry_blocks.span_as<std::uint32_t>(neb_max).data();
    const Key step_y = Key(g.half[0]), step_z = Key(g.half[0]) * Key(g.half[1]);
    double pass_ms[3] = {0, 0, 0};  // entries, sort, pairs
    auto run_passes = [&](std::uint32_t* store, std::uint64_t cap_pairs) {
      CG_CUDA_CHECK(cudaEventRecord(m_pass_events[0], st));
      for (std::uint32_t t = 0; t < 8; ++t) {
        const auto nt = static_cast<std::uint32_t>(type_entries[t]);
        cudaEvent_t* ev = m_pass_events + 1 + 3 * t;
        keys = cub::DoubleBuffer<Key>(m_keys[0].span_as<Key>(n).data(), m_keys[1].span_as<Key>(n).data());
        body = cub::DoubleBuffer<std::uint32_t>(m_bodies[0].span_as<std::uint32_t>(n).data(),
                                                m_bodies[1].span_as<std::uint32_t>(n).data());
        if (nt > 0) {
          cuda::fill_type_entries_kernel<Key><<<nb, kBlock, 0, st>>>(
              d_ctrl, d_base, n, t, step_y, step_z, d_type_offsets + std::size_t(t) * nb,
              static_cast<std::uint32_t>(start[t]), keys.Current(), body.Current());
          CG_CUDA_CHECK_LAUNCH("fill_type_entries");
        }
        CG_CUDA_CHECK(cudaEventRecord(ev[0], st));
        if (nt > 1 && g.half_bits > 0) {
          n_sort = nt;
          run_cub(sort_entries);
        }
        CG_CUDA_CHECK(cudaEventRecord(ev[1], st));
        if (nt > 0) {
          cuda::count_pairs_kernel<Real, Key><<<blocks_for(nt), kBlock, 0, st>>>(
              keys.Current(), body.Current(), nt, d_ctrl, d_cell_spheres, d_perm, d_report, g.half_bits, t,
              reinterpret_cast<std::uint32_t*>(keys.Alternate()), d_entry_totals, d_counters, store,
              store + cap_pairs, cap_pairs);
          CG_CUDA_CHECK_LAUNCH("count_pairs");
        }
        CG_CUDA_CHECK(cudaEventRecord(ev[2], st));
      }
      CG_CUDA_CHECK(cudaMemcpyAsync(h_counters, d_counters, sizeof(Counters), cudaMemcpyDeviceToHost, st));
      CG_CUDA_CHECK(cudaStreamSynchronize(st));  // host needs the pairs total
      cudaEvent_t prev = m_pass_events[0];
      for (int t = 0; t < 8; ++t)
        for (int s = 0; s < 3; ++s) {
          float ms = 0;
          CG_CUDA_CHECK(cudaEventElapsedTime(&ms, prev, m_pass_events[1 + 3 * t + s]));
          pass_ms[s] += ms;
          prev = m_pass_events[1 + 3 * t + s];
        }
    };
    std::uint32_t* d_pair_store = m_pairs.span_as<std::uint32_t>(4 * std::size_t(cap)).data();
    run_passes(d_pair_store, cap);
    {
      float ms = 0;  // the scan and the host sync after pack, as in the single-sort path's entries stage
      CG_CUDA_CHECK(cudaEventElapsedTime(&ms, m_events[2], m_pass_events[0]));
      pass_ms[0] += ms;
    }
    if (h_counters->pairs > cap) {
      check_pairs(h_counters->pairs);
      cap = h_counters->pairs;
      reserve({{&m_pairs, 4 * std::size_t(cap) * sizeof(std::uint32_t)}}, "pairs");
      cap = std::max<std::uint64_t>(cap, m_pairs.bytes() / (4 * sizeof(std::uint32_t)));
      d_pair_store = m_pairs.span_as<std::uint32_t>(4 * std::size_t(cap)).data();
      CG_CUDA_CHECK(cudaMemsetAsync(d_counters, 0, sizeof(Counters), st));  // pairs and tests again
      run_passes(d_pair_store, cap);
    }
    const std::uint64_t n_pairs = h_counters->pairs;
    stats.pair_tests = h_counters->tests;
    check_pairs(n_pairs);
    np = static_cast<std::uint32_t>(n_pairs);
    reserve({{&m_out, out_bytes_for(np)}, {&m_temp, order_temp()}}, "pairs");
    pair_a = cub::DoubleBuffer<std::uint32_t>(d_pair_store, d_pair_store + 2 * cap);
    pair_b = cub::DoubleBuffer<std::uint32_t>(d_pair_store + cap, d_pair_store + 3 * cap);
    // Stage times: the passes' fill / sort / count times, summed (marks 2 and 3 only close the chain).
    mark(2);
    mark(3);
    mark(4);
    for (int s = 0; s < 3; ++s) {
      has_override[2 + s] = true;
      override_ms[2 + s] = pass_ms[s];
    }
    override_tail = true;  // + the host sync after the last pass (to mark 4), added to pairs below
  }

  // ---- order ------------------------------------------------------------------------------------
  if (np > 1 && !counting_order) {
    run_cub(sort_pairs);
  } else if (np > 1) {
    d_a_count = m_keys[0].span_as<std::uint32_t>(n).data();  // n <= entries: the buffers hold n u32
    d_a_offset = m_keys[1].span_as<std::uint32_t>(n).data();
    CG_CUDA_CHECK(cudaMemsetAsync(d_a_count, 0, n64 * sizeof(std::uint32_t), st));
    cuda::count_a_kernel<<<blocks_for(np), kBlock, 0, st>>>(pair_a.Current(), np, d_a_count);
    CG_CUDA_CHECK_LAUNCH("count_a");
    run_cub(scan_a_counts);
    cuda::scatter_a_kernel<<<blocks_for(np), kBlock, 0, st>>>(
        pair_a.Current(), pair_b.Current(), np, d_a_offset, pair_a.Alternate(), pair_b.Alternate());
    CG_CUDA_CHECK_LAUNCH("scatter_a");
    pair_a.selector ^= 1;
    pair_b.selector ^= 1;
  }
  if (np > 1) {
    cuda::sort_runs_kernel<<<blocks_for(np), kBlock, 0, st>>>(pair_a.Current(), pair_b.Current(), np);
    CG_CUDA_CHECK_LAUNCH("sort_runs");
  }
  mark(5);

  // ---- narrow -----------------------------------------------------------------------------------
  const std::size_t v3 = align16(np * sizeof(Vec3<Real>));
  const std::size_t ids = align16(np * sizeof(std::int64_t));
  const std::size_t reals = align16(np * sizeof(Real));
  std::byte* o = m_out.data();
  std::size_t at = 0;
  auto take = [&](std::size_t bytes) {
    std::byte* p = o + at;
    at += bytes;
    return p;
  };
  ContactPtrs<Real> cp{};
  cp.id_a = reinterpret_cast<std::int64_t*>(take(ids));
  cp.id_b = reinterpret_cast<std::int64_t*>(take(ids));
  cp.position_on_a = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.position_on_b = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.normal_on_b = reinterpret_cast<Vec3<Real>*>(take(v3));
  cp.distance = reinterpret_cast<Real*>(take(reals));
  if (full) {
    cp.local_point_a = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.local_point_b = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.dir1 = reinterpret_cast<Vec3<Real>*>(take(v3));
    cp.dir2 = reinterpret_cast<Vec3<Real>*>(take(v3));
  }
  if (np > 0) {
    cuda::narrow_kernel<Real><<<blocks_for(np), kBlock, 0, st>>>(pair_a.Current(), pair_b.Current(), np,
                                                                 d_spheres, origin, cp, full);
    CG_CUDA_CHECK_LAUNCH("narrow");
  }
  mark(6);

  // ---- download ---------------------------------------------------------------------------------
  double host_copy_s = 0, host_sizing_s = 0;
  if (job.device_out) {
    DeviceContactsView<Real>& v = *job.device_out;
    v = DeviceContactsView<Real>{};
    v.count = np;
    v.full = full;
    v.id_a = cp.id_a;
    v.id_b = cp.id_b;
    v.position_on_a = cp.position_on_a;
    v.position_on_b = cp.position_on_b;
    v.normal_on_b = cp.normal_on_b;
    v.distance = cp.distance;
    if (full) {
      v.local_point_a = cp.local_point_a;
      v.local_point_b = cp.local_point_b;
      v.lateral_friction_dir1 = cp.dir1;
      v.lateral_friction_dir2 = cp.dir2;
    }
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
  } else {
    // Large results go straight into the result vectors, page-locked in place (cudaHostRegister:
    // that is their first touch); small ones, and any range the driver will not register, through
    // the pinned staging buffer and a parallel host copy. At 2^26 contacts the staged path paid a
    // first touch of the staging buffer and another of the vectors. CONTACTGRID_CUDA_DOWNLOAD=staged /
    // registered forces one (measurement and test knob).
    const char* dl_env = std::getenv("CONTACTGRID_CUDA_DOWNLOAD");
    const bool want_registered = dl_env && std::string_view(dl_env) == "registered" ? true
                                 : dl_env && std::string_view(dl_env) == "staged"
                                     ? false
                                     : at >= (std::size_t(64) << 20);
    bool registered = false;
    if (want_registered && np > 0) {
      const auto t0 = clock_type::now();
      out.resize(np, full);
      std::vector<std::pair<void*, const void*>> fields;  // (host, device)
      std::vector<std::size_t> sizes;
      for_each_field(out, cp, full, [&](auto& vec, const void* d_ptr) {
        fields.push_back({vec.data(), d_ptr});
        sizes.push_back(vec.size() * sizeof(vec[0]));
      });
      // First touch on every host thread: registering faults the pages in on one thread (1.5 GB on
      // the 2×H200 host: touch 0.05 s on 32 threads, then register 0.06 s and copy 0.03 s; the
      // download of 2^26 contacts took 0.36–0.41 s without it).
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
        mark(7);
        CG_CUDA_CHECK(cudaStreamSynchronize(st));
        host_sizing_s = std::chrono::duration<double>(t1 - t0).count();  // registering, before the copy
      } else {
        (void)cudaGetLastError();  // clear the refusal; the staged path below does the download
      }
      const auto t2 = clock_type::now();
      for (std::size_t f = 0; f < locked; ++f) CG_CUDA_CHECK(cudaHostUnregister(fields[f].first));
      host_copy_s = std::chrono::duration<double>(clock_type::now() - t2).count();  // unregistering
    }
    if (!registered) {
      m_h_staging.reserve(std::max<std::size_t>(at, 1));
      if (at > 0) CG_CUDA_CHECK(cudaMemcpyAsync(m_h_staging.data(), o, at, cudaMemcpyDeviceToHost, st));
      mark(7);
      // The result vectors are sized (no fill: HostVector) while the transfer runs.
      const auto t0 = clock_type::now();
      out.resize(np, full);
      CG_CUDA_CHECK(cudaStreamSynchronize(st));
      const auto t1 = clock_type::now();
      const std::byte* h = m_h_staging.data();
      auto from = [&](const void* d_ptr) { return h + (static_cast<const std::byte*>(d_ptr) - o); };
      std::vector<CopyBlock> blocks;
      for_each_field(out, cp, full, [&](auto& vec, const void* d_ptr) {
        if (np) blocks.push_back({vec.data(), from(d_ptr), vec.size() * sizeof(vec[0])});
      });
      parallel_copy(blocks.data(), blocks.size(), 0);  // pinned staging → result vectors, all host threads
      const auto t2 = clock_type::now();
      host_sizing_s = std::chrono::duration<double>(t1 - t0).count();
      host_copy_s = std::chrono::duration<double>(t2 - t1).count();
    }
  }

  // Stage times from the events (all complete: the stream was synchronised above).
  cudaEvent_t prev = m_events[0];
  for (int s = 0; s < kStages; ++s) {
    if (!recorded[s]) continue;
    float ms = 0;
    CG_CUDA_CHECK(cudaEventElapsedTime(&ms, prev, m_events[s + 1]));
    double sec = ms * 1e-3;
    if (has_override[s]) {
      double o = override_ms[s];
      if (s == 4 && override_tail) {
        float tail = 0;
        CG_CUDA_CHECK(cudaEventElapsedTime(&tail, m_pass_events[kPassEvents - 1], m_events[s + 1]));
        o += tail;
      }
      sec = o * 1e-3;
    }
    // Staged: the sizing overlapped the transfer, so the stage is the longer of the two, plus the copy.
    // Registered: the events span registering + transfer (the copies were queued after it), plus
    // the unregistering.
    if (s == 7) sec = std::max(sec, host_sizing_s) + host_copy_s;
    times.push_back({kStageNames[s], sec});
    prev = m_events[s + 1];
  }
  stats.peak_device_bytes = held_bytes();
  stats.device_allocations = m_allocations;
}

std::unique_ptr<CudaBackend> make_cuda_backend(int device) {
  if (!cuda_available()) throw CudaError("no CUDA device is available to this process");
  return std::make_unique<CudaBackend>(device);
}

void destroy(CudaBackend* backend) { delete backend; }

Bounds device_bounds(CudaBackend& backend, const DeviceBodiesView& bodies) { return backend.bounds(bodies); }

void resident_upload(CudaBackend& b, const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  b.reserve({{&b.m_res_pos, n * sizeof(Vec3<double>)},
             {&b.m_res_rad, n * sizeof(double)},
             {&b.m_res_report, bodies.report.empty() ? 0 : n}},
            "resident bodies");
  b.m_res_count = n;
  b.m_res_reported = !bodies.report.empty();
  if (n == 0) return;
  CG_CUDA_CHECK(cudaMemcpyAsync(b.m_res_pos.data(), bodies.position.data(), n * sizeof(Vec3<double>),
                                cudaMemcpyHostToDevice, b.m_stream));
  CG_CUDA_CHECK(cudaMemcpyAsync(b.m_res_rad.data(), bodies.radius.data(), n * sizeof(double),
                                cudaMemcpyHostToDevice, b.m_stream));
  if (!bodies.report.empty())
    CG_CUDA_CHECK(
        cudaMemcpyAsync(b.m_res_report.data(), bodies.report.data(), n, cudaMemcpyHostToDevice, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

template <class Real>
void download_contacts(CudaBackend& b, const DeviceContactsView<Real>& v, Contacts<Real>& out) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  out = Contacts<Real>{};
  out.resize(v.count, v.full);
  if (v.count == 0) return;
  const ContactPtrs<Real> cp{const_cast<std::int64_t*>(v.id_a),
                             const_cast<std::int64_t*>(v.id_b),
                             const_cast<Vec3<Real>*>(v.position_on_a),
                             const_cast<Vec3<Real>*>(v.position_on_b),
                             const_cast<Vec3<Real>*>(v.normal_on_b),
                             const_cast<Real*>(v.distance),
                             const_cast<Vec3<Real>*>(v.local_point_a),
                             const_cast<Vec3<Real>*>(v.local_point_b),
                             const_cast<Vec3<Real>*>(v.lateral_friction_dir1),
                             const_cast<Vec3<Real>*>(v.lateral_friction_dir2)};
  for_each_field(out, cp, v.full, [&](auto& vec, const void* d_ptr) {
    CG_CUDA_CHECK(
        cudaMemcpyAsync(vec.data(), d_ptr, vec.size() * sizeof(vec[0]), cudaMemcpyDeviceToHost, b.m_stream));
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
  v.position = reinterpret_cast<const double*>(b.m_res_pos.data());
  v.radius = reinterpret_cast<const double*>(b.m_res_rad.data());
  v.report = b.m_res_reported ? reinterpret_cast<const std::uint8_t*>(b.m_res_report.data()) : nullptr;
  v.count = b.m_res_count;
  return v;
}

// Rows [first, first + count) of positions and radii between the resident DEVICE arrays and host
// memory (page-locked when the caller pinned it: Engine::pin_host).
void resident_copy(CudaBackend& b, std::size_t first, std::size_t count, Vec3<double>* position,
                   double* radius, bool to_device) {
  CG_CUDA_CHECK(cudaSetDevice(b.m_device));
  auto* d_pos = reinterpret_cast<Vec3<double>*>(b.m_res_pos.data()) + first;
  auto* d_rad = reinterpret_cast<double*>(b.m_res_rad.data()) + first;
  const auto kind = to_device ? cudaMemcpyHostToDevice : cudaMemcpyDeviceToHost;
  CG_CUDA_CHECK(cudaMemcpyAsync(to_device ? static_cast<void*>(d_pos) : position,
                                to_device ? static_cast<const void*>(position) : d_pos,
                                count * sizeof(Vec3<double>), kind, b.m_stream));
  CG_CUDA_CHECK(cudaMemcpyAsync(to_device ? static_cast<void*>(d_rad) : radius,
                                to_device ? static_cast<const void*>(radius) : d_rad, count * sizeof(double),
                                kind, b.m_stream));
  CG_CUDA_CHECK(cudaStreamSynchronize(b.m_stream));
}

template <class Real>
void run_stages(CudaBackend& backend, const DetectJob<Real>& job, Contacts<Real>& out, StageTimes& times,
                EngineStats& stats) {
  if (job.plan.key64)
    backend.run<Real, std::uint64_t>(job, out, times, stats);
  else
    backend.run<Real, std::uint32_t>(job, out, times, stats);
}

template void run_stages(CudaBackend&, const DetectJob<float>&, Contacts<float>&, StageTimes&, EngineStats&);
template void run_stages(CudaBackend&, const DetectJob<double>&, Contacts<double>&, StageTimes&,
                         EngineStats&);

}  // namespace detail
}  // namespace cg
