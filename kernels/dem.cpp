// The granular dynamics' host side (kernels/dem.hpp): the sequence of a step on either backend
// (host/dem_stages.hpp, cuda/dem_backend.cu), with the engine detecting the contacts in between; the
// setup's damping, time scales and checks are dem_setup.cpp's, one rank's rows of a run over several
// ranks dem_rows.cpp's, the state both share dem_impl.hpp's.
#include "dem.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <string>

#include "core/dem_step.hpp"
#include "dem_backend.hpp"
#include "dem_impl.hpp"
#include "dem_setup.hpp"
#include "dem_slots.hpp"
#include "host/dem_stages.hpp"
#include "timing.hpp"

namespace cg {

#if !defined(CONTACTGRID_HAVE_CUDA)
namespace detail {
class CudaDem {};
std::unique_ptr<CudaDem> make_cuda_dem(int, const DemBodies&, const std::vector<dem::BodyProps>&,
                                       const std::vector<dem::Wall>&) {
  throw CudaError("this contactgrid was built without CUDA (rebuild with nvcc present)");
}
void destroy(CudaDem* d) { delete d; }
DeviceBodiesView cuda_dem_bodies(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_kick_drift(CudaDem&, double) { throw CudaError("this contactgrid was built without CUDA"); }
template <class Real>
void cuda_dem_forces(CudaDem&, const DeviceContactsView<Real>&, const dem::StepConstants&, DemThen) {
  throw CudaError("this contactgrid was built without CUDA");
}
template void cuda_dem_forces(CudaDem&, const DeviceContactsView<float>&, const dem::StepConstants&, DemThen);
template void cuda_dem_forces(CudaDem&, const DeviceContactsView<double>&, const dem::StepConstants&,
                              DemThen);
DemEnergies cuda_dem_energies(CudaDem&, std::size_t, Vec3<double>) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_dem_time_enable(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_time_start(CudaDem&) {}
void cuda_dem_time_mark(CudaDem&, DemStage) {}
void cuda_dem_time_collect(CudaDem&, double*) {}
void cuda_dem_download(CudaDem&, DemBodies&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_set_ids(CudaDem&, const std::vector<std::int64_t>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_dem_read_rows(CudaDem&, const std::vector<std::uint32_t>&, std::vector<DemRow>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_dem_write_rows(CudaDem&, const std::vector<std::uint32_t>&, const std::vector<DemRow>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
bool cuda_dem_can_overlap(const CudaDem&) { return false; }
template <class Real>
const std::byte* cuda_dem_forces_sending(CudaDem&, const DeviceContactsView<Real>&,
                                         const dem::StepConstants&) {
  throw CudaError("this contactgrid was built without CUDA");
}
template const std::byte* cuda_dem_forces_sending(CudaDem&, const DeviceContactsView<float>&,
                                                  const dem::StepConstants&);
template const std::byte* cuda_dem_forces_sending(CudaDem&, const DeviceContactsView<double>&,
                                                  const dem::StepConstants&);
void cuda_dem_receive_halo(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
double cuda_dem_interior_seconds(CudaDem&) { return 0; }
void cuda_dem_mark(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_set_halo(CudaDem&, const std::vector<std::uint32_t>&, const std::vector<std::uint32_t>&, bool) {
  throw CudaError("this contactgrid was built without CUDA");
}
const std::byte* cuda_dem_gather_halo(CudaDem&) {
  throw CudaError("this contactgrid was built without CUDA");
}
std::byte* cuda_dem_halo_inbox(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_scatter_halo(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
double cuda_dem_displacement(CudaDem&) { throw CudaError("this contactgrid was built without CUDA"); }
void cuda_dem_get_state(CudaDem&, std::size_t, DemState&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_dem_set_state(CudaDem&, const DemState&) {
  throw CudaError("this contactgrid was built without CUDA");
}
void cuda_dem_log_terms(CudaDem&, const std::vector<std::uint32_t>&, Vec3<double>, std::size_t,
                        std::vector<DemLogRow>&, std::vector<double>&) {
  throw CudaError("this contactgrid was built without CUDA");
}
}  // namespace detail
#endif

// ---- the simulation --------------------------------------------------------------------------------

template <class Real>
Simulation<Real>::Simulation(const DemBodies& bodies, const DemOptions& options)
    : Simulation(bodies, options, {}, std::nullopt) {}

template <class Real>
Simulation<Real>::Simulation(const DemBodies& bodies, const DemOptions& options,
                             std::vector<std::int64_t> ids, std::optional<Frame> frame)
    : m_impl(std::make_unique<Impl>(options)) {
  Impl& s = *m_impl;
  check_dem_setup(bodies, options);
  if (!ids.empty() && ids.size() != bodies.size())
    throw UsageError("simulate: the rows' ids differ in number from the bodies");
  s.ids = std::move(ids);
  s.frame = frame;
  s.alpha = damping_for_restitution(options.material.restitution);
  s.constants.law = law_of(options.material, s.alpha);
  s.constants.gravity = options.gravity;
  s.constants.walls = options.walls.data();
  s.constants.wall_count = static_cast<int>(options.walls.size());
  s.constants.dt = options.dt;
  s.constants.synchronized = options.synchronized;
  s.resolved = s.engine.backend();
  s.threads = options.engine.threads > 0 ? options.engine.threads : omp_get_max_threads();
  if (detail::slots_path_wanted(bodies, options, !s.ids.empty() || s.frame.has_value()))
    s.slots = std::make_unique<detail::SlotPath<Real>>(s.engine.options());
  s.start = bodies;
  const std::size_t n = bodies.size();
  const bool shapes = bodies.has_ellipsoids();
  DemBodies& st = s.start;
  if (st.velocity.empty()) st.velocity.assign(n, {0, 0, 0});
  if (st.angular_velocity.empty()) st.angular_velocity.assign(n, {0, 0, 0});
  if (!shapes) {  // the sphere-only path: no shape rows
    st.shape.clear();
    st.semi_axes.clear();
    st.orientation.clear();
  }
  const std::vector<dem::BodyProps> props = props_of(st, options.material.density);
  if (s.resolved == Backend::cuda) {
    s.cuda = detail::make_cuda_dem(options.engine.device, st, props, options.walls);
    if (!s.ids.empty()) detail::cuda_dem_set_ids(*s.cuda, s.ids);
    if (options.stage_times) detail::cuda_dem_time_enable(*s.cuda);
  } else {
    detail::host::HostDem& h = s.host;
    h.position = st.position;
    h.velocity = st.velocity;
    h.omega = st.angular_velocity;
    h.radius = st.radius;
    h.props = props;
    h.shape = st.shape;
    h.semi_axes = st.semi_axes;
    h.orientation = shapes ? st.orientation : std::vector<Quat<double>>(n, Quat<double>{1, 0, 0, 0});
    h.momentum.resize(n);
    for (std::size_t i = 0; i < n; ++i)  // L = R I Rᵀ ω
      if (shapes && st.shape[i] == Shape::ellipsoid) {
        const Mat3<double> r = rotation_matrix(h.orientation[i]);
        const Vec3<double> l = mul_transpose(r, h.omega[i]);
        h.momentum[i] = mul(
            r, Vec3<double>{props[i].inertia.x * l.x, props[i].inertia.y * l.y, props[i].inertia.z * l.z});
      } else {
        h.momentum[i] = props[i].inertia.x * h.omega[i];
      }
    h.force.assign(n, {0, 0, 0});
    h.torque.assign(n, {0, 0, 0});
    s.marked = h.position;
  }
  s.forces();  // the forces of the start: the first half kick's
}

template <class Real>
Simulation<Real>::~Simulation() = default;
template <class Real>
Simulation<Real>::Simulation(Simulation&&) noexcept = default;
template <class Real>
Simulation<Real>& Simulation<Real>::operator=(Simulation&&) noexcept = default;

template <class Real>
void Simulation<Real>::run(std::uint64_t steps) {
  for (std::uint64_t k = 0; k < steps; ++k) {
    try {
      m_impl->step(k + 1 < steps);
    } catch (const InputError& e) {  // a body's state stopped being finite: say when
      throw InputError(std::string(e.what()) + " (at step " + std::to_string(m_impl->steps + 1) + ")");
    }
  }
}

template <class Real>
std::uint64_t Simulation<Real>::steps() const {
  return m_impl->steps;
}
template <class Real>
double Simulation<Real>::time() const {
  return double(m_impl->steps) * m_impl->options.dt;
}
template <class Real>
std::size_t Simulation<Real>::contact_count() const {
  if (m_impl->slots) return m_impl->slots->contact_count(m_impl->cuda.get());
  return m_impl->contact_count;
}
template <class Real>
const EngineStats& Simulation<Real>::engine_stats() const {
  if (m_impl->slots) return m_impl->slots->stats();
  return m_impl->engine.stats();
}
template <class Real>
const StageTimes& Simulation<Real>::engine_times() const {
  if (m_impl->slots) return m_impl->slots->times();
  return m_impl->engine.times();
}
template <class Real>
DemStageTimes Simulation<Real>::stage_times() const {
  const Impl& s = *m_impl;
  DemStageTimes t = s.times;
  if (t.steps == 0) return t;
  for (int i = 0; i < detail::kDemStages; ++i)
    t.step.push_back({detail::dem_stage_name(i), s.stage_seconds[i]});
  return t;
}
template <class Real>
Backend Simulation<Real>::backend() const {
  return m_impl->resolved;
}
template <class Real>
double Simulation<Real>::alpha() const {
  return m_impl->alpha;
}

template <class Real>
DemBodies Simulation<Real>::bodies() {
  Impl& s = *m_impl;
  DemBodies out = s.start;
  if (s.resolved == Backend::cuda) {
    detail::cuda_dem_download(*s.cuda, out);
    return out;
  }
  out.position = s.host.position;
  out.velocity = s.host.velocity;
  out.angular_velocity = s.host.omega;
  if (!out.shape.empty()) out.orientation = s.host.orientation;
  return out;
}

template <class Real>
const Contacts<Real>& Simulation<Real>::contacts() {
  Impl& s = *m_impl;
  if (s.slots && !s.contacts_downloaded) {  // rows made from the slots, once a step
    s.contacts = s.slots->contacts(s.resolved == Backend::cuda ? nullptr : &s.host, s.cuda.get());
    s.contacts_downloaded = true;
    return s.contacts;
  }
  if (s.resolved == Backend::cuda && !s.contacts_downloaded) {
    s.contacts = s.engine.download(s.device_contacts);
    s.contacts_downloaded = true;
  }
  return s.contacts;
}

template <class Real>
DemEnergies Simulation<Real>::energies() {
  Impl& s = *m_impl;
  const WallClock::time_point t0 = WallClock::now();
  std::size_t contacts = s.contact_count;
  if (s.slots) {  // the touching slots' energies, in contact order, where the rows path keeps them
    contacts = s.slots->contact_count(s.cuda.get());
    if (s.resolved == Backend::cuda)
      s.slots->cuda_contact_energies(*s.cuda);
    else
      s.slots->contact_energies(s.host);
  }
  const DemEnergies e = s.resolved == Backend::cuda
                            ? detail::cuda_dem_energies(*s.cuda, contacts, s.options.gravity)
                            : detail::host::dem_energies(s.host, contacts, s.options.gravity, s.threads);
  if (s.options.stage_times) {
    s.times.energy_seconds += seconds_since(t0);
    ++s.times.energy_calls;
  }
  return e;
}

// ---- one rank's rows of a run over several ranks ----------------------------------------------------

template <class Real>
void Simulation<Real>::kick_drift() {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) {
    if (!s.drifted) detail::cuda_dem_kick_drift(*s.cuda, s.options.dt);
    s.drifted = true;
    return;
  }
  if (!s.drifted) detail::host::dem_kick_drift(s.host, s.options.dt, s.threads);
  s.drifted = true;
}

template <class Real>
void Simulation<Real>::finish_step(std::optional<Frame> frame) {
  Impl& s = *m_impl;
  s.frame = frame;
  try {
    if (s.resolved == Backend::cuda) {
      s.forces(detail::DemThen::kick);  // kick: in body_terms
      s.drifted = false;
    } else {
      s.forces();
      detail::host::dem_kick(s.host, s.options.dt, s.threads);
      s.drifted = false;
    }
  } catch (const InputError& e) {
    throw InputError(std::string(e.what()) + " (at step " + std::to_string(s.steps + 1) + ")");
  }
  ++s.steps;
}

template class Simulation<float>;
template class Simulation<double>;

}  // namespace cg
