// The engine's host side: backend choice, the plan of each call (grid_plan.hpp), and the mapping of
// local body indices back to global ids. The stages themselves live in the
// backends (kernels/host/, kernels/cuda/).
#include "engine.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <type_traits>
#include <vector>

#include "backend.hpp"
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
std::unique_ptr<CudaBackend> make_cuda_backend(int, std::uint64_t) {
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

template <class Real>
struct Engine<Real>::Impl {
  EngineOptions options;
  Backend resolved = Backend::cpu;
  detail::HostBackend host;
  detail::CudaBackend* cuda = nullptr;
  StageTimes times;
  EngineStats stats;
  // resident bodies of the CPU backend (CUDA keeps them in the backend) and their last contacts
  HostVector<Vec3<double>> resident_position;
  HostVector<double> resident_radius;
  HostVector<std::uint8_t> resident_report;
  HostVector<Shape> resident_shape;  // shape rows (empty: all spheres)
  HostVector<Vec3<double>> resident_semi_axes;
  HostVector<Quat<double>> resident_orientation;
  HostVector<std::int64_t> resident_id;  // the rows' global ids (history keys); empty: row indices
  std::size_t resident_rows = 0;
  bool resident_shapes = false;                       // set_resident had shape rows (either backend)
  bool resident_marked = false;                       // mark_resident since the rows were set
  HostVector<Vec3<double>> resident_marked_position;  // CPU: the centres at the mark (CUDA: on the device)
  Contacts<Real> resident_contacts;
  std::optional<DeviceContactsView<Real>> resident_on_device;  // CUDA: not yet downloaded
  bool resident_overwritten = false;  // CUDA: a later detection reused the workspace first
  bool rows_any_order = false;        // CUDA: detect_resident's call (DetectJob::any_row_order)
  // set_row_list's lists: their lengths (both backends; set: since the rows were set), the CPU
  // backend's rows and packed-row buffers (CUDA keeps them in the backend)
  std::array<std::size_t, kRowLists> row_list_size{};
  std::array<bool, kRowLists> row_list_set{};
  std::array<std::vector<std::size_t>, kRowLists> row_list;
  HostVector<std::byte> row_gathered, row_scattered;
  std::size_t scattered_rows = 0;
  bool scattered_orientations = false;
  // EngineOptions::skin > 0: what the kept candidate list was built for (the backend keeps the list
  // and the bodies' state); a call that matches it checks the motion, any other call rebuilds.
  struct KeptFor {
    bool valid = false;
    std::size_t count = 0;
    std::vector<std::int64_t> id;  // the bodies' ids (empty: implied, as for device bodies)
    bool shapes = false;           // the scene had ellipsoids
    double coordinate_bound = 0;   // core/skin.hpp: a later call's coordinates must stay within
    double skin = 0;               // the skin it was built with (its check's)
  } kept;
  // EngineOptions::skin_auto: the tuner, and the calls since the last build (this one included)
  SkinTuner tuner;
  int calls_since_build = 0;
  void forget_resident_view() {  // before any detection: the view's storage is reused
    if (resident_on_device) resident_overwritten = true;
    resident_on_device.reset();
  }
  // EngineOptions::history: the previous call's keys and ages, on the host (`history`) or in the
  // CUDA backend's device history (after a device-path call); moved where the next call needs them.
  ContactHistory history;
  bool history_on_device = false;
  void history_to_host() {
    if (history_on_device) detail::history_download(*cuda, history);
    history_on_device = false;
  }
  void history_to_device() {
    if (!history_on_device) detail::history_upload(*cuda, history);
    history_on_device = true;
  }
  // A call without bodies: no contacts, so every pair of the previous call has ended.
  void history_end_all(Contacts<Real>& out) {
    history.clear();
    history_on_device = false;
    out.history = true;
  }
  ~Impl() { detail::destroy(cuda); }
};

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
    m_impl->cuda = detail::make_cuda_backend(options.device, options.device_memory_limit).release();
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

// The host-array path. `history_ids`: the keys of the contact history (EngineOptions::history) when
// the contacts' ids are row indices (resident bodies with ids); empty: the contacts' ids.
// `known`: compute_bounds(bodies), when the caller has it.
template <class Real>
static Contacts<Real> detect_host(typename Engine<Real>::Impl& s, const BodiesView& bodies,
                                  std::optional<Frame> frame, std::span<const std::int64_t> history_ids,
                                  const Bounds* known = nullptr) {
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

  // Local indices → global ids (monotone, so the (id_a, id_b) order is kept).
  if (!bodies.id.empty()) {
    const std::size_t k_n = out.size();
    const std::int64_t* id = bodies.id.data();
    std::int64_t* a = out.id_a.data();
    std::int64_t* b2 = out.id_b.data();
    const int nt = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) if (k_n > (std::size_t(1) << 15))
    for (std::size_t k = 0; k < k_n; ++k) {
      a[k] = id[static_cast<std::size_t>(a[k])];
      b2[k] = id[static_cast<std::size_t>(b2[k])];
    }
  }
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
Contacts<Real> Engine<Real>::detect(const BodiesView& bodies, std::optional<Frame> frame) {
  return detect_host<Real>(*m_impl, bodies, frame, {});
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

namespace {
// UsageError naming `what` unless every array of `b` given has `rows` rows (position always; report and
// id when given; the three shape arrays together or none).
void check_resident_lengths(const BodiesView& b, std::size_t rows, const char* what) {
  const std::size_t m = b.size();
  const bool shapes = !b.shape.empty();
  if (b.position.size() != m || rows != m || (!b.report.empty() && b.report.size() != m) ||
      (!b.id.empty() && b.id.size() != m) ||
      (shapes && (b.shape.size() != m || b.semi_axes.size() != m || b.orientation.size() != m)) ||
      (!shapes && (!b.semi_axes.empty() || !b.orientation.empty())))
    throw UsageError(std::string(what) + ": the arrays differ in length");
}

// The resident rows are now `rows` other rows: what was known of the former ones is dropped (the
// rebuild check's mark, the kept candidates — the next detection builds —, the contacts kept).
template <class Impl>
void rows_changed(Impl& s, std::size_t rows) {
  s.resident_rows = rows;
  s.resident_marked = false;
  s.kept.valid = false;
  s.resident_contacts = {};
  s.resident_on_device.reset();
  s.resident_overwritten = false;
  s.row_list_set.fill(false);
}
}  // namespace

template <class Real>
void Engine<Real>::set_resident(const BodiesView& b) {
  Impl& s = *m_impl;
  const bool shapes = !b.shape.empty();
  check_resident_lengths(b, b.size(), "set_resident");
  for (std::size_t i = 1; i < b.id.size(); ++i)
    if (!(b.id[i] > b.id[i - 1]))
      throw InputError("set_resident: ids are not strictly ascending at row " + std::to_string(i));
  s.resident_shapes = shapes;
  rows_changed(s, b.size());
  if (s.resolved == Backend::cuda) {
    detail::resident_upload(*s.cuda, b);
    return;
  }
  s.resident_position.assign(b.position.begin(), b.position.end());
  s.resident_radius.assign(b.radius.begin(), b.radius.end());
  s.resident_report.assign(b.report.begin(), b.report.end());
  s.resident_shape.assign(b.shape.begin(), b.shape.end());
  s.resident_semi_axes.assign(b.semi_axes.begin(), b.semi_axes.end());
  s.resident_orientation.assign(b.orientation.begin(), b.orientation.end());
  s.resident_id.assign(b.id.begin(), b.id.end());
}

namespace {
// `v`'s rows spliced by `plan` with `arrivals` (stride elements a row), through a pooled array.
template <class T>
void splice_host_rows(HostVector<T>& v, const SplicePlan& plan, std::span<const T> arrivals,
                      std::size_t stride, int threads) {
  HostVector<T> into(plan.size * stride);
  splice_rows(plan, v.data(), arrivals.data(), into.data(), stride, threads);
  v.swap(into);
}
}  // namespace

template <class Real>
void Engine<Real>::splice_resident(std::span<const std::size_t> leaving, std::span<const std::size_t> at,
                                   const BodiesView& b) {
  Impl& s = *m_impl;
  const std::size_t m = b.size();
  const bool shapes = !b.shape.empty();
  check_resident_lengths(b, at.size(), "splice_resident");
  if (s.resident_rows == 0) {  // nothing stays: the arrivals are the rows, whatever fields they carry
    plan_splice(0, leaving, at, "splice_resident");
    set_resident(b);
    return;
  }
  const bool ided =
      s.resolved == Backend::cuda ? detail::resident_view(*s.cuda).id != nullptr : !s.resident_id.empty();
  const bool reported = s.resolved == Backend::cuda ? detail::resident_view(*s.cuda).report != nullptr
                                                    : !s.resident_report.empty();
  if (m > 0 && (shapes != s.resident_shapes || b.id.empty() == ided || b.report.empty() == reported))
    throw UsageError("splice_resident: the arrivals' fields (ids, report, shape rows) differ from the rows'");
  const SplicePlan plan = plan_splice(s.resident_rows, leaving, at, "splice_resident");
  rows_changed(s, plan.size);
  if (s.resolved == Backend::cuda) {
    detail::resident_splice(*s.cuda, leaving, at, b);
    return;
  }
  const int threads = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
  splice_host_rows(s.resident_position, plan, b.position, 1, threads);
  splice_host_rows(s.resident_radius, plan, b.radius, 1, threads);
  if (reported) splice_host_rows(s.resident_report, plan, b.report, 1, threads);
  if (ided) splice_host_rows(s.resident_id, plan, b.id, 1, threads);
  if (s.resident_shapes) {
    splice_host_rows(s.resident_shape, plan, b.shape, 1, threads);
    splice_host_rows(s.resident_semi_axes, plan, b.semi_axes, 1, threads);
    splice_host_rows(s.resident_orientation, plan, b.orientation, 1, threads);
  }
}

template <class Real>
void Engine<Real>::mark_resident() {
  Impl& s = *m_impl;
  s.resident_marked = true;
  if (s.resolved == Backend::cuda) {
    detail::resident_mark(*s.cuda);
    return;
  }
  const std::size_t n = s.resident_rows;
  s.resident_marked_position.resize(n);
  const Vec3<double>* x = s.resident_position.data();
  Vec3<double>* to = s.resident_marked_position.data();
  const int nt = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) if (n > (std::size_t(1) << 15))
  for (std::size_t k = 0; k < n; ++k) to[k] = x[k];
}

template <class Real>
ResidentExtent Engine<Real>::resident_extent(std::span<const std::int64_t> ids) {
  Impl& s = *m_impl;
  const std::size_t n = s.resident_rows;
  if (!ids.empty() && ids.size() != n)
    throw UsageError("resident_extent: " + std::to_string(ids.size()) + " ids for " + std::to_string(n) +
                     " resident rows");
  ResidentExtent e;
  if (s.resolved == Backend::cuda) {
    e.bounds = detail::resident_extent(*s.cuda, ids, s.resident_marked, e.displacement);
    return e;
  }
  e.bounds =
      compute_bounds(BodiesView{{s.resident_position.data(), n}, {s.resident_radius.data(), n}, ids, {}});
  if (!s.resident_marked) return e;
  // the largest squared distance (exact: the max of values rounded alike on both backends), then its root
  double moved_sq = 0;
  const Vec3<double>* x = s.resident_position.data();
  const Vec3<double>* x0 = s.resident_marked_position.data();
  const int nt = s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
#pragma omp parallel for num_threads(nt) schedule(static) \
    reduction(max                                         \
              : moved_sq) if (n > (std::size_t(1) << 15))
  for (std::size_t k = 0; k < n; ++k) {
    const Vec3<double> d = x[k] - x0[k];
    moved_sq = std::max(moved_sq, d.x * d.x + d.y * d.y + d.z * d.z);
  }
  e.displacement = std::sqrt(moved_sq);
  return e;
}

template <class Real>
void Engine<Real>::set_skin(double skin) {
  if (!(skin >= 0) || !std::isfinite(skin))
    throw UsageError("skin must be a finite length >= 0 (0: no candidates kept across calls)");
  m_impl->options.skin = skin;
  m_impl->options.skin_auto = false;
}

template <class Real>
void Engine<Real>::rebuild_candidates() {
  m_impl->kept.valid = false;
}

template <class Real>
std::size_t Engine<Real>::resident_size() const {
  return m_impl->resident_rows;
}

namespace {
void check_rows(std::size_t first, std::size_t count, std::size_t rows, const char* what) {
  if (first > rows || count > rows - first)
    throw UsageError(std::string(what) + ": rows " + std::to_string(first) + " + " + std::to_string(count) +
                     " are outside the " + std::to_string(rows) + " resident rows");
}
}  // namespace

template <class Real>
void Engine<Real>::read_resident(std::size_t first, std::size_t count, Vec3<double>* position,
                                 double* radius) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "read_resident");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_copy(*s.cuda, first, count, position, radius, false);
    return;
  }
  std::copy_n(s.resident_position.data() + first, count, position);
  std::copy_n(s.resident_radius.data() + first, count, radius);
}

template <class Real>
void Engine<Real>::write_resident(std::size_t first, std::size_t count, const Vec3<double>* position,
                                  const double* radius) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "write_resident");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_copy(*s.cuda, first, count, const_cast<Vec3<double>*>(position),
                          const_cast<double*>(radius), true);
    return;
  }
  std::copy_n(position, count, s.resident_position.data() + first);
  std::copy_n(radius, count, s.resident_radius.data() + first);
}

template <class Real>
void Engine<Real>::read_resident_shapes(std::size_t first, std::size_t count, Vec3<double>* semi_axes,
                                        Quat<double>* orientation) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "read_resident_shapes");
  if (!s.resident_shapes) throw UsageError("read_resident_shapes: the resident bodies have no shape rows");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_shape_copy(*s.cuda, first, count, semi_axes, orientation, false);
    return;
  }
  if (semi_axes) std::copy_n(s.resident_semi_axes.data() + first, count, semi_axes);
  if (orientation) std::copy_n(s.resident_orientation.data() + first, count, orientation);
}

template <class Real>
void Engine<Real>::write_resident_shapes(std::size_t first, std::size_t count, const Vec3<double>* semi_axes,
                                         const Quat<double>* orientation) {
  Impl& s = *m_impl;
  check_rows(first, count, s.resident_rows, "write_resident_shapes");
  if (!s.resident_shapes) throw UsageError("write_resident_shapes: the resident bodies have no shape rows");
  if (count == 0) return;
  if (s.resolved == Backend::cuda) {
    detail::resident_shape_copy(*s.cuda, first, count, const_cast<Vec3<double>*>(semi_axes),
                                const_cast<Quat<double>*>(orientation), true);
    return;
  }
  if (semi_axes) std::copy_n(semi_axes, count, s.resident_semi_axes.data() + first);
  if (orientation) std::copy_n(orientation, count, s.resident_orientation.data() + first);
}

template <class Real>
std::size_t Engine<Real>::detect_resident(std::optional<Frame> frame) {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) {
    const DeviceBodiesView v = detail::resident_view(*s.cuda);
    s.resident_contacts = Contacts<Real>{};
    // the rows come to the caller through resident_contacts() alone: their device order is free
    s.rows_any_order = true;
    struct AnyOrder {
      bool& flag;
      ~AnyOrder() { flag = false; }
    } any_order{s.rows_any_order};
    const DeviceContactsView<Real> view = detect_device_resident(v, frame);
    s.resident_on_device = view;
    s.resident_overwritten = false;
    return view.count;
  }
  const std::size_t n = s.resident_rows;
  s.resident_contacts = detect_host<Real>(s,
                                          BodiesView{{s.resident_position.data(), n},
                                                     {s.resident_radius.data(), n},
                                                     {},
                                                     {s.resident_report.data(), s.resident_report.size()},
                                                     s.resident_shape,
                                                     s.resident_semi_axes,
                                                     s.resident_orientation},
                                          frame, s.resident_id);
  return s.resident_contacts.size();
}

template <class Real>
const Contacts<Real>& Engine<Real>::resident_contacts() {
  Impl& s = *m_impl;
  if (s.resident_overwritten)
    throw UsageError(
        "resident_contacts: another detection reused the device workspace since detect_resident");
  if (s.resident_on_device) {  // CUDA: downloaded on the first request after the detection
    detail::download_contacts(*s.cuda, *s.resident_on_device, s.resident_contacts);
    s.resident_on_device.reset();
  }
  return s.resident_contacts;
}

template <class Real>
bool Engine<Real>::pin_host(void* p, std::size_t bytes) {
  return m_impl->resolved == Backend::cuda && p && bytes > 0 && detail::pin_host(*m_impl->cuda, p, bytes);
}

template <class Real>
void Engine<Real>::unpin_host(void* p) {
  if (m_impl->resolved == Backend::cuda && p) detail::unpin_host(*m_impl->cuda, p);
}

namespace {
template <class Impl>
int host_threads(const Impl& s) {
  return s.options.threads > 0 ? s.options.threads : omp_get_max_threads();
}
template <class Impl>
detail::RowArrays host_rows(Impl& s) {
  return {s.resident_position.data(), s.resident_radius.data(),
          s.resident_orientation.empty() ? nullptr : s.resident_orientation.data()};
}
// The length of list `list`, set since the rows were set; orientations of listed rows need shape rows.
template <class Impl>
std::size_t listed_rows(const Impl& s, int list, bool orientations, const char* what) {
  if (list < 0 || list >= static_cast<int>(s.row_list_set.size()))
    throw UsageError(std::string(what) + ": no row list " + std::to_string(list));
  if (!s.row_list_set[static_cast<std::size_t>(list)])
    throw UsageError(std::string(what) + ": row list " + std::to_string(list) +
                     " was not set for these rows");
  const std::size_t m = s.row_list_size[static_cast<std::size_t>(list)];
  if (orientations && !s.resident_shapes && m > 0)  // (a rank without rows has none to orient)
    throw UsageError(std::string(what) + ": orientations of rows set without shape rows");
  return m;
}
}  // namespace

template <class Real>
void Engine<Real>::set_row_list(int list, std::span<const std::size_t> rows) {
  Impl& s = *m_impl;
  if (list < 0 || list >= kRowLists) throw UsageError("set_row_list: no row list " + std::to_string(list));
  for (const std::size_t row : rows)
    if (row >= s.resident_rows)
      throw UsageError("set_row_list: row " + std::to_string(row) + " is outside the " +
                       std::to_string(s.resident_rows) + " resident rows");
  const auto l = static_cast<std::size_t>(list);
  if (s.resolved == Backend::cuda)
    detail::rows_set_list(*s.cuda, list, rows);
  else
    s.row_list[l].assign(rows.begin(), rows.end());
  s.row_list_size[l] = rows.size();
  s.row_list_set[l] = true;
}

template <class Real>
std::span<const std::byte> Engine<Real>::gather_rows(int list, bool orientations) {
  Impl& s = *m_impl;
  const std::size_t m = listed_rows(s, list, orientations, "gather_rows");
  if (s.resolved == Backend::cuda) return detail::rows_gather(*s.cuda, list, m, orientations);
  s.row_gathered.resize(m * packed_row_bytes(orientations));
  detail::pack_rows(host_rows(s), s.row_list[static_cast<std::size_t>(list)], orientations,
                    s.row_gathered.data(), host_threads(s));
  return {s.row_gathered.data(), s.row_gathered.size()};
}

template <class Real>
std::span<std::byte> Engine<Real>::scatter_buffer(std::size_t count, bool orientations) {
  Impl& s = *m_impl;
  s.scattered_rows = count;
  s.scattered_orientations = orientations;
  if (s.resolved == Backend::cuda) return detail::rows_scatter_buffer(*s.cuda, count, orientations);
  s.row_scattered.resize(count * packed_row_bytes(orientations));
  return {s.row_scattered.data(), s.row_scattered.size()};
}

template <class Real>
void Engine<Real>::scatter_rows(int list, bool orientations) {
  Impl& s = *m_impl;
  const std::size_t m = listed_rows(s, list, orientations, "scatter_rows");
  if (m > s.scattered_rows || orientations != s.scattered_orientations)
    throw UsageError("scatter_rows: the scatter buffer holds " + std::to_string(s.scattered_rows) +
                     " rows of another layout than the list's " + std::to_string(m));
  if (s.resolved == Backend::cuda) {
    detail::rows_scatter(*s.cuda, list, m, orientations);
    return;
  }
  detail::unpack_rows(s.row_scattered.data(), s.row_list[static_cast<std::size_t>(list)], orientations,
                      host_rows(s), host_threads(s));
}

template <class Real>
void Engine<Real>::copy_rows(Engine& from, int from_list, int to_list, bool orientations) {
  Impl& s = *m_impl;
  Impl& f = *from.m_impl;
  const std::size_t m = listed_rows(s, to_list, orientations, "copy_rows");
  if (listed_rows(f, from_list, orientations, "copy_rows") != m)
    throw UsageError("copy_rows: lists of " +
                     std::to_string(f.row_list_size[static_cast<std::size_t>(from_list)]) + " and " +
                     std::to_string(m) + " rows");
  if (s.resolved != f.resolved) throw UsageError("copy_rows: the engines run on other backends");
  if (s.resolved == Backend::cuda) {
    detail::rows_copy(*s.cuda, *f.cuda, from_list, to_list, m, orientations);
    return;
  }
  detail::copy_rows(host_rows(f), f.row_list[static_cast<std::size_t>(from_list)], host_rows(s),
                    s.row_list[static_cast<std::size_t>(to_list)], orientations, host_threads(s));
}

template <class Real>
std::vector<std::size_t> Engine<Real>::rows_outside(int axis, double lo, double hi) {
  Impl& s = *m_impl;
  if (axis < 0 || axis > 2)
    throw UsageError("rows_outside: axis " + std::to_string(axis) + " is not 0, 1 or 2");
  if (s.resolved == Backend::cuda) return detail::rows_outside(*s.cuda, axis, lo, hi);
  return detail::rows_outside(s.resident_position.data(), s.resident_rows, axis, lo, hi, host_threads(s));
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

}  // namespace cg
