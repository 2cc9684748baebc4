// The CUDA backend of the granular dynamics (kernels/dem_backend.hpp): its state on the device and
// the stages in order, one header each (dem_integrate.cuh, dem_forces.cuh, dem_sums.cuh,
// dem_energy.cuh), over the same core math as the CPU backend (core/dem_step.hpp), so the two agree
// bit for bit. The engine detects between the stages on the bodies' device arrays and leaves its
// contacts there (detect_device_resident); nothing crosses to the host in a step.
#include <algorithm>

#include "cuda/dem_energy.cuh"
#include "cuda/dem_forces.cuh"
#include "cuda/dem_integrate.cuh"
#include "cuda/dem_overlap.cuh"
#include "cuda/dem_rows.cuh"
#include "cuda/dem_state.cuh"
#include "cuda/dem_sums.cuh"
#include "cuda/tuning.hpp"
#include "dem_backend.hpp"

namespace cg::detail {

namespace {
template <class T>
void upload(DemBuffer<T>& d, const std::vector<T>& h) {
  d.reserve(std::max<std::size_t>(h.size(), 1), false);
  if (!h.empty()) CG_CUDA_CHECK(cudaMemcpy(d.data(), h.data(), h.size() * sizeof(T), cudaMemcpyHostToDevice));
}
template <class T>
void download(std::vector<T>& h, const DemBuffer<T>& d, std::size_t n) {
  h.resize(n);
  if (n > 0) CG_CUDA_CHECK(cudaMemcpy(h.data(), d.data(), n * sizeof(T), cudaMemcpyDeviceToHost));
}
}  // namespace

std::unique_ptr<CudaDem> make_cuda_dem(int device, const DemBodies& b,
                                       const std::vector<dem::BodyProps>& props,
                                       const std::vector<dem::Wall>& walls) {
  if (!cuda_available()) throw CudaError("no CUDA device is available to this process");
  auto d = std::make_unique<CudaDem>();
  if (device < 0) CG_CUDA_CHECK(cudaGetDevice(&device));
  d->device = device;
  CG_CUDA_CHECK(cudaSetDevice(device));
  d->sums_by_sort = read_tuning().dem_sums_sort;
  d->a_sums = !read_tuning().dem_terms_rows;
  d->segments_cub = read_tuning().dem_segments_cub;
  d->store_all = read_tuning().dem_store_all;
  d->min_blocks = read_tuning().dem_min_blocks;
  const std::size_t n = b.size();
  d->count = n;
  d->shapes = !b.shape.empty();
  upload(d->position, b.position);
  upload(d->velocity, b.velocity);
  upload(d->omega, b.angular_velocity);
  upload(d->radius, b.radius);
  upload(d->props, props);
  std::vector<Vec3<double>> momentum(n), zero(n, Vec3<double>{0, 0, 0});
  std::vector<Quat<double>> orientation =
      d->shapes ? b.orientation : std::vector<Quat<double>>(n, {1, 0, 0, 0});
  for (std::size_t i = 0; i < n; ++i)  // L = R I Rᵀ ω (as the CPU backend)
    if (d->shapes && b.shape[i] == Shape::ellipsoid) {
      const Mat3<double> r = rotation_matrix(orientation[i]);
      const Vec3<double> l = mul_transpose(r, b.angular_velocity[i]);
      momentum[i] =
          mul(r, Vec3<double>{props[i].inertia.x * l.x, props[i].inertia.y * l.y, props[i].inertia.z * l.z});
    } else {
      momentum[i] = props[i].inertia.x * b.angular_velocity[i];
    }
  upload(d->momentum, momentum);
  upload(d->orientation, orientation);
  upload(d->force, zero);
  upload(d->torque, zero);
  if (d->shapes) {
    upload(d->shape, b.shape);
    upload(d->semi_axes, b.semi_axes);
  } else {
    upload(d->semi_axes, zero);
  }
  upload(d->walls, walls);
  d->wall_count = static_cast<int>(walls.size());
  d->wall_xi.reserve(std::max<std::size_t>(n * walls.size(), 1), false);
  if (n * walls.size() > 0)
    CG_CUDA_CHECK(cudaMemset(d->wall_xi.data(), 0, n * walls.size() * sizeof(Vec3<double>)));
  d->wall_energy.reserve(std::max<std::size_t>(n, 1), false);
  CG_CUDA_CHECK(cudaMemset(d->wall_energy.data(), 0, std::max<std::size_t>(n, 1) * sizeof(double)));
  dem_mark_rows(*d);
  return d;
}

void destroy(CudaDem* d) {
  if (d) cudaSetDevice(d->device);
  delete d;
}

DeviceBodiesView cuda_dem_bodies(CudaDem& d) {
  DeviceBodiesView v;
  v.position = reinterpret_cast<const double*>(d.position.data());
  v.radius = d.radius.data();
  v.count = d.count;
  if (d.has_ids) v.id = d.ids.data();
  if (d.shapes) {
    v.shape = d.shape.data();
    v.semi_axes = reinterpret_cast<const double*>(d.semi_axes.data());
    v.orientation = reinterpret_cast<const double*>(d.orientation.data());
  }
  return v;
}

void cuda_dem_kick_drift(CudaDem& d, double dt) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  dem_kick_drift_stage(d, dt);
}

template <class Real>
void cuda_dem_forces(CudaDem& d, const DeviceContactsView<Real>& contacts, const dem::StepConstants& c,
                     DemThen then) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  const dem::ContactRows<Real> rows = contact_rows(contacts);
  dem_contact_stage(d, rows, c, then != DemThen::kick_and_drift);
  d.events.mark(DemStage::contact_terms);
  dem_body_stage(d, rows, c, then);  // marks body_index and body_terms
}
template void cuda_dem_forces(CudaDem&, const DeviceContactsView<float>&, const dem::StepConstants&, DemThen);
template void cuda_dem_forces(CudaDem&, const DeviceContactsView<double>&, const dem::StepConstants&,
                              DemThen);

DemEnergies cuda_dem_energies(CudaDem& d, std::size_t contacts, Vec3<double> gravity) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  return dem_energy_stage(d, contacts, gravity);
}

void cuda_dem_time_enable(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  d.events.enable();
}
void cuda_dem_time_start(CudaDem& d) { d.events.start(); }
void cuda_dem_time_mark(CudaDem& d, DemStage stage) { d.events.mark(stage); }
void cuda_dem_time_collect(CudaDem& d, double* seconds) { d.events.collect(seconds); }

void cuda_dem_download(CudaDem& d, DemBodies& out) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  CG_CUDA_CHECK(cudaDeviceSynchronize());
  download(out.position, d.position, d.count);
  download(out.velocity, d.velocity, d.count);
  download(out.angular_velocity, d.omega, d.count);
  if (d.shapes) download(out.orientation, d.orientation, d.count);
}

void cuda_dem_set_ids(CudaDem& d, const std::vector<std::int64_t>& ids) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  if (ids.size() != d.count) throw UsageError("simulate: the rows' ids differ in number from the rows");
  upload(d.ids, ids);
  d.has_ids = true;
}

namespace {
void check_rows(const CudaDem& d, const std::vector<std::uint32_t>& rows) {
  for (const std::uint32_t r : rows)
    if (r >= d.count) throw UsageError("simulate: row " + std::to_string(r) + " is not a row of the rank");
}
}  // namespace

void cuda_dem_read_rows(CudaDem& d, const std::vector<std::uint32_t>& rows, std::vector<DemRow>& out) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  check_rows(d, rows);
  dem_gather_rows(d, rows, out);
}

void cuda_dem_write_rows(CudaDem& d, const std::vector<std::uint32_t>& rows, const std::vector<DemRow>& in) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  check_rows(d, rows);
  if (in.size() != rows.size())
    throw UsageError("simulate: the rows' records differ in number from the rows");
  dem_scatter_rows(d, rows, in);
}

void cuda_dem_set_halo(CudaDem& d, const std::vector<std::uint32_t>& send,
                       const std::vector<std::uint32_t>& receive, bool spheres) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  check_rows(d, send);
  check_rows(d, receive);
  dem_set_halo(d, send, receive, spheres);
}

const std::byte* cuda_dem_gather_halo(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  return dem_gather_halo(d);
}

std::byte* cuda_dem_halo_inbox(CudaDem& d) { return d.halo_in.data(); }

void cuda_dem_scatter_halo(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  dem_scatter_halo(d);
}

bool cuda_dem_can_overlap(const CudaDem& d) { return dem_can_overlap(d); }

template <class Real>
const std::byte* cuda_dem_forces_sending(CudaDem& d, const DeviceContactsView<Real>& contacts,
                                         const dem::StepConstants& c) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  return dem_forces_sending(d, contact_rows(contacts), c);
}
template const std::byte* cuda_dem_forces_sending(CudaDem&, const DeviceContactsView<float>&,
                                                  const dem::StepConstants&);
template const std::byte* cuda_dem_forces_sending(CudaDem&, const DeviceContactsView<double>&,
                                                  const dem::StepConstants&);

void cuda_dem_receive_halo(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  dem_receive_halo(d);
}

double cuda_dem_interior_seconds(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  return dem_interior_seconds(d);
}

void cuda_dem_mark(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  dem_mark_rows(d);
}

double cuda_dem_displacement(CudaDem& d) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  return dem_rows_moved(d);
}

void cuda_dem_get_state(CudaDem& d, std::size_t contacts, DemState& out) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  CG_CUDA_CHECK(cudaDeviceSynchronize());
  const std::size_t n = d.count, w = n * std::size_t(d.wall_count);
  std::vector<std::uint32_t> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = static_cast<std::uint32_t>(i);
  dem_gather_rows(d, all, out.rows);
  download(out.wall_xi, d.wall_xi, w);
  download(out.wall_energy, d.wall_energy, n);
  download(out.xi, d.xi[d.current], contacts);
  if (d.normals_f) {
    std::vector<Vec3<float>> f;
    download(f, d.normal_f[d.current], contacts);
    out.normal.resize(contacts);
    for (std::size_t k = 0; k < contacts; ++k) out.normal[k] = vec_cast<double>(f[k]);
  } else {
    download(out.normal, d.normal[d.current], contacts);
  }
  download(out.contact_energy, d.contact_energy, contacts);
}

void cuda_dem_log_terms(CudaDem& d, const std::vector<std::uint32_t>& rows, Vec3<double> gravity,
                        std::size_t contacts, std::vector<DemLogRow>& out,
                        std::vector<double>& contact_energy) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  check_rows(d, rows);
  if (!rows.empty() && (d.a_begin.capacity() < d.count + 1 || d.contact_energy.capacity() < contacts))
    throw Error("simulate: the log's terms before the forces of a step: internal error");
  dem_log_rows(d, rows, gravity, contacts, out, contact_energy);
}

void cuda_dem_set_state(CudaDem& d, const DemState& in) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  const std::size_t n = d.count, k = in.xi.size();
  if (in.rows.size() != n || in.wall_xi.size() != n * std::size_t(d.wall_count) || in.normal.size() != k)
    throw UsageError("simulate: a rank's state differs in size from its rows");
  std::vector<std::uint32_t> all(n);
  for (std::size_t i = 0; i < n; ++i) all[i] = static_cast<std::uint32_t>(i);
  dem_scatter_rows(d, all, in.rows);
  if (!in.wall_xi.empty()) upload(d.wall_xi, in.wall_xi);
  upload(d.xi[d.current], in.xi);
  upload(d.normal[d.current], in.normal);
  std::vector<Vec3<float>> f(k);
  for (std::size_t j = 0; j < k; ++j) f[j] = vec_cast<float>(in.normal[j]);
  upload(d.normal_f[d.current], f);
  dem_mark_rows(d);
}

}  // namespace cg::detail
