// The engine's host side: backend choice, the plan of each call (grid_plan.hpp), its skin, and the
// mapping of local body indices back to global ids. The engine's state is in engine_impl.hpp, the
// resident bodies' calls in engine_resident.cpp; the stages themselves live in the backends
// (kernels/host/, kernels/cuda/).
#include "engine.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <sstream>
#include <type_traits>
#include <vector>

#include "backend.hpp"
#include "cuda/tuning.hpp"
#include "engine_impl.hpp"
#include "host_vector.hpp"
#include "inflated_bounds.hpp"
#include "resident_rows.hpp"
#include "skin_tuner.hpp"
#include "splice_rows.hpp"
#include "stage.hpp"
#include "stage_names.hpp"
#include "timing.hpp"

namespace cg {

const char* to_string(Backend b) {
  switch (b) {
    case Backend::cpu:
      return "cpu";
    case Backend::cuda:
      return "cuda";
    case Backend::automatic:
      return "auto";
  }
  return "?";
}
const char* to_string(Fields f) { return f == Fields::full ? "full" : "basic"; }

const std::vector<std::string>& engine_stage_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> v;
    for (int i = 0; i < detail::kStageCount; ++i) v.emplace_back(detail::name(detail::stage_at(i)));
    return v;
  }();
  return names;
}

namespace detail {
void parallel_copy(const CopyBlock* blocks, std::size_t count, int threads) {
  std::size_t total = 0;
  for (std::size_t b = 0; b < count; ++b) total += blocks[b].bytes;
  const int nt = total < (std::size_t(1) << 22) ? 1 : (threads > 0 ? threads : omp_get_max_threads());
  // piece t covers bytes [total·t/nt, total·(t+1)/nt) of the blocks laid end to end
#pragma omp parallel for num_threads(nt) schedule(static, 1) if (nt > 1)
  for (int t = 0; t < nt; ++t) {
    std::size_t lo = total * std::size_t(t) / std::size_t(nt),
                hi = total * std::size_t(t + 1) / std::size_t(nt);
    std::size_t at = 0;
    for (std::size_t b = 0; b < count && lo < hi; ++b) {
      const std::size_t end = at + blocks[b].bytes;
      if (lo < end) {
        const std::size_t from = lo - at, to = std::min(hi, end) - at;
        auto* dst = static_cast<std::byte*>(blocks[b].dst);
        if (blocks[b].src) {
          std::memcpy(dst + from, static_cast<const std::byte*>(blocks[b].src) + from, to - from);
        } else {
          for (std::size_t k = from; k < to; k = (k / 4096 + 1) * 4096) dst[k] = std::byte{0};
        }
        lo = at + to;
      }
      at = end;
    }
  }
}

}  // namespace detail

#if !defined(CONTACTGRID_HAVE_CUDA)
bool cuda_available() { return false; }
int cuda_device_count() { return 0; }
namespace detail {
class CudaBackend {};
std::unique_ptr<CudaBackend> make_cuda_backend(int, std::uint64_t, bool) {
  throw CudaError("this contactgrid was built without CUDA (rebuild with nvcc present)");
}
template <class Broad, class Narrow>
void run_stages(CudaBackend&, const DetectJob<Broad, Narrow>&, Contacts<Narrow>&, StageTimes&, EngineStats&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void destroy(CudaBackend* b) { delete b; }
Bounds device_bounds(CudaBackend&, const DeviceBodiesView&, std::size_t&) {
  throw CudaError("this contactgrid was built without CUDA");
}
DeviceBodiesView upload_bodies(CudaBackend&, const BodiesView&) {
  throw CudaError("this contactgrid was built without CUDA");
}
double upload_seconds(CudaBackend&) { throw CudaError("this contactgrid was built without CUDA"); }
void resident_mark(CudaBackend&) { throw CudaError("this contactgrid was built without CUDA"); }
Bounds resident_extent(CudaBackend&, std::span<const std::int64_t>, bool, double&) {
  throw CudaError("this contactgrid was built without CUDA");
}
template <class Real>
void download_contacts(CudaBackend&, const DeviceContactsView<Real>&, Contacts<Real>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
template void download_contacts(CudaBackend&, const DeviceContactsView<float>&, Contacts<float>&);
template void download_contacts(CudaBackend&, const DeviceContactsView<double>&, Contacts<double>&);
bool pin_host(CudaBackend&, void*, std::size_t) {
  throw CudaError("this contactgrid was built without CUDA");
}
void unpin_host(CudaBackend&, void*) { throw CudaError("this contactgrid was built without CUDA"); }
void resident_splice(CudaBackend&, std::span<const std::size_t>, std::span<const std::size_t>,
                     const BodiesView&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void resident_upload(CudaBackend&, const BodiesView&) {
  throw CudaError("this contactgrid was built without CUDA");
}
DeviceBodiesView resident_view(const CudaBackend&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void resident_copy(CudaBackend&, std::size_t, std::size_t, Vec3<double>*, double*, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
void resident_shape_copy(CudaBackend&, std::size_t, std::size_t, Vec3<double>*, Quat<double>*, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
void rows_set_list(CudaBackend&, int, std::span<const std::size_t>) {
  throw CudaError("this contactgrid was built without CUDA");
}
std::span<const std::byte> rows_gather(CudaBackend&, int, std::size_t, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
std::span<std::byte> rows_scatter_buffer(CudaBackend&, std::size_t, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
void rows_scatter(CudaBackend&, int, std::size_t, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
void rows_copy(CudaBackend&, CudaBackend&, int, int, std::size_t, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
std::vector<std::size_t> rows_outside(CudaBackend&, int, double, double) {
  throw CudaError("this contactgrid was built without CUDA");
}
void history_upload(CudaBackend&, const ContactHistory&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void history_download(CudaBackend&, ContactHistory&) {
  throw CudaError("this contactgrid was built without CUDA");
}
}  // namespace detail
#endif

BroadPhase resolved_broad_phase(BroadPhase requested, const Bounds& b, Precision p, Backend backend,
                                bool skin) {
  if (requested != BroadPhase::automatic) return requested;
  if (backend == Backend::automatic) backend = cuda_available() ? Backend::cuda : Backend::cpu;
  return choose_broad_phase(b, p, backend == Backend::cuda, skin);
}

template <class Real>
Engine<Real>::Engine(EngineOptions options) : m_impl(std::make_unique<Impl>()) {
  m_impl->options = options;
  m_impl->host.threads = options.threads;
  if (options.threads < 0) throw UsageError("--threads must be >= 0");
  if (!(options.ellipsoid_tolerance >= 0) || !std::isfinite(options.ellipsoid_tolerance))
    throw UsageError("ellipsoid tolerance must be finite and >= 0 (0: the default)");
  if (options.ellipsoid_max_iterations < 0) throw UsageError("ellipsoid iteration cap must be >= 0");
  if (!(options.skin >= 0) || !std::isfinite(options.skin))
    throw UsageError("skin must be a finite length >= 0 (0: no candidates kept across calls)");
  if (options.fp32_broad_phase && std::is_same_v<Real, float>)
    throw UsageError("fp32_broad_phase (precision mixed) is an option of Engine<double>");
  Backend b = options.backend;
  if (b == Backend::automatic) b = cuda_available() ? Backend::cuda : Backend::cpu;
  if (b == Backend::cuda)
    m_impl->cuda =
        detail::make_cuda_backend(options.device, options.device_memory_limit, options.high_priority)
            .release();
  m_impl->options.backend = b;
  m_impl->resolved = b;
}
template <class Real>
Engine<Real>::~Engine() = default;
template <class Real>
Engine<Real>::Engine(Engine&&) noexcept = default;
template <class Real>
Engine<Real>& Engine<Real>::operator=(Engine&&) noexcept = default;
template <class Real>
Backend Engine<Real>::backend() const {
  return m_impl->resolved;
}
template <class Real>
Precision Engine<Real>::precision() const {
  return m_impl->options.fp32_broad_phase ? Precision::mixed : precision_of<Real>();
}
template <class Real>
const StageTimes& Engine<Real>::times() const {
  return m_impl->times;
}
template <class Real>
const EngineStats& Engine<Real>::stats() const {
  return m_impl->stats;
}
template <class Real>
const EngineOptions& Engine<Real>::options() const {
  return m_impl->options;
}
template <class Real>
void Engine<Real>::reset_history() {
  m_impl->history.clear();
  m_impl->history_on_device = false;
}
template <class Real>
const ContactHistory& Engine<Real>::history() {
  if (m_impl->resolved == Backend::cuda) m_impl->history_to_host();
  return m_impl->history;
}
template <class Real>
void Engine<Real>::set_history(ContactHistory history) {
  if (history.age.size() != history.keys.size())
    throw UsageError("set_history: keys and ages differ in length");
  for (std::size_t j = 1; j < history.keys.size(); ++j)
    if (!(history.keys[j - 1] < history.keys[j]))
      throw UsageError("set_history: keys are not strictly ascending at row " + std::to_string(j));
  m_impl->history = std::move(history);
  m_impl->history_on_device = false;
}

namespace {
// Frame and grid plan of one call from the bodies' bounds; pushes the "plan" stage time. A skin
// (inflation > 0): the origin is the one of a skin-0 call (so the packed spheres and the contacts are
// the same bits), the cell edge and the grid cover the radii inflated by `inflation`.
template <class Broad, class Narrow>
detail::DetectJob<Broad, Narrow> plan_job(const Bounds& b, std::optional<Frame> frame,
                                          const EngineOptions& options, double inflation,
                                          EngineStats& stats) {
  constexpr Precision prec = precision_of<Broad, Narrow>();
  // the levels and auto's choice size themselves by the smallest radius: bounds without it (0) would
  // plan one level, the grid, whatever the radii (every source of bounds carries it)
  if (b.count > 0 && !(b.r_min > 0 && b.r_min <= b.r_max))
    throw Error("internal: the bodies' bounds lack their smallest radius (r_min " + std::to_string(b.r_min) +
                ", r_max " + std::to_string(b.r_max) + ")");
  Frame f = frame ? *frame : make_frame(b, options.cell_size, prec, options.cell_choice);
  if (frame) check_fp32_world(b, prec);
  const double margin = broad_margin(b, f.origin, prec);
  if (frame && f.cell_size < 2 * (b.r_max + margin))
    throw UsageError("frame cell size is smaller than the largest diameter");
  const Bounds grid_bounds = inflation > 0 ? inflated_bounds(b, inflation) : b;
  if (inflation > 0)  // a requested or shared edge grows to the inflated radii' smallest valid edge
    f.cell_size = frame || options.cell_size > 0
                      ? std::max(f.cell_size, min_cell_size(grid_bounds, prec))
                      : make_frame(grid_bounds, 0, prec, options.cell_choice).cell_size;
  detail::DetectJob<Broad, Narrow> job{{}, plan_grid(grid_bounds, f, prec), {}, options.fields};
  job.grid = detail::grid_params<Broad>(job.plan, margin);
  job.broad = resolved_broad_phase(options.broad_phase, b, prec, options.backend, keeps_candidates(options));
  stats.broad_phase = job.broad;
  if (job.broad == BroadPhase::levels) {
    const LevelsPlan levels = plan_levels(b, f, prec, margin + inflation);
    job.levels = level_params<Broad>(levels, margin);
    job.plan.key_bits = levels.key_bits;
    job.plan.key64 = levels.key64;
    stats.levels = levels.count;
  }
  if (job.broad == BroadPhase::sweep) job.sweep_axis = sweep_axis(grid_bounds);
  if (options.ellipsoid_tolerance > 0)
    job.solver.tolerance = static_cast<Narrow>(options.ellipsoid_tolerance);
  if (options.ellipsoid_max_iterations > 0) job.solver.max_iterations = options.ellipsoid_max_iterations;
  job.pair_limits = {options.max_pair_tests, options.on_pair_estimate ? &options.on_pair_estimate : nullptr,
                     options.on_pair_progress ? &options.on_pair_progress : nullptr};
  stats.key_bits = job.plan.key_bits;
  stats.cell_size = f.cell_size;
  return job;
}

// The job of one call in the engine's precision mode (mixed: a float broad phase), handed to `run`.
template <class Real, class Run>
void run_job(const EngineOptions& options, const Bounds& b, std::optional<Frame> frame, double inflation,
             EngineStats& stats, Run&& run) {
  if constexpr (std::is_same_v<Real, double>) {
    if (options.fp32_broad_phase) return run(plan_job<float, double>(b, frame, options, inflation, stats));
  }
  run(plan_job<Real, Real>(b, frame, options, inflation, stats));
}

// A fresh per-call EngineStats that carries the counters kept across calls.
void reset_stats(EngineStats& stats) {
  EngineStats fresh;
  fresh.candidate_builds = stats.candidate_builds;
  fresh.candidate_reuses = stats.candidate_reuses;
  fresh.skin = stats.skin;
  stats = fresh;
}

// EngineOptions::skin of one call (core/skin.hpp): whether it checks the kept list, the coordinate
// bound it is built or checked for, the inflation of a build.
struct SkinPlan {
  double skin = 0, bound = 0, inflation = 0;  // skin: the check's (0: no list kept or checked)
  double next = 0;                            // the skin of a build
  bool check = false;
  template <class Job>
  void apply(Job& job) const {
    job.skin = skin;
    job.inflation = inflation;
    job.check = check;
  }
};
}  // namespace

// The call's skin plan: it checks when the bodies match the kept list's (count, ids, shape presence,
// coordinates within its bound). Marks the kept list invalid until remember_build() (a call that
// throws leaves it unusable). The rounding margin is the broad phase's (mixed: float).
template <class Real>
static SkinPlan plan_skin(typename Engine<Real>::Impl& s, const Bounds& b, std::optional<Frame> frame,
                          std::span<const std::int64_t> id, std::size_t ellipsoids) {
  SkinPlan p;
  p.next = s.options.skin;
  if (!(p.next > 0)) {
    s.kept.valid = false;
    s.stats.skin = 0;
    return p;
  }
  auto& k = s.kept;
  const double now = coordinate_magnitude(b, frame ? frame->origin : b.lo);
  p.check = k.valid && k.count == b.count && std::equal(id.begin(), id.end(), k.id.begin(), k.id.end()) &&
            k.shapes == (ellipsoids > 0) && now <= k.coordinate_bound;
  // a check uses the kept list's skin; a build (now, or after a failed check) the next skin
  p.skin = p.check ? k.skin : p.next;
  p.bound = p.check ? k.coordinate_bound : now + p.next;
  const double eps = s.options.fp32_broad_phase ? double(std::numeric_limits<float>::epsilon())
                                                : double(std::numeric_limits<Real>::epsilon());
  p.inflation = skin_inflation(p.next, p.bound, b.r_max, eps);
  k.valid = false;
  return p;
}

// After a call that ran with a skin: the kept list is what this call used (reused or built).
template <class Real>
static void remember_build(typename Engine<Real>::Impl& s, const Bounds& b, std::span<const std::int64_t> id,
                           std::size_t ellipsoids, const SkinPlan& p, bool reused) {
  if (!(p.skin > 0)) return;
  auto& k = s.kept;
  k.valid = true;
  k.count = b.count;
  k.id.assign(id.begin(), id.end());
  k.shapes = ellipsoids > 0;
  k.coordinate_bound = p.bound;
  if (!reused) k.skin = p.next;
  s.stats.skin = k.skin;
}

// EngineOptions::skin_auto: the tuner's skin for this call's build, and after the call what it saw.
template <class Real>
static void choose_skin(typename Engine<Real>::Impl& s, const Bounds& b) {
  if (!s.options.skin_auto) return;
  s.tuner.set_length(b.r_max);
  s.options.skin = s.tuner.skin();
}
template <class Real>
static void observe_skin(typename Engine<Real>::Impl& s, std::uint64_t builds_before, double seconds) {
  if (!s.options.skin_auto) return;
  const bool built = s.stats.candidate_builds > builds_before || !(s.stats.skin > 0);
  ++s.calls_since_build;
  s.tuner.observe(built, seconds, s.stats.skin_displacement, s.calls_since_build);
  if (built) s.calls_since_build = 0;
}

// Local indices → global ids (monotone, so the (id_a, id_b) order is kept); no ids: nothing.
template <class Real>
static void to_global_ids(Contacts<Real>& out, std::span<const std::int64_t> ids, int threads) {
  if (ids.empty()) return;
  const std::size_t k_n = out.size();
  const std::int64_t* id = ids.data();
  std::int64_t* a = out.id_a.data();
  std::int64_t* b = out.id_b.data();
  const int nt = threads > 0 ? threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) if (k_n > (std::size_t(1) << 15))
  for (std::size_t k = 0; k < k_n; ++k) {
    a[k] = id[static_cast<std::size_t>(a[k])];
    b[k] = id[static_cast<std::size_t>(b[k])];
  }
}

// The host-array path (engine_impl.hpp).
template <class Real>
Contacts<Real> detect_host(typename Engine<Real>::Impl& s, const BodiesView& bodies,
                           std::optional<Frame> frame, std::span<const std::int64_t> history_ids,
                           const Bounds* known) {
  s.forget_resident_view();
  s.times.clear();
  reset_stats(s.stats);
  Contacts<Real> out;
  const auto t0 = WallClock::now();
  const Bounds b = known != nullptr ? *known : compute_bounds(bodies);
  const std::size_t ellipsoids = validate_shapes(bodies);
  s.stats.bodies = b.count;
  s.stats.ellipsoids = ellipsoids;
  if (b.count == 0) {
    if (s.options.history) s.history_end_all(out);
    return out;
  }
  choose_skin<Real>(s, b);
  const std::uint64_t builds = s.stats.candidate_builds, reuses = s.stats.candidate_reuses;
  const SkinPlan skin = plan_skin<Real>(s, b, frame, bodies.id, ellipsoids);
  run_job<Real>(s.options, b, frame, skin.inflation, s.stats, [&](auto job) {
    job.bodies = bodies;
    job.ellipsoids = ellipsoids;
    skin.apply(job);
    s.times.push_back({detail::name(detail::EngineStage::plan), seconds_since(t0)});
    if (s.resolved == Backend::cuda)
      detail::run_stages(*s.cuda, job, out, s.times, s.stats);
    else
      detail::run_stages(s.host, job, out, s.times, s.stats);
  });
  remember_build<Real>(s, b, bodies.id, ellipsoids, skin, s.stats.candidate_reuses > reuses);

  to_global_ids(out, bodies.id, s.options.threads);
  if (s.options.history) {
    const auto t1 = WallClock::now();
    s.history_to_host();
    step_history(out, s.history, history_ids, s.options.threads);
    s.times.push_back({detail::name(detail::EngineStage::history), seconds_since(t1)});
  }
  s.stats.contacts = out.size();
  observe_skin<Real>(s, builds, seconds_since(t0));
  return out;
}

template <class Real>
Contacts<Real> Engine<Real>::detect(const BodiesView& bodies, const Bounds& bounds,
                                    std::optional<Frame> frame) {
  if (bounds.count != bodies.size())
    throw UsageError("detect: bounds of " + std::to_string(bounds.count) + " bodies for " +
                     std::to_string(bodies.size()) + " bodies");
  return detect_host<Real>(*m_impl, bodies, frame, {}, &bounds);
}

// Device-array path: bounds on the device, the same plan, the same CUDA stages. `device_out` set:
// contacts stay on the device; else they are downloaded into `out`.
template <class Real>
static void detect_on_device(typename Engine<Real>::Impl& s, const DeviceBodiesView& bodies,
                             std::optional<Frame> frame, Contacts<Real>& out,
                             DeviceContactsView<Real>* device_out) {
  s.forget_resident_view();
  s.times.clear();
  reset_stats(s.stats);
  if (s.resolved != Backend::cuda) throw UsageError("detect_device needs the CUDA backend");
  if (bodies.count > 0 && (!bodies.position || !bodies.radius))
    throw UsageError("detect_device: null position or radius pointer");
  const auto t0 = WallClock::now();
  if (bodies.count > 0 && bodies.shape && (!bodies.semi_axes || !bodies.orientation))
    throw UsageError("detect_device: shape kinds without semi-axes or orientation pointers");
  std::size_t ellipsoids = 0;
  const Bounds b = detail::device_bounds(*s.cuda, bodies, ellipsoids);
  s.stats.bodies = b.count;
  s.stats.ellipsoids = ellipsoids;
  if (device_out) *device_out = DeviceContactsView<Real>{};
  if (b.count == 0) {
    if (s.options.history) s.history_end_all(out);
    if (device_out) device_out->history = s.options.history;
    return;
  }
  if (s.options.history) s.history_to_device();
  choose_skin<Real>(s, b);
  const std::uint64_t builds = s.stats.candidate_builds, reuses = s.stats.candidate_reuses;
  const SkinPlan skin = plan_skin<Real>(s, b, frame, {}, ellipsoids);
  run_job<Real>(s.options, b, frame, skin.inflation, s.stats, [&](auto job) {
    job.device_bodies = &bodies;
    job.ellipsoids = ellipsoids;
    job.device_out = device_out;
    job.history = s.options.history;
    job.any_row_order = s.rows_any_order && device_out;
    skin.apply(job);
    s.times.push_back({detail::name(detail::EngineStage::plan), seconds_since(t0)});
    detail::run_stages(*s.cuda, job, out, s.times, s.stats);
  });
  remember_build<Real>(s, b, {}, ellipsoids, skin, s.stats.candidate_reuses > reuses);
  s.stats.contacts = device_out ? device_out->count : out.size();
  observe_skin<Real>(s, builds, seconds_since(t0));
}

// The CUDA host-array path of HostPath::device (cuda/tuning.hpp): the bodies go up first and the
// device takes their bounds, as for DEVICE bodies, so that the host reads each input byte once (its
// bounds pass cost as much as the upload). Not with a skin or the contact history (their host
// bookkeeping runs on the host's pass) nor where the caller gives the bounds (detect_host).
template <class Real>
static bool bodies_go_up_first(const typename Engine<Real>::Impl& s, const BodiesView& bodies) {
  return s.resolved == Backend::cuda && bodies.size() > 0 && !(s.options.skin > 0) && !s.options.skin_auto &&
         !s.options.history && detail::host_path() == detail::HostPath::device;
}

template <class Real>
static Contacts<Real> detect_host_on_device(typename Engine<Real>::Impl& s, const BodiesView& bodies,
                                            std::optional<Frame> frame) {
  const std::size_t n = bodies.size();
  const bool sized = bodies.position.size() == n && (bodies.id.empty() || bodies.id.size() == n) &&
                     (bodies.report.empty() || bodies.report.size() == n) &&
                     (bodies.shape.empty() || (bodies.shape.size() == n && bodies.semi_axes.size() == n &&
                                               bodies.orientation.size() == n));
  if (!sized) {  // the host's checks throw their texts
    compute_bounds(bodies);
    validate_shapes(bodies);
    throw InputError("bodies: arrays of different sizes");
  }
  const auto t0 = WallClock::now();
  const DeviceBodiesView device = detail::upload_bodies(*s.cuda, bodies);
  const double queued_s = seconds_since(t0);
  // (while the copy engine moves the last slots)
  if (!bodies.id.empty() && !ids_ascending(bodies.id, s.options.threads)) {
    detail::upload_seconds(*s.cuda);  // the copies (page-locked arrays: from the caller's) are done first
    compute_bounds(bodies);           // names the first bad body
    throw InputError("bodies: ids are not strictly ascending");
  }
  Contacts<Real> out;
  try {
    detect_on_device<Real>(s, device, frame, out, nullptr);
  } catch (const InputError&) {
    compute_bounds(bodies);  // a bad body named by id, as the host's own path names it
    validate_shapes(bodies);
    throw;
  }
  // stage "upload": the copies on the stream; "plan": the rest of the wall time up to the stages
  const double upload_s = detail::upload_seconds(*s.cuda);
  const std::string plan = detail::name(detail::EngineStage::plan);
  for (auto it = s.times.begin(); it != s.times.end(); ++it)
    if (it->name == plan) {
      it->seconds = std::max(0.0, queued_s + it->seconds - upload_s);
      s.times.insert(it + 1, {detail::name(detail::EngineStage::upload), upload_s});
      break;
    }
  if (detail::read_tuning().trace)
    std::fprintf(stderr, "host path: bodies queued in %.3f ms (host), copied in %.3f ms (stream), %s\n",
                 queued_s * 1e3, upload_s * 1e3, bodies.id.empty() ? "no ids" : "ids checked");
  to_global_ids(out, bodies.id, s.options.threads);
  return out;
}

template <class Real>
Contacts<Real> Engine<Real>::detect(const BodiesView& bodies, std::optional<Frame> frame) {
  if (bodies_go_up_first<Real>(*m_impl, bodies)) return detect_host_on_device<Real>(*m_impl, bodies, frame);
  return detect_host<Real>(*m_impl, bodies, frame, {});
}

template <class Real>
Contacts<Real> Engine<Real>::detect_device(const DeviceBodiesView& bodies, std::optional<Frame> frame) {
  Contacts<Real> out;
  detect_on_device<Real>(*m_impl, bodies, frame, out, nullptr);
  return out;
}

template <class Real>
DeviceContactsView<Real> Engine<Real>::detect_device_resident(const DeviceBodiesView& bodies,
                                                              std::optional<Frame> frame) {
  Contacts<Real> unused;
  DeviceContactsView<Real> view;
  detect_on_device<Real>(*m_impl, bodies, frame, unused, &view);
  return view;
}

template <class Real>
Contacts<Real> Engine<Real>::download(const DeviceContactsView<Real>& view) {
  if (m_impl->resolved != Backend::cuda) throw UsageError("download: device contacts need the CUDA backend");
  Contacts<Real> out;
  detail::download_contacts(*m_impl->cuda, view, out);
  return out;
}

template <class Real>
Bounds Engine<Real>::device_bounds(const DeviceBodiesView& bodies, std::size_t* ellipsoids) {
  Impl& s = *m_impl;
  if (s.resolved != Backend::cuda) throw UsageError("device_bounds needs the CUDA backend");
  if (bodies.count > 0 && (!bodies.position || !bodies.radius))
    throw UsageError("device_bounds: null position or radius pointer");
  if (bodies.count > 0 && bodies.shape && (!bodies.semi_axes || !bodies.orientation))
    throw UsageError("device_bounds: shape kinds without semi-axes or orientation pointers");
  std::size_t count = 0;
  const Bounds b = detail::device_bounds(*s.cuda, bodies, count);
  if (ellipsoids) *ellipsoids = count;
  return b;
}

template class Engine<float>;
template class Engine<double>;
template Contacts<float> detect_host<float>(Engine<float>::Impl&, const BodiesView&, std::optional<Frame>,
                                            std::span<const std::int64_t>, const Bounds*);
template Contacts<double> detect_host<double>(Engine<double>::Impl&, const BodiesView&, std::optional<Frame>,
                                              std::span<const std::int64_t>, const Bounds*);

}  // namespace cg
