// The granular dynamics' host side (kernels/dem.hpp): the sequence of a step on either backend
// (host/dem_stages.hpp, cuda/dem_backend.cu), with the engine detecting the contacts in between; the
// setup's damping, time scales and checks are dem_setup.cpp's.
#include "dem.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <string>
#include <type_traits>

#include "core/dem_step.hpp"
#include "dem_backend.hpp"
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
struct Simulation<Real>::Impl {
  DemOptions options;
  double alpha = 0;
  dem::StepConstants constants{};
  Engine<Real> engine;
  Backend resolved = Backend::cpu;
  int threads = 1;
  detail::host::HostDem host;
  std::unique_ptr<detail::CudaDem> cuda;
  // the slots path (dem_slots.hpp; null: the rows path, this file's engine detecting contact rows)
  std::unique_ptr<detail::SlotPath<Real>> slots;
  DemBodies start;  // the bodies as given (shape rows, radii: what the state does not change)
  std::uint64_t steps = 0;
  std::size_t contact_count = 0;
  Contacts<Real> contacts;  // CPU: the last step's; CUDA: downloaded on request
  bool contacts_downloaded = false;
  DeviceContactsView<Real> device_contacts{};
  // CUDA: the device state already holds this step's kick_drift (done by the last step's body stage)
  bool drifted = false;
  // DemOptions::stage_times: on during step(); the sums (DemStageTimes)
  bool timing = false;
  double stage_seconds[detail::kDemStages] = {};
  WallClock::time_point last_mark{};
  DemStageTimes times;
  // one rank's rows of a run over several ranks (dem.hpp): their global ids (empty: row i is body i),
  // the frame of every detection, the CPU's positions when the rows were set (CUDA: CudaDem::mark)
  std::vector<std::int64_t> ids;
  std::optional<Frame> frame;
  std::vector<Vec3<double>> marked;
  // set_halo's rows (the CPU's; CUDA keeps them on the device) and the CPU's records of them
  std::vector<std::uint32_t> halo_send, halo_receive;
  std::vector<std::byte> halo_out, halo_in;
  bool halo_set = false;
  bool halo_spheres = false;  // the halo's records are DemSphereRow (else DemRow)
  // the CPU's edge flags (the halo's rows, sent or received: the overlapped step's first pass)
  std::vector<std::uint8_t> edge;

  static EngineOptions engine_options(EngineOptions e) {
    e.history = true;
    e.fields = Fields::basic;
    return e;
  }
  explicit Impl(const DemOptions& o) : options(o), engine(engine_options(o.engine)) {}

  BodiesView host_view() {
    BodiesView v{host.position, host.radius, ids, {}};
    if (!host.shape.empty()) {
      v.shape = host.shape;
      v.semi_axes = host.semi_axes;
      v.orientation = host.orientation;
    }
    return v;
  }

  // Host contacts carry the rows' ids (BodiesView::id): back to row indices, as the device's are
  // (the rows being in id order, the rows' order stays).
  void local_ids(Contacts<Real>& c) const {
    const std::ptrdiff_t k = static_cast<std::ptrdiff_t>(c.size());
    const std::int64_t* first = ids.data();
    const std::int64_t* last = first + ids.size();
    auto row = [&](std::int64_t id) {
      const std::int64_t* at = std::lower_bound(first, last, id);
      if (at == last || *at != id) throw Error("simulate: a contact's body is not a row: internal error");
      return static_cast<std::int64_t>(at - first);
    };
    bool bad = false;
#pragma omp parallel for num_threads(threads) schedule(static) if (k > 65536) reduction(|| : bad)
    for (std::ptrdiff_t r = 0; r < k; ++r) {
      try {
        c.id_a[r] = row(c.id_a[r]);
        c.id_b[r] = row(c.id_b[r]);
      } catch (const Error&) {
        bad = true;
      }
    }
    if (bad) throw Error("simulate: a contact's body is not a row: internal error");
  }

  // The end of a stage of a timed step (CUDA: an event; CPU: the wall clock).
  void mark(detail::DemStage s) {
    if (!timing) return;
    if (resolved == Backend::cuda) {
      detail::cuda_dem_time_mark(*cuda, s);
      return;
    }
    const WallClock::time_point now = WallClock::now();
    stage_seconds[static_cast<int>(s)] += std::chrono::duration<double>(now - last_mark).count();
    last_mark = now;
  }
  void detected() {
    mark(detail::DemStage::detect);
    if (!timing) return;
    for (const StageTime& t : slots ? slots->times() : engine.times()) {
      auto at = std::find_if(times.detection.begin(), times.detection.end(),
                             [&](const StageTime& x) { return x.name == t.name; });
      if (at == times.detection.end())
        times.detection.push_back(t);
      else
        at->seconds += t.seconds;
    }
  }

  // The contacts at the current positions and the forces from them; CUDA: then `then` (the body
  // stage's pass over the bodies integrates them too).
  void forces(detail::DemThen then = detail::DemThen::nothing) {
    if (slots) {  // the kept candidates' slots: no contact rows (dem_slots.hpp)
      if (resolved == Backend::cuda) {
        slots->cuda_detect(*cuda, engine);
        detected();
        slots->cuda_forces(*cuda, constants, then);
      } else {
        slots->host_detect(host, threads);
        detected();
        slots->host_forces(host, constants, threads);
      }
      mark(detail::DemStage::body_terms);
      contacts_downloaded = false;
      return;
    }
    if (resolved == Backend::cuda) {
      device_contacts = engine.detect_device_resident(detail::cuda_dem_bodies(*cuda), frame);
      detected();
      contact_count = device_contacts.count;
      contacts_downloaded = false;
      detail::cuda_dem_forces(*cuda, device_contacts, constants, then);  // marks its stages
      return;
    }
    contacts = engine.detect(host_view(), frame);
    if (!ids.empty()) local_ids(contacts);
    detected();
    contact_count = contacts.size();
    const dem::ContactRows<Real> rows = host_rows();
    detail::host::dem_contact_forces(host, rows, constants, threads);
    mark(detail::DemStage::contact_terms);
    detail::host::dem_body_forces(host, rows, constants, threads);
    mark(detail::DemStage::body_terms);
  }

  // The CPU's contact rows of the step (contacts, row indices).
  dem::ContactRows<Real> host_rows() const {
    return {contacts.id_a.data(),          contacts.id_b.data(),
            contacts.position_on_a.data(), contacts.position_on_b.data(),
            contacts.normal_on_b.data(),   contacts.distance.data(),
            contacts.previous_row.data(),  contacts.size()};
  }

  // One step; `another`: the next step follows with nothing between (CUDA: this step's body stage
  // also does the next one's kick_drift, one pass over the bodies fewer; the same bits).
  void step(bool another) {
    const double dt = options.dt;
    timing = options.stage_times;
    if (resolved == Backend::cuda) {
      if (timing) detail::cuda_dem_time_start(*cuda);
      if (!drifted) detail::cuda_dem_kick_drift(*cuda, dt);
      mark(detail::DemStage::kick_drift);
      drifted = false;
      forces(another ? detail::DemThen::kick_and_drift : detail::DemThen::kick);  // kick: in body_terms
      drifted = another;
      mark(detail::DemStage::kick);
      if (timing) detail::cuda_dem_time_collect(*cuda, stage_seconds);
    } else {
      last_mark = WallClock::now();
      detail::host::dem_kick_drift(host, dt, threads);
      mark(detail::DemStage::kick_drift);
      forces();
      detail::host::dem_kick(host, dt, threads);
      mark(detail::DemStage::kick);
    }
    if (timing) ++times.steps;
    timing = false;
    ++steps;
  }
};

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

namespace {
// Row i of the CPU's state as a record, and a record into row i.
DemRow host_row(const detail::host::HostDem& h, std::size_t i) {
  return DemRow{h.position[i],    h.velocity[i], h.omega[i], h.momentum[i],
                h.orientation[i], h.force[i],    h.torque[i]};
}
void set_host_row(detail::host::HostDem& h, std::size_t i, const DemRow& r) {
  h.position[i] = r.position;
  h.velocity[i] = r.velocity;
  h.omega[i] = r.omega;
  h.momentum[i] = r.momentum;
  h.orientation[i] = r.orientation;
  h.force[i] = r.force;
  h.torque[i] = r.torque;
}
// Row i as the halo's record at `at` (a sphere's: DemSphereRow), and such a record into row i.
void put_halo_row(const detail::host::HostDem& h, std::size_t i, bool sphere, std::byte* at) {
  if (!sphere) {
    const DemRow r = host_row(h, i);
    std::memcpy(at, &r, sizeof r);
    return;
  }
  const DemSphereRow r{h.position[i], h.velocity[i], h.omega[i], h.force[i], h.torque[i]};
  std::memcpy(at, &r, sizeof r);
}
void take_halo_row(detail::host::HostDem& h, std::size_t i, bool sphere, const std::byte* at) {
  if (!sphere) {
    DemRow r;
    std::memcpy(&r, at, sizeof r);
    set_host_row(h, i, r);
    return;
  }
  DemSphereRow r;
  std::memcpy(&r, at, sizeof r);
  h.position[i] = r.position;
  h.velocity[i] = r.velocity;
  h.omega[i] = r.omega;
  h.force[i] = r.force;
  h.torque[i] = r.torque;
}
}  // namespace

template <class Real>
void Simulation<Real>::read_rows(const std::vector<std::uint32_t>& rows, std::vector<DemRow>& out) {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) return detail::cuda_dem_read_rows(*s.cuda, rows, out);
  const detail::host::HostDem& h = s.host;
  out.resize(rows.size());
  for (std::size_t j = 0; j < rows.size(); ++j) {
    const std::size_t i = rows[j];
    if (i >= h.size()) throw UsageError("simulate: row " + std::to_string(i) + " is not a row of the rank");
    out[j] = host_row(h, i);
  }
}

template <class Real>
void Simulation<Real>::write_rows(const std::vector<std::uint32_t>& rows, const std::vector<DemRow>& in) {
  Impl& s = *m_impl;
  if (in.size() != rows.size())
    throw UsageError("simulate: the rows' records differ in number from the rows");
  if (s.resolved == Backend::cuda) return detail::cuda_dem_write_rows(*s.cuda, rows, in);
  detail::host::HostDem& h = s.host;
  for (std::size_t j = 0; j < rows.size(); ++j) {
    const std::size_t i = rows[j];
    if (i >= h.size()) throw UsageError("simulate: row " + std::to_string(i) + " is not a row of the rank");
    set_host_row(h, i, in[j]);
  }
}

template <class Real>
void Simulation<Real>::set_halo(const std::vector<std::uint32_t>& send,
                                const std::vector<std::uint32_t>& receive, bool full_records) {
  Impl& s = *m_impl;
  s.halo_set = false;
  s.halo_spheres = !full_records && s.start.shape.empty();
  if (s.resolved == Backend::cuda) {
    detail::cuda_dem_set_halo(*s.cuda, send, receive, s.halo_spheres);  // checks the rows
    s.halo_set = true;
    return;
  }
  for (const auto* rows : {&send, &receive})
    for (const std::uint32_t r : *rows)
      if (r >= s.host.size())
        throw UsageError("simulate: row " + std::to_string(r) + " is not a row of the rank");
  s.halo_send = send;
  s.halo_receive = receive;
  s.edge.assign(s.host.size(), 0);
  for (const auto* rows : {&send, &receive})
    for (const std::uint32_t r : *rows) s.edge[r] = 1;
  s.halo_set = true;
  s.halo_out.resize(send.size() * halo_record_bytes());
  s.halo_in.resize(receive.size() * halo_record_bytes());
}

template <class Real>
std::size_t Simulation<Real>::halo_record_bytes() const {
  return m_impl->halo_spheres ? sizeof(DemSphereRow) : sizeof(DemRow);
}

template <class Real>
const std::byte* Simulation<Real>::gather_halo() {
  Impl& s = *m_impl;
  if (!s.halo_set) throw Error("simulate: the halo's rows were not set: internal error");
  if (s.resolved == Backend::cuda) return detail::cuda_dem_gather_halo(*s.cuda);
  const detail::host::HostDem& h = s.host;
  const std::size_t bytes = halo_record_bytes();
  for (std::size_t j = 0; j < s.halo_send.size(); ++j)
    put_halo_row(h, s.halo_send[j], s.halo_spheres, s.halo_out.data() + j * bytes);
  return s.halo_out.data();
}

template <class Real>
std::byte* Simulation<Real>::halo_inbox() {
  Impl& s = *m_impl;
  if (!s.halo_set) throw Error("simulate: the halo's rows were not set: internal error");
  if (s.resolved == Backend::cuda) return detail::cuda_dem_halo_inbox(*s.cuda);
  return s.halo_in.data();
}

template <class Real>
void Simulation<Real>::scatter_halo() {
  Impl& s = *m_impl;
  if (!s.halo_set) throw Error("simulate: the halo's rows were not set: internal error");
  if (s.resolved == Backend::cuda) return detail::cuda_dem_scatter_halo(*s.cuda);
  detail::host::HostDem& h = s.host;
  const std::size_t bytes = halo_record_bytes();
  for (std::size_t j = 0; j < s.halo_receive.size(); ++j)
    take_halo_row(h, s.halo_receive[j], s.halo_spheres, s.halo_in.data() + j * bytes);
}

template <class Real>
bool Simulation<Real>::can_overlap() const {
  const Impl& s = *m_impl;
  if (!s.halo_set || s.slots) return false;
  return s.resolved == Backend::cuda ? detail::cuda_dem_can_overlap(*s.cuda) : true;
}

template <class Real>
const std::byte* Simulation<Real>::finish_step_sending(std::optional<Frame> frame) {
  Impl& s = *m_impl;
  if (!can_overlap()) throw Error("simulate: an overlapped step without its halo: internal error");
  s.frame = frame;
  try {
    if (s.resolved == Backend::cuda) {
      s.device_contacts = s.engine.detect_device_resident(detail::cuda_dem_bodies(*s.cuda), s.frame);
      s.detected();
      s.contact_count = s.device_contacts.count;
      s.contacts_downloaded = false;
      return detail::cuda_dem_forces_sending(*s.cuda, s.device_contacts, s.constants);
    }
    s.contacts = s.engine.detect(s.host_view(), s.frame);
    if (!s.ids.empty()) s.local_ids(s.contacts);
    s.detected();
    s.contact_count = s.contacts.size();
    const dem::ContactRows<Real> rows = s.host_rows();
    detail::host::HostDem& h = s.host;
    detail::host::dem_body_index(h, rows);
    detail::host::dem_contact_forces(h, rows, s.constants, s.threads, dem::Pass::edge, s.edge.data());
    detail::host::dem_body_terms(h, s.constants, s.threads, dem::Pass::edge, s.edge.data(), true);
  } catch (const InputError& e) {
    throw InputError(std::string(e.what()) + " (at step " + std::to_string(s.steps + 1) + ")");
  }
  return gather_halo();
}

template <class Real>
void Simulation<Real>::receive_halo() {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) {
    detail::cuda_dem_receive_halo(*s.cuda);
    s.drifted = true;
    ++s.steps;
    return;
  }
  scatter_halo();
  s.drifted = true;
  const dem::ContactRows<Real> rows = s.host_rows();
  detail::host::HostDem& h = s.host;
  detail::host::dem_contact_forces(h, rows, s.constants, s.threads, dem::Pass::interior, s.edge.data());
  detail::host::dem_body_terms(h, s.constants, s.threads, dem::Pass::interior, s.edge.data(), true);
  ++s.steps;
}

template <class Real>
double Simulation<Real>::interior_seconds() {
  Impl& s = *m_impl;
  return s.resolved == Backend::cuda ? detail::cuda_dem_interior_seconds(*s.cuda) : 0.0;
}

template <class Real>
ResidentExtent Simulation<Real>::extent() {
  Impl& s = *m_impl;
  ResidentExtent e;
  if (s.resolved == Backend::cuda) {
    e.bounds = s.engine.device_bounds(detail::cuda_dem_bodies(*s.cuda));
    e.displacement = detail::cuda_dem_displacement(*s.cuda);
    return e;
  }
  const detail::host::HostDem& h = s.host;
  e.bounds = compute_bounds(BodiesView{h.position, h.radius, s.ids, {}});
  double moved_sq = 0;
  for (std::size_t i = 0; i < h.size(); ++i) {
    const Vec3<double> d = h.position[i] - s.marked[i];
    moved_sq = std::max(moved_sq, dot(d, d));
  }
  e.displacement = std::sqrt(moved_sq);
  return e;
}

template <class Real>
DemState Simulation<Real>::state() {
  Impl& s = *m_impl;
  DemState out;
  out.history = s.engine.history();
  if (s.resolved == Backend::cuda) {
    detail::cuda_dem_get_state(*s.cuda, s.contact_count, out);
  } else {
    const detail::host::HostDem& h = s.host;
    std::vector<std::uint32_t> all(h.size());
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
    read_rows(all, out.rows);
    out.wall_xi = h.wall_xi;
    out.wall_energy = h.wall_energy;
    out.xi = h.xi[h.current];
    out.normal = h.normal[h.current];
    out.contact_energy = h.contact_energy;
  }
  if (out.xi.size() != out.history.size())
    throw Error("simulate: the springs differ in number from the contact history: internal error");
  return out;
}

template <class Real>
void Simulation<Real>::log_terms(const std::vector<std::uint32_t>& rows, std::vector<DemLogRow>& out,
                                 std::vector<double>& contact_energy) {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda)
    return detail::cuda_dem_log_terms(*s.cuda, rows, s.options.gravity, s.contact_count, out, contact_energy);
  detail::host::HostDem& h = s.host;
  const std::size_t n = h.size();
  for (const std::uint32_t r : rows)
    if (r >= n) throw UsageError("simulate: row " + std::to_string(r) + " is not a row of the rank");
  if (h.a_begin.size() != n + 1 || h.contact_energy.size() < s.contact_count)
    throw Error("simulate: the log's terms before the forces of a step: internal error");
  const dem::BodyArrays b = h.arrays();
  out.resize(rows.size());
  const std::ptrdiff_t m = static_cast<std::ptrdiff_t>(rows.size());
#pragma omp parallel for num_threads(s.threads) schedule(static) if (m > 65536)
  for (std::ptrdiff_t j = 0; j < m; ++j) {
    const std::size_t i = rows[std::size_t(j)];
    const dem::BodyEnergy e = dem::body_energy(i, b, s.options.gravity);
    out[std::size_t(j)] = DemLogRow{e.kinetic, e.gravity, h.wall_energy.empty() ? 0.0 : h.wall_energy[i],
                                    h.a_begin[i], h.a_begin[i + 1]};
  }
  contact_energy.assign(h.contact_energy.begin(),
                        h.contact_energy.begin() + static_cast<std::ptrdiff_t>(s.contact_count));
}

template <class Real>
void Simulation<Real>::set_rows(const DemBodies& bodies, std::vector<std::int64_t> ids,
                                const DemState& state) {
  Impl& s = *m_impl;
  const std::size_t n = bodies.size();
  if (ids.size() != n || state.rows.size() != n)
    throw UsageError("simulate: the rows' ids or state differ in number from the bodies");
  s.halo_set = false;  // the rows change: set_halo again
  s.ids = std::move(ids);
  s.start = bodies;
  DemBodies& st = s.start;
  const bool shapes = bodies.has_ellipsoids();
  if (st.velocity.empty()) st.velocity.assign(n, {0, 0, 0});
  if (st.angular_velocity.empty()) st.angular_velocity.assign(n, {0, 0, 0});
  if (!shapes) {
    st.shape.clear();
    st.semi_axes.clear();
    st.orientation.clear();
  }
  const std::vector<dem::BodyProps> props = props_of(st, s.options.material.density);
  s.contact_count = state.xi.size();
  s.contacts = Contacts<Real>{};
  s.contacts_downloaded = false;
  s.engine.set_history(state.history);
  s.engine.rebuild_candidates();  // other rows: the next detection builds its candidates
  if (s.resolved == Backend::cuda) {
    s.cuda = detail::make_cuda_dem(s.options.engine.device, st, props, s.options.walls);
    detail::cuda_dem_set_ids(*s.cuda, s.ids);
    if (s.options.stage_times) detail::cuda_dem_time_enable(*s.cuda);
    detail::cuda_dem_set_state(*s.cuda, state);
    s.drifted = false;
    return;
  }
  s.drifted = false;
  const std::size_t walls = s.options.walls.size();
  if (state.wall_xi.size() != n * walls || state.normal.size() != state.xi.size())
    throw UsageError("simulate: a rank's state differs in size from its rows");
  detail::host::HostDem& h = s.host;
  h.position.resize(n);
  h.velocity.resize(n);
  h.omega.resize(n);
  h.momentum.resize(n);
  h.orientation.resize(n);
  h.force.resize(n);
  h.torque.resize(n);
  for (std::size_t i = 0; i < n; ++i) set_host_row(h, i, state.rows[i]);
  h.radius = st.radius;
  h.props = props;
  h.shape = st.shape;
  h.semi_axes = st.semi_axes;
  h.wall_xi = state.wall_xi;
  h.wall_energy = state.wall_energy;
  if (h.wall_energy.size() != n) h.wall_energy.assign(n, 0);
  h.xi[h.current] = state.xi;
  h.normal[h.current] = state.normal;
  h.contact_energy = state.contact_energy;
  s.marked = h.position;
}

template <class Real>
void Simulation<Real>::mark_rows() {
  Impl& s = *m_impl;
  if (s.resolved == Backend::cuda) return detail::cuda_dem_mark(*s.cuda);
  s.marked = s.host.position;
}

template <class Real>
const std::vector<std::int64_t>& Simulation<Real>::ids() const {
  return m_impl->ids;
}

template class Simulation<float>;
template class Simulation<double>;

}  // namespace cg
