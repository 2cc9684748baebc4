// One rank's rows of a granular run over several ranks (kernels/dem.hpp): the rows' records read and
// written, the halo's rows gathered and scattered, the overlapped step, the extent, state and log
// terms of the rows, and the rows set at a layout; the step's sequence is dem.cpp's.
#include <cstring>
#include <string>

#include "dem_impl.hpp"
#include "dem_setup.hpp"

namespace cg {

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
