// The engine's host side: validation and bounds, the shared frame, the grid plan, backend choice,
// and the mapping of local body indices back to global ids. The stages themselves live in the
// backends (kernels/host/, kernels/cuda/).
#include "engine.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <vector>

#include "backend.hpp"
#include "host/huge_pages.hpp"

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
const char* to_string(Precision p) { return p == Precision::fp32 ? "fp32" : "fp64"; }

template <class Real>
void Contacts<Real>::reserve(std::size_t k, bool with_full) {
  id_a.reserve(k);
  id_b.reserve(k);
  position_on_a.reserve(k);
  position_on_b.reserve(k);
  normal_on_b.reserve(k);
  distance.reserve(k);
  if (with_full) {
    local_point_a.reserve(k);
    local_point_b.reserve(k);
    lateral_friction_dir1.reserve(k);
    lateral_friction_dir2.reserve(k);
  }
}

template <class Real>
void Contacts<Real>::resize(std::size_t k, bool with_full) {
  reserve(k, with_full);  // exact: growing by resize alone may over-allocate a non-empty vector
  full = with_full;
  id_a.resize(k);
  id_b.resize(k);
  position_on_a.resize(k);
  position_on_b.resize(k);
  normal_on_b.resize(k);
  distance.resize(k);
  const std::size_t kf = with_full ? k : 0;
  local_point_a.resize(kf);
  local_point_b.resize(kf);
  lateral_friction_dir1.resize(kf);
  lateral_friction_dir2.resize(kf);
}
template struct Contacts<float>;
template struct Contacts<double>;

void Bounds::merge(const Bounds& o) {
  if (o.count == 0) return;
  if (count == 0) {
    *this = o;
    return;
  }
  lo = {std::min(lo.x, o.lo.x), std::min(lo.y, o.lo.y), std::min(lo.z, o.lo.z)};
  hi = {std::max(hi.x, o.hi.x), std::max(hi.y, o.hi.y), std::max(hi.z, o.hi.z)};
  r_max = std::max(r_max, o.r_max);
  count += o.count;
  for (int k = 0; k < 3; ++k) r_sum[k] += o.r_sum[k];
}

Bounds compute_bounds(const BodiesView& bodies) {
  const std::size_t n = bodies.size();
  if (bodies.position.size() != n)
    throw InputError("bodies: " + std::to_string(bodies.position.size()) + " positions but " +
                     std::to_string(n) + " radii");
  if (!bodies.id.empty() && bodies.id.size() != n) throw InputError("bodies: id array has the wrong size");
  if (!bodies.report.empty() && bodies.report.size() != n)
    throw InputError("bodies: report mask has the wrong size");
  Bounds b;
  b.count = n;
  if (n == 0) return b;
  constexpr double inf = std::numeric_limits<double>::infinity();
  b.lo = {inf, inf, inf};
  b.hi = {-inf, -inf, -inf};
  auto id_of = [&](std::size_t i) { return bodies.id.empty() ? std::int64_t(i) : bodies.id[i]; };
  auto bad = [&](std::size_t i) {
    const Vec3<double> p = bodies.position[i];
    const double r = bodies.radius[i];
    return !std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z) || !(r > 0) ||
           !std::isfinite(r) || (i > 0 && !bodies.id.empty() && !(bodies.id[i] > bodies.id[i - 1]));
  };
  // Parallel: per chunk the bounds (min / max are exact, so the fold order does not matter: every
  // lower bound p - r and upper bound p + r of a valid body is a +0 or a non-zero value) and the first
  // bad body; the smallest bad index over the chunks is reported, as a sequential scan would.
  const int threads = n < (std::size_t(1) << 15) ? 1 : omp_get_max_threads();
  std::vector<Bounds> part(static_cast<std::size_t>(threads), b);
  std::vector<std::size_t> first_bad(static_cast<std::size_t>(threads), n);
#pragma omp parallel for num_threads(threads) schedule(static, 1) if (threads > 1)
  for (int t = 0; t < threads; ++t) {
    const std::size_t begin = n * std::size_t(t) / std::size_t(threads),
                      end = n * std::size_t(t + 1) / std::size_t(threads);
    Vec3<double> lo = b.lo, hi = b.hi;
    double r_max = 0, s1 = 0, s2 = 0, s3 = 0;
    for (std::size_t i = begin; i < end; ++i) {
      if (bad(i)) {
        first_bad[static_cast<std::size_t>(t)] = i;
        break;
      }
      const Vec3<double> p = bodies.position[i];
      const double r = bodies.radius[i];
      lo = {std::min(lo.x, p.x - r), std::min(lo.y, p.y - r), std::min(lo.z, p.z - r)};
      hi = {std::max(hi.x, p.x + r), std::max(hi.y, p.y + r), std::max(hi.z, p.z + r)};
      r_max = std::max(r_max, r);
      s1 += r;
      s2 += r * r;
      s3 += r * r * r;
    }
    part[static_cast<std::size_t>(t)].r_sum[0] = s1;
    part[static_cast<std::size_t>(t)].r_sum[1] = s2;
    part[static_cast<std::size_t>(t)].r_sum[2] = s3;
    part[static_cast<std::size_t>(t)].lo = lo;
    part[static_cast<std::size_t>(t)].hi = hi;
    part[static_cast<std::size_t>(t)].r_max = r_max;
  }
  const std::size_t i = *std::min_element(first_bad.begin(), first_bad.end());
  if (i < n) {
    const Vec3<double> p = bodies.position[i];
    const double r = bodies.radius[i];
    if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) {
      std::ostringstream m;
      m << "body " << id_of(i) << ": centre (" << p.x << ", " << p.y << ", " << p.z << ") is not finite";
      throw InputError(m.str());
    }
    if (!(r > 0) || !std::isfinite(r)) {
      std::ostringstream m;
      m << "body " << id_of(i) << ": radius " << r << " is not a finite value > 0";
      throw InputError(m.str());
    }
    throw InputError("bodies: ids are not strictly ascending at index " + std::to_string(i));
  }
  for (const Bounds& q : part) {
    b.lo = {std::min(b.lo.x, q.lo.x), std::min(b.lo.y, q.lo.y), std::min(b.lo.z, q.lo.z)};
    b.hi = {std::max(b.hi.x, q.hi.x), std::max(b.hi.y, q.hi.y), std::max(b.hi.z, q.hi.z)};
    b.r_max = std::max(b.r_max, q.r_max);
    for (int k = 0; k < 3; ++k) b.r_sum[k] += q.r_sum[k];
  }
  return b;
}

namespace {
double real_epsilon(Precision p) {
  return p == Precision::fp32 ? double(std::numeric_limits<float>::epsilon())
                              : std::numeric_limits<double>::epsilon();
}
double max_extent(const Bounds& b) { return std::max({b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z}); }
}  // namespace

double min_cell_size(const Bounds& b, Precision p) {
  // c ± r is computed in Real in the local frame, where |c| <= extent: each of the two bounds and the
  // product by 1/cell carries a few ulps of rounding. 16 ulps of (extent + 2 r_max) covers them all,
  // so a body never spans three cells along an axis.
  const double eps = real_epsilon(p);
  const double d = 2.0 * b.r_max;
  return d * (1.0 + 16 * eps) + 16 * eps * (max_extent(b) + d);
}

double tuned_cell_size(const Bounds& b, Precision p) {
  const double c0 = min_cell_size(b, p);
  if (b.count == 0 || !(b.r_max > 0)) return c0;
  const double n = double(b.count);
  // Mean r, r², r³; bounds without moments (all zero) model every body at r_max.
  double m[3] = {b.r_sum[0] / n, b.r_sum[1] / n, b.r_sum[2] / n};
  if (!(m[0] > 0)) m[0] = b.r_max, m[1] = b.r_max * b.r_max, m[2] = b.r_max * b.r_max * b.r_max;
  const double ext[3] = {b.hi.x - b.lo.x, b.hi.y - b.lo.y, b.hi.z - b.lo.z};
  double best = c0, best_cost = std::numeric_limits<double>::infinity();
  for (int step = 0; step <= 8; ++step) {  // factors 1, 1.25, …, 3: the first minimum wins
    const double c = c0 * (1.0 + 0.25 * step);
    const double u = 2.0 / c;  // E[(1 + u r)³] = 1 + 3u E[r] + 3u² E[r²] + u³ E[r³]
    const double e = 1.0 + 3.0 * u * m[0] + 3.0 * u * u * m[1] + u * u * u * m[2];
    double cells = 1.0;
    for (double x : ext) cells *= std::max(1.0, x / c);
    const double cost = e + kPairWeight * n * e * e / cells;
    if (cost < best_cost) best = c, best_cost = cost;
  }
  return best;
}

Frame make_frame(const Bounds& b, double requested_cell_size, Precision p, CellChoice choice) {
  if (b.count == 0) throw InputError("scene has no bodies");
  Frame f;
  f.origin = b.lo;
  const double need = min_cell_size(b, p);
  if (requested_cell_size == 0) {
    f.cell_size = choice == CellChoice::tuned ? tuned_cell_size(b, p) : need;
  } else {
    if (!(requested_cell_size > 0) || !std::isfinite(requested_cell_size))
      throw UsageError("--cell-size must be a finite value > 0");
    if (requested_cell_size < need) {
      std::ostringstream m;
      m.precision(17);
      m << "--cell-size " << requested_cell_size << " is smaller than the largest bounding diameter "
        << 2 * b.r_max << " plus its rounding margin (" << need << ")";
      throw UsageError(m.str());
    }
    f.cell_size = requested_cell_size;
  }
  return f;
}

GridPlan plan_grid(const Bounds& local, const Frame& frame, Precision p) {
  GridPlan g;
  g.frame = frame;
  if (local.count == 0) return g;
  // Per axis, the frame cell coordinates the local bodies can produce, with one cell of slack for
  // rounding on each side; base rounded down to even so cell parity (type) is the frame's.
  const double lim = p == Precision::fp32 ? double(1u << 22) : double(1u << 31) - 4;
  const double lo[3] = {local.lo.x - frame.origin.x, local.lo.y - frame.origin.y,
                        local.lo.z - frame.origin.z};
  const double hi[3] = {local.hi.x - frame.origin.x, local.hi.y - frame.origin.y,
                        local.hi.z - frame.origin.z};
  for (int k = 0; k < 3; ++k) {
    const double c_hi = std::floor(hi[k] / frame.cell_size) + 1;
    if (!(c_hi < lim)) {
      std::ostringstream m;
      m << "the scene spans " << c_hi << " cells of edge " << frame.cell_size << " along axis "
        << "xyz"[k] << ", more than the " << lim << " that " << to_string(p)
        << " local coordinates resolve; use --precision fp64 or a larger --cell-size";
      throw InputError(m.str());
    }
    double c_lo = std::max(0.0, std::floor(lo[k] / frame.cell_size) - 1);
    auto base = static_cast<std::uint32_t>(c_lo) & ~1u;
    g.base[k] = base;
    g.dims[k] = static_cast<std::uint32_t>(c_hi) - base + 1;
    g.half[k] = (g.dims[k] + 1) / 2;
  }
  const long double cells = (long double)g.half[0] * g.half[1] * g.half[2];
  if (cells > (long double)(std::uint64_t(1) << 60)) {
    std::ostringstream m;
    m << "the grid needs " << double(cells) * 8 << " cells (" << g.dims[0] << " x " << g.dims[1] << " x "
      << g.dims[2] << "), more than a 64-bit cell key encodes; use a larger --cell-size";
    throw InputError(m.str());
  }
  g.half_bits = detail::bits_for(std::uint64_t(g.half[0]) * g.half[1] * g.half[2]);
  g.key_bits = g.half_bits + 3;
  g.key64 = g.key_bits > 32;
  return g;
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
std::unique_ptr<CudaBackend> make_cuda_backend(int) {
  throw CudaError("this contactgrid was built without CUDA (rebuild with nvcc present)");
}
template <class Real>
void run_stages(CudaBackend&, const DetectJob<Real>&, Contacts<Real>&, StageTimes&, EngineStats&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void destroy(CudaBackend* b) { delete b; }
Bounds device_bounds(CudaBackend&, const DeviceBodiesView&) {
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
void resident_upload(CudaBackend&, const BodiesView&) {
  throw CudaError("this contactgrid was built without CUDA");
}
DeviceBodiesView resident_view(const CudaBackend&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void resident_copy(CudaBackend&, std::size_t, std::size_t, Vec3<double>*, double*, bool) {
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
  std::size_t resident_rows = 0;
  Contacts<Real> resident_contacts;
  std::optional<DeviceContactsView<Real>> resident_on_device;  // CUDA: not yet downloaded
  bool resident_overwritten = false;  // CUDA: a later detection reused the workspace first
  void forget_resident_view() {       // before any detection: the view's storage is reused
    if (resident_on_device) resident_overwritten = true;
    resident_on_device.reset();
  }
  ~Impl() { detail::destroy(cuda); }
};

template <class Real>
Engine<Real>::Engine(EngineOptions options) : m_impl(std::make_unique<Impl>()) {
  m_impl->options = options;
  m_impl->host.threads = options.threads;
  if (options.threads < 0) throw UsageError("--threads must be >= 0");
  Backend b = options.backend;
  if (b == Backend::automatic) b = cuda_available() ? Backend::cuda : Backend::cpu;
  if (b == Backend::cuda) m_impl->cuda = detail::make_cuda_backend(options.device).release();
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

namespace {
// Frame and grid plan of one call from the bodies' bounds; pushes the "plan" stage time.
template <class Real>
detail::DetectJob<Real> plan_job(const Bounds& b, std::optional<Frame> frame, const EngineOptions& options,
                                 EngineStats& stats) {
  constexpr Precision prec = sizeof(Real) == 4 ? Precision::fp32 : Precision::fp64;
  const Frame f = frame ? *frame : make_frame(b, options.cell_size, prec, options.cell_choice);
  if (frame && f.cell_size < 2 * b.r_max)
    throw UsageError("frame cell size is smaller than the largest diameter");
  detail::DetectJob<Real> job{{}, plan_grid(b, f, prec), {}, options.fields};
  job.grid = detail::grid_params<Real>(job.plan);
  stats.key_bits = job.plan.key_bits;
  stats.cell_size = f.cell_size;
  return job;
}
}  // namespace

template <class Real>
Contacts<Real> Engine<Real>::detect(const BodiesView& bodies, std::optional<Frame> frame) {
  using clock = std::chrono::steady_clock;
  Impl& s = *m_impl;
  s.forget_resident_view();
  s.times.clear();
  s.stats = EngineStats{};
  Contacts<Real> out;
  auto t0 = clock::now();
  const Bounds b = compute_bounds(bodies);
  s.stats.bodies = b.count;
  if (b.count == 0) return out;
  detail::DetectJob<Real> job = plan_job<Real>(b, frame, s.options, s.stats);
  job.bodies = bodies;
  s.times.push_back({"plan", std::chrono::duration<double>(clock::now() - t0).count()});

  if (s.resolved == Backend::cuda)
    detail::run_stages(*s.cuda, job, out, s.times, s.stats);
  else
    detail::run_stages(s.host, job, out, s.times, s.stats);

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
  s.stats.contacts = out.size();
  return out;
}

// Device-array path: bounds on the device, the same plan, the same CUDA stages. `device_out` set:
// contacts stay on the device; else they are downloaded into `out`.
template <class Real>
static void detect_on_device(typename Engine<Real>::Impl& s, const DeviceBodiesView& bodies,
                             std::optional<Frame> frame, Contacts<Real>& out,
                             DeviceContactsView<Real>* device_out) {
  using clock = std::chrono::steady_clock;
  s.forget_resident_view();
  s.times.clear();
  s.stats = EngineStats{};
  if (s.resolved != Backend::cuda) throw UsageError("detect_device needs the CUDA backend");
  if (bodies.count > 0 && (!bodies.position || !bodies.radius))
    throw UsageError("detect_device: null position or radius pointer");
  auto t0 = clock::now();
  const Bounds b = detail::device_bounds(*s.cuda, bodies);
  s.stats.bodies = b.count;
  if (b.count == 0) return;
  detail::DetectJob<Real> job = plan_job<Real>(b, frame, s.options, s.stats);
  job.device_bodies = &bodies;
  job.device_out = device_out;
  s.times.push_back({"plan", std::chrono::duration<double>(clock::now() - t0).count()});
  detail::run_stages(*s.cuda, job, out, s.times, s.stats);
  s.stats.contacts = device_out ? device_out->count : out.size();
}

template <class Real>
void Engine<Real>::set_resident(const BodiesView& b) {
  Impl& s = *m_impl;
  if (!b.id.empty()) throw UsageError("set_resident: ids are implied (row i is body i)");
  if (b.position.size() != b.size() || (!b.report.empty() && b.report.size() != b.size()))
    throw UsageError("set_resident: the arrays differ in length");
  s.resident_rows = b.size();
  s.resident_contacts = Contacts<Real>{};
  s.resident_on_device.reset();
  s.resident_overwritten = false;
  if (s.resolved == Backend::cuda) {
    detail::resident_upload(*s.cuda, b);
    return;
  }
  s.resident_position.assign(b.position.begin(), b.position.end());
  s.resident_radius.assign(b.radius.begin(), b.radius.end());
  s.resident_report.assign(b.report.begin(), b.report.end());
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
std::size_t Engine<Real>::detect_resident(std::optional<Frame> frame) {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) {
    const DeviceBodiesView v = detail::resident_view(*s.cuda);
    s.resident_contacts = Contacts<Real>{};
    const DeviceContactsView<Real> view = detect_device_resident(v, frame);
    s.resident_on_device = view;
    s.resident_overwritten = false;
    return view.count;
  }
  const std::size_t n = s.resident_rows;
  s.resident_contacts = detect(BodiesView{{s.resident_position.data(), n},
                                          {s.resident_radius.data(), n},
                                          {},
                                          {s.resident_report.data(), s.resident_report.size()}},
                               frame);
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

template class Engine<float>;
template class Engine<double>;

}  // namespace cg
