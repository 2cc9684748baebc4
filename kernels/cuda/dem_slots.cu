// The CUDA backend of the granular dynamics' slots path (kernels/dem_slots.hpp; the per-item
// functions are core/dem_slots.hpp, as the CPU backend's, host/dem_slots.cpp, so the two agree bit
// for bit): the slots' state on the device, a rebuild (the candidate engine's device contacts as the
// list, remap_slot per new slot, each body's index by a stable radix sort of the slots by b and
// Thrust's vectorised lower_bound), and the step (slot_body_terms, one thread per body, into the
// second force buffer; then each body's kick, and the next step's kick_drift: DemThen). Every kernel
// on the legacy default stream, as the rest of the backend (cuda/dem_state.cuh).
#include <thrust/binary_search.h>
#include <thrust/copy.h>
#include <thrust/count.h>
#include <thrust/execution_policy.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>
#include <thrust/scan.h>
#include <thrust/transform_scan.h>

#include <cub/device/device_radix_sort.cuh>
#include <utility>

#include "backend.hpp"
#include "core/dem_slots.hpp"
#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"
#include "dem_backend.hpp"
#include "host/dem_slots.hpp"

namespace cg::detail {

class CudaSlots {
 public:
  std::size_t count = 0;  // slots
  DemBuffer<std::uint32_t> a, b, old_a, old_b, a_begin, b_begin, by_b[2], keys[2];
  DemBuffer<Vec3<double>> xi[2], normal[2], force_next, torque_next;
  DemBuffer<std::int32_t> age[2];
  DemBuffer<double> energy, inflated;
  DemBuffer<std::int64_t> rank, prev_row;
  DemBuffer<std::byte> temp;
  int cur = 0;            // [cur]: the last step's state
  bool remapped = false;  // prev_row holds the last step's previous rows (a rebuild's step)
};

}  // namespace cg::detail

namespace cg::cuda {

struct Touching {
  __host__ __device__ bool operator()(std::int32_t age) const { return age >= 0; }
};
struct TouchFlag {
  __host__ __device__ std::int64_t operator()(std::int32_t age) const { return age >= 0 ? 1 : 0; }
};

__global__ void slots_inflate_kernel(const double* radius, std::size_t n, double d, double* out) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i < n) out[i] = radius[i] + d;
}

// The candidate engine's rows as the list's pairs, and the keys and values of the sort by b.
__global__ void slots_pairs_kernel(const std::int64_t* id_a, const std::int64_t* id_b, std::size_t m,
                                   std::uint32_t* a, std::uint32_t* b, std::uint32_t* keys,
                                   std::uint32_t* vals) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= m) return;
  a[k] = static_cast<std::uint32_t>(id_a[k]);
  b[k] = keys[k] = static_cast<std::uint32_t>(id_b[k]);
  vals[k] = static_cast<std::uint32_t>(k);
}

__global__ void slots_remap_kernel(const std::uint32_t* a, const std::uint32_t* b, std::size_t m,
                                   dem::SlotRemap map) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k < m) dem::remap_slot(k, a, b, m, map);
}

// slot_body_terms of body i (its force and torque into the second buffers: every body's thread
// reads its partners' last forces).
template <class Real>
__global__ void __launch_bounds__(kBlock, 2)
    slots_body_kernel(dem::SlotList list, NarrowBodies<Real> world, dem::BodyArrays b, dem::StepConstants c,
                      dem::SlotState st, dem::WallTerms w, Vec3<double>* force_out,
                      Vec3<double>* torque_out) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  dem::slot_body_terms(i, list, world, b, c, st, w, force_out, torque_out);
}

// The kick (and the next step's kick_drift: DemThen) of every body, the step's forces in b, as the
// rows path's body stage (cuda/dem_sums.cuh: dem_body_kernel) does them after its sums.
template <int kThen>
__global__ void slots_then_kernel(dem::BodyArrays b, double dt) {
  const std::size_t i = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (i >= b.count) return;
  dem::BodyState s = b.state(i);
  const dem::BodyProps& p = b.props[i];
  const bool ell = b.ellipsoid(i);
  dem::kick(s, p, ell, dt);
  if (kThen == int(detail::DemThen::kick_and_drift)) dem::kick_drift(s, p, ell, dt);
  b.store(i, s);
}

}  // namespace cg::cuda

namespace cg::detail {

std::unique_ptr<CudaSlots> make_cuda_slots() { return std::make_unique<CudaSlots>(); }
void destroy(CudaSlots* s) { delete s; }

DeviceBodiesView cuda_slots_inflate(CudaDem& d, CudaSlots& s, double inflation) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  const std::size_t n = d.count;
  s.inflated.reserve(std::max<std::size_t>(n, 1), false);
  if (n > 0) {
    cuda::slots_inflate_kernel<<<cuda::blocks_for(n), cuda::kBlock>>>(d.radius.data(), n, inflation,
                                                                      s.inflated.data());
    CG_CUDA_CHECK_LAUNCH("slots_inflate");
  }
  DeviceBodiesView v;
  v.position = reinterpret_cast<const double*>(d.position.data());
  v.radius = s.inflated.data();
  v.count = n;
  return v;
}

template <class Real>
void cuda_slots_rebuild(CudaDem& d, CudaSlots& s, const DeviceContactsView<Real>& pairs) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  const std::size_t n = d.count, m = pairs.count, old = s.count;
  auto policy = thrust::cuda::par_nosync(d.thrust).on(cudaStreamLegacy);
  std::swap(s.a, s.old_a);
  std::swap(s.b, s.old_b);
  // the old list's touching slots numbered in slot order (their rows in the last step's contacts)
  s.rank.reserve(std::max<std::size_t>(old, 1), true);
  if (old > 0)
    thrust::transform_exclusive_scan(policy, s.age[s.cur].data(), s.age[s.cur].data() + old, s.rank.data(),
                                     cuda::TouchFlag{}, std::int64_t(0), thrust::plus<std::int64_t>());
  const std::size_t room = std::max<std::size_t>(m, 1);
  for (auto* v : {&s.a, &s.b, &s.keys[0], &s.keys[1], &s.by_b[0], &s.by_b[1]}) v->reserve(room, true);
  const int to = 1 - s.cur;
  s.xi[to].reserve(room, true);
  s.normal[to].reserve(room, true);
  s.age[to].reserve(room, true);
  s.prev_row.reserve(room, true);
  s.energy.reserve(room, true);
  if (m > 0) {
    cuda::slots_pairs_kernel<<<cuda::blocks_for(m), cuda::kBlock>>>(
        pairs.id_a, pairs.id_b, m, s.a.data(), s.b.data(), s.keys[0].data(), s.by_b[0].data());
    CG_CUDA_CHECK_LAUNCH("slots_pairs");
    const dem::SlotRemap map{s.old_a.data(),     s.old_b.data(),         old,
                             s.xi[s.cur].data(), s.normal[s.cur].data(), s.age[s.cur].data(),
                             s.rank.data(),      s.xi[to].data(),        s.normal[to].data(),
                             s.age[to].data(),   s.prev_row.data()};
    cuda::slots_remap_kernel<<<cuda::blocks_for(m), cuda::kBlock>>>(s.a.data(), s.b.data(), m, map);
    CG_CUDA_CHECK_LAUNCH("slots_remap");
  }
  s.cur = to;  // the remapped state is the last step's; the other buffers take this step's
  const int next = 1 - s.cur;
  s.xi[next].reserve(room, true);
  s.normal[next].reserve(room, true);
  s.age[next].reserve(room, true);
  s.count = m;
  s.remapped = true;
  // each body's index: a run of the list (sorted by a), and the slots stably sorted by b
  s.a_begin.reserve(n + 1, true);
  s.b_begin.reserve(n + 1, true);
  cub::DoubleBuffer<std::uint32_t> keys(s.keys[0].data(), s.keys[1].data());
  cub::DoubleBuffer<std::uint32_t> vals(s.by_b[0].data(), s.by_b[1].data());
  if (m > 0) {
    const int bits = std::max(1, bits_for(n));
    std::size_t temp = 0;
    CG_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(nullptr, temp, keys, vals, int(m), 0, bits, cudaStreamLegacy));
    s.temp.reserve(std::max<std::size_t>(temp, 1), true);
    CG_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(s.temp.data(), temp, keys, vals, int(m), 0, bits, cudaStreamLegacy));
  }
  if (keys.Current() != s.keys[0].data()) std::swap(s.keys[0], s.keys[1]);
  if (vals.Current() != s.by_b[0].data()) std::swap(s.by_b[0], s.by_b[1]);
  thrust::lower_bound(policy, s.a.data(), s.a.data() + m, thrust::counting_iterator<std::uint32_t>(0),
                      thrust::counting_iterator<std::uint32_t>(std::uint32_t(n) + 1), s.a_begin.data());
  thrust::lower_bound(policy, s.keys[0].data(), s.keys[0].data() + m,
                      thrust::counting_iterator<std::uint32_t>(0),
                      thrust::counting_iterator<std::uint32_t>(std::uint32_t(n) + 1), s.b_begin.data());
}

void cuda_slots_step_begins(CudaSlots& s) { s.remapped = false; }

template <class Real>
void cuda_slots_forces(CudaDem& d, CudaSlots& s, const NarrowBodies<Real>& world, dem::StepConstants c,
                       DemThen then) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  const std::size_t n = d.count;
  if (n == 0) return;
  c.walls = d.walls.data();
  s.force_next.reserve(n, false);
  s.torque_next.reserve(n, false);
  const int now = 1 - s.cur;
  const dem::SlotList list{s.a.data(),       s.b.data(),       s.count,
                           s.a_begin.data(), s.b_begin.data(), s.by_b[0].data()};
  const dem::SlotState st{s.xi[s.cur].data(),   s.normal[s.cur].data(), s.age[s.cur].data(), s.xi[now].data(),
                          s.normal[now].data(), s.age[now].data(),      s.energy.data()};
  const dem::WallTerms w{d.wall_xi.data(), d.wall_energy.data()};
  cuda::slots_body_kernel<Real><<<cuda::blocks_for(n), cuda::kBlock>>>(
      list, world, d.arrays(), c, st, w, s.force_next.data(), s.torque_next.data());
  CG_CUDA_CHECK_LAUNCH("slots_body");
  std::swap(d.force, s.force_next);
  std::swap(d.torque, s.torque_next);
  s.cur = now;
  if (then == DemThen::kick)
    cuda::slots_then_kernel<int(DemThen::kick)><<<cuda::blocks_for(n), cuda::kBlock>>>(d.arrays(), c.dt);
  else if (then == DemThen::kick_and_drift)
    cuda::slots_then_kernel<int(DemThen::kick_and_drift)>
        <<<cuda::blocks_for(n), cuda::kBlock>>>(d.arrays(), c.dt);
  CG_CUDA_CHECK_LAUNCH("slots_then");
}

std::size_t cuda_slots_contact_count(CudaDem& d, CudaSlots& s) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  if (s.count == 0) return 0;
  auto policy = thrust::cuda::par(d.thrust).on(cudaStreamLegacy);
  return static_cast<std::size_t>(
      thrust::count_if(policy, s.age[s.cur].data(), s.age[s.cur].data() + s.count, cuda::Touching{}));
}

void cuda_slots_contact_energies(CudaDem& d, CudaSlots& s, std::size_t contacts) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  d.contact_energy.reserve(std::max<std::size_t>(contacts, 1), true);
  if (s.count == 0) return;
  auto policy = thrust::cuda::par(d.thrust).on(cudaStreamLegacy);
  thrust::copy_if(policy, s.energy.data(), s.energy.data() + s.count, s.age[s.cur].data(),
                  d.contact_energy.data(), cuda::Touching{});
}

template <class Real>
Contacts<Real> cuda_slots_contacts(CudaDem& d, CudaSlots& s) {
  CG_CUDA_CHECK(cudaSetDevice(d.device));
  CG_CUDA_CHECK(cudaDeviceSynchronize());
  const std::size_t n = d.count, m = s.count;
  auto get = [](auto& h, const auto& buf, std::size_t k) {
    h.resize(k);
    if (k > 0) CG_CUDA_CHECK(cudaMemcpy(h.data(), buf.data(), k * sizeof(h[0]), cudaMemcpyDeviceToHost));
  };
  std::vector<std::uint32_t> a, b;
  std::vector<std::int32_t> age, before;
  std::vector<std::int64_t> prev;
  std::vector<Vec3<double>> position;
  std::vector<double> radius;
  get(a, s.a, m);
  get(b, s.b, m);
  get(age, s.age[s.cur], m);
  get(before, s.age[1 - s.cur], m);
  if (s.remapped) get(prev, s.prev_row, m);
  get(position, d.position, n);
  get(radius, d.radius, n);
  // the rows on the host from the same doubles: the narrow functions give the device's bits
  const Bounds bounds = compute_bounds(BodiesView{position, radius, {}, {}});
  const NarrowBodies<Real> world{nullptr, reinterpret_cast<const double*>(position.data()), radius.data(),
                                 bounds.lo};
  return host::slots_contacts(a.data(), b.data(), age.data(), before.data(), prev.data(), s.remapped, m,
                              world);
}

template void cuda_slots_rebuild(CudaDem&, CudaSlots&, const DeviceContactsView<float>&);
template void cuda_slots_rebuild(CudaDem&, CudaSlots&, const DeviceContactsView<double>&);
template void cuda_slots_forces(CudaDem&, CudaSlots&, const NarrowBodies<float>&, dem::StepConstants,
                                DemThen);
template void cuda_slots_forces(CudaDem&, CudaSlots&, const NarrowBodies<double>&, dem::StepConstants,
                                DemThen);
template Contacts<float> cuda_slots_contacts(CudaDem&, CudaSlots&);
template Contacts<double> cuda_slots_contacts(CudaDem&, CudaSlots&);

}  // namespace cg::detail
