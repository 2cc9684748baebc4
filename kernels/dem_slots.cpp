// The granular dynamics' slots path: the sequence of a step (kernels/dem_slots.hpp), the engine's
// skin decision repeated with the engine's values, and the candidate list's builds.
#include "dem_slots.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <type_traits>

#include "core/skin.hpp"
#include "grid_plan.hpp"
#include "host/dem_slots.hpp"
#include "inflated_bounds.hpp"

namespace cg::detail {

bool slots_path_wanted(const DemBodies& bodies, const DemOptions& options, bool ranked) {
  // opt-in: on an H100 the slots path is as fast as the rows path at 2^20 spheres and 18 % slower
  // at 2^24 (each pair's terms computed twice, over the skin's candidates; BENCHMARKS.md §28)
  const char* knob = std::getenv("CONTACTGRID_DEM_PATH");
  if (knob == nullptr || *knob == 0 || std::strcmp(knob, "rows") == 0) return false;
  if (std::strcmp(knob, "slots") != 0)
    throw UsageError(std::string("CONTACTGRID_DEM_PATH must be rows or slots, not ") + knob);
  return !ranked && !bodies.has_ellipsoids() && options.engine.skin > 0 && !options.engine.skin_auto;
}

namespace {
EngineOptions candidate_options(EngineOptions e) {
  e.skin = 0;
  e.skin_auto = false;
  e.history = false;
  e.fields = Fields::basic;
  return e;
}
}  // namespace

template <class Real>
SlotPath<Real>::SlotPath(const EngineOptions& engine)
    : m_options(engine),
      m_candidates(candidate_options(engine)),
      m_host(std::make_unique<host::HostSlots>()) {
  m_stats.skin = 0;
}

template <class Real>
SlotPath<Real>::~SlotPath() = default;

template <class Real>
double SlotPath<Real>::inflation(const Bounds& b) const {
  const double eps = m_options.fp32_broad_phase ? double(std::numeric_limits<float>::epsilon())
                                                : double(std::numeric_limits<Real>::epsilon());
  return skin_inflation(m_options.skin, m_bound, b.r_max, eps);
}

template <class Real>
NarrowBodies<Real> SlotPath<Real>::world(const double* position, const double* radius) const {
  return NarrowBodies<Real>{nullptr, position, radius, m_origin};
}

template <class Real>
bool SlotPath<Real>::must_build(const Bounds& b, double displacement) {
  m_origin = b.lo;  // the frame of a call without one (make_frame)
  const double now = coordinate_magnitude(b, m_origin);
  const bool check = m_valid && now <= m_bound;
  Motion m;
  m.displacement = displacement;
  m_stats.skin_displacement = check ? displacement : 0;
  if (check && skin_covers(m, m_skin)) {
    ++m_stats.candidate_reuses;
    return false;
  }
  // a build after a check keeps the checked bound (the engine's plan_skin: p.bound), else now + skin
  if (!check) m_bound = now + m_options.skin;
  m_skin = m_options.skin;
  m_stats.skin = m_skin;
  m_valid = true;
  ++m_stats.candidate_builds;
  return true;
}

template <class Real>
void SlotPath<Real>::host_detect(host::HostDem& h, int threads) {
  const WallClock::time_point t0 = WallClock::now();
  const std::size_t n = h.size();
  const Bounds b = compute_bounds(BodiesView{h.position, h.radius, {}, {}});
  double moved_sq = 0;
  if (m_valid && m_ref.size() == n) {
    const std::ptrdiff_t nn = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for num_threads(threads) schedule(static) reduction(max : moved_sq) if (n > 32768)
    for (std::ptrdiff_t i = 0; i < nn; ++i) {
      const Vec3<double> d = h.position[std::size_t(i)] - m_ref[std::size_t(i)];
      moved_sq = std::max(moved_sq, d.x * d.x + d.y * d.y + d.z * d.z);  // the engine's order (host/skin.cpp)
    }
  }
  const bool build = must_build(b, std::sqrt(moved_sq));
  plan_cell_size(b);
  m_host->remapped = false;
  const WallClock::time_point t1 = WallClock::now();
  if (build) {
    const double d = inflation(b);
    m_inflated.resize(n);
    for (std::size_t i = 0; i < n; ++i) m_inflated[i] = h.radius[i] + d;
    const Contacts<Real> pairs = m_candidates.detect(BodiesView{h.position, m_inflated, {}, {}});
    const std::size_t m = pairs.size();
    std::vector<std::uint32_t> a(m), bb(m);
    for (std::size_t k = 0; k < m; ++k) {
      a[k] = static_cast<std::uint32_t>(pairs.id_a[k]);
      bb[k] = static_cast<std::uint32_t>(pairs.id_b[k]);
    }
    host::slots_rebuild(*m_host, std::move(a), std::move(bb), n, threads);
    m_ref = h.position;
  }
  m_count.reset();
  timed(t0, t1, build);
}

template <class Real>
void SlotPath<Real>::host_forces(host::HostDem& h, const dem::StepConstants& c, int threads) {
  host::slots_forces(h, *m_host, world(reinterpret_cast<const double*>(h.position.data()), h.radius.data()),
                     c, threads);
}

template <class Real>
void SlotPath<Real>::contact_energies(host::HostDem& h) {
  host::slots_contact_energies(h, *m_host);
}

// The cell edge the rows path's engine reports for a call on these bounds (its plan_job: the frame of
// the spheres inflated for the skin), for EngineStats::cell_size (a contact file records it).
template <class Real>
void SlotPath<Real>::plan_cell_size(const Bounds& b) {
  if (b.count == 0) return;
  const Precision prec =
      m_options.fp32_broad_phase && std::is_same_v<Real, double> ? Precision::mixed : precision_of<Real>();
  const Bounds grid = inflated_bounds(b, inflation(b));
  m_stats.cell_size =
      m_options.cell_size > 0
          ? std::max(make_frame(b, m_options.cell_size, prec, m_options.cell_choice).cell_size,
                     min_cell_size(grid, prec))
          : make_frame(grid, 0, prec, m_options.cell_choice).cell_size;
}

template <class Real>
Contacts<Real> SlotPath<Real>::contacts(const host::HostDem* h, CudaDem* d) {
  if (d) return cuda_slots_contacts<Real>(*d, *m_cuda);
  return host::slots_contacts(*m_host,
                              world(reinterpret_cast<const double*>(h->position.data()), h->radius.data()));
}

template <class Real>
void SlotPath<Real>::timed(WallClock::time_point t0, WallClock::time_point t1, bool build) {
  const WallClock::time_point t2 = WallClock::now();
  m_times = {{"skin", std::chrono::duration<double>(t1 - t0).count()},
             {"candidates", build ? std::chrono::duration<double>(t2 - t1).count() : 0.0}};
}

template <class Real>
void SlotPath<Real>::cuda_detect(CudaDem& d, Engine<Real>& main) {
  const WallClock::time_point t0 = WallClock::now();
  if (!m_cuda) m_cuda = make_cuda_slots();
  const DeviceBodiesView v = cuda_dem_bodies(d);
  const Bounds b = main.device_bounds(v);
  // the displacement only where the engine would check it (a pass and a read back)
  const bool check = m_valid && coordinate_magnitude(b, b.lo) <= m_bound;
  const bool build = must_build(b, check ? cuda_dem_displacement(d) : 0.0);
  plan_cell_size(b);
  cuda_slots_step_begins(*m_cuda);
  const WallClock::time_point t1 = WallClock::now();
  if (build) {
    const DeviceBodiesView inflated = cuda_slots_inflate(d, *m_cuda, inflation(b));
    const DeviceContactsView<Real> pairs = m_candidates.detect_device_resident(inflated);
    cuda_slots_rebuild(d, *m_cuda, pairs);
    cuda_dem_mark(d);  // the positions of the build (cuda_dem_displacement's reference)
  }
  m_count.reset();
  timed(t0, t1, build);
}

template <class Real>
void SlotPath<Real>::cuda_forces(CudaDem& d, const dem::StepConstants& c, DemThen then) {
  const DeviceBodiesView v = cuda_dem_bodies(d);
  cuda_slots_forces(d, *m_cuda, world(v.position, v.radius), c, then);
}

template <class Real>
void SlotPath<Real>::cuda_contact_energies(CudaDem& d) {
  cuda_slots_contact_energies(d, *m_cuda, contact_count_of(&d));
}

template <class Real>
std::size_t SlotPath<Real>::contact_count_of(CudaDem* d) const {
  if (!m_count) m_count = m_cuda ? cuda_slots_contact_count(*d, *m_cuda) : host::slots_contact_count(*m_host);
  return *m_count;
}

#if !defined(CONTACTGRID_HAVE_CUDA)
class CudaSlots {};
std::unique_ptr<CudaSlots> make_cuda_slots() { throw CudaError("this contactgrid was built without CUDA"); }
void destroy(CudaSlots* s) { delete s; }
DeviceBodiesView cuda_slots_inflate(CudaDem&, CudaSlots&, double) {
  throw CudaError("this contactgrid was built without CUDA");
}
template <class Real>
void cuda_slots_rebuild(CudaDem&, CudaSlots&, const DeviceContactsView<Real>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_slots_step_begins(CudaSlots&) {}
template <class Real>
void cuda_slots_forces(CudaDem&, CudaSlots&, const NarrowBodies<Real>&, dem::StepConstants, DemThen) {
  throw CudaError("this contactgrid was built without CUDA");
}
std::size_t cuda_slots_contact_count(CudaDem&, CudaSlots&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_slots_contact_energies(CudaDem&, CudaSlots&, std::size_t) {
  throw CudaError("this contactgrid was built without CUDA");
}
template <class Real>
Contacts<Real> cuda_slots_contacts(CudaDem&, CudaSlots&) {
  throw CudaError("this contactgrid was built without CUDA");
}
#endif

template class SlotPath<float>;
template class SlotPath<double>;

}  // namespace cg::detail
