#pragma once
// The contact stage of the granular dynamics on the device: each contact row's terms
// (core/dem_step.hpp: contact_result), one thread per row, over the engine's device-resident
// contacts; then this step's springs become the last step's. Two ways (tuning: CONTACTGRID_DEM_TERMS):
//   sums              the kernel also sums each body's rows as A (the rows are sorted by A, so a body's
//                     rows as A are one run): a block keeps its rows' force and torque on A in shared
//                     memory, and the thread of the first row of each run adds the run's terms in row
//                     order, from zero (a run that goes on past the block's last row: its further
//                     rows computed again by that thread, the same function of the same inputs, the
//                     same bits). It stores each body's sums (a_force, a_torque) and, per row, only
//                     what the body stage still needs (the force and torque on B, the spring, the
//                     normal, the energy): no torque on A per row, and the body stage reads no rows
//                     as A (dem_sums.cuh).
//   rows (default)    contact_terms of every row (its terms stored); the body stage sums both sides:
//                     on the H100 the faster of the two (the sums' runs keep a block's threads waiting
//                     on the run's first thread). Only what a later stage reads is stored
//                     (CONTACTGRID_DEM_STORE=all: every term, in double, every step): no torques where
//                     the law has no rolling resistance (the body stage takes each from the row's point
//                     and force, the same expression: torques_from_points), in fp32 the normals as
//                     detected (12 bytes a row, the same values), each row's energy only where the
//                     energies may be asked next (a run's last step).
// The same sums in the same order either way: the bits of the CPU backend.
#include <type_traits>

#include "cuda/common.cuh"
#include "cuda/dem_state.cuh"

namespace cg::cuda {

// Contact row k's terms (core/dem_step.hpp: contact_terms; the null terms of t not stored). normal
// non-null: the normals kept as detected, this step's into `normal` and the last step's read from
// old_normal (t.normal unused): the same values as their doubles.
// kMinBlocks: the blocks an SM must hold at once (__launch_bounds__: the compiler caps each thread's
// registers at 65536 / (kBlock kMinBlocks), spilling what does not fit; the same instructions' results,
// the same bits). The force law's doubles take about 150 registers a thread uncapped: one block of
// 8 warps an SM, too few loads in flight for the rows' and bodies' gathers (tuning:
// CONTACTGRID_DEM_BLOCKS).
template <class Real>
__device__ void dem_contact_row(std::size_t k, const dem::ContactRows<Real>& rows, const dem::BodyArrays& b,
                                const dem::StepConstants& c, const dem::ContactTerms& t, Vec3<Real>* normal,
                                const Vec3<Real>* old_normal) {
  if (!normal) {
    dem::contact_terms(k, rows, b, c, t);
    return;
  }
  const dem::ContactResult r = dem::contact_result(k, rows, b, c, t.old_xi, old_normal);
  t.force[k] = r.force;
  if (t.torque_a) t.torque_a[k] = r.torque_a;
  if (t.torque_b) t.torque_b[k] = r.torque_b;
  if (t.energy) t.energy[k] = r.energy;
  t.xi[k] = r.xi;
  normal[k] = rows.normal_on_b[k];
}

// pass (dem::Pass; edge: the rows' edge flags): only the rows of the pass (the overlapped step's
// interior: dem_overlap.cuh).
template <class Real, int kMinBlocks>
__global__ void __launch_bounds__(kBlock, kMinBlocks)
    dem_contact_kernel(dem::ContactRows<Real> rows, dem::BodyArrays b, dem::StepConstants c,
                       dem::ContactTerms t, Vec3<Real>* normal, const Vec3<Real>* old_normal,
                       const std::uint8_t* edge, dem::Pass pass) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= rows.count) return;
  if (!dem::contact_in_pass(k, rows, edge, pass)) return;
  dem_contact_row(k, rows, b, c, t, normal, old_normal);
}

// The overlapped step's edge pass over the contacts: one thread per edge row (edge_rows[0, m)), its
// rows as A, then its rows as B whose A is not an edge row (that A's thread computes those): every
// contact touching an edge row once.
template <class Real, int kMinBlocks>
__global__ void __launch_bounds__(kBlock, kMinBlocks)
    dem_edge_contact_kernel(dem::ContactRows<Real> rows, dem::BodyArrays b, dem::StepConstants c,
                            dem::ContactTerms t, Vec3<Real>* normal, const Vec3<Real>* old_normal,
                            dem::BodyRowIndex index, const std::uint32_t* edge_rows, std::size_t m,
                            const std::uint8_t* edge) {
  const std::size_t e = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (e >= m) return;
  const std::uint32_t i = edge_rows[e];
  for (std::uint32_t k = index.a_begin[i]; k < index.a_begin[i + 1]; ++k)
    dem_contact_row(k, rows, b, c, t, normal, old_normal);
  for (std::uint32_t j = index.b_begin[i]; j < index.b_begin[i + 1]; ++j) {
    const std::uint32_t k = index.by_b[j];
    if (edge[rows.id_a[k]] == 0) dem_contact_row(k, rows, b, c, t, normal, old_normal);
  }
}

template <class Real>
__global__ void dem_contact_a_kernel(dem::ContactRows<Real> rows, dem::BodyArrays b, dem::StepConstants c,
                                     dem::ContactTerms t, Vec3<double>* a_force, Vec3<double>* a_torque) {
  __shared__ Vec3<double> force[kBlock], torque_a[kBlock];
  const std::size_t first = std::size_t(blockIdx.x) * kBlock, k = first + threadIdx.x;
  const std::size_t end = first + kBlock < rows.count ? first + kBlock : rows.count;
  if (k < rows.count) {
    const dem::ContactResult r = dem::contact_result(k, rows, b, c, t.old_xi, t.old_normal);
    t.force[k] = r.force;
    t.torque_b[k] = r.torque_b;
    t.energy[k] = r.energy;
    t.xi[k] = r.xi;
    t.normal[k] = r.normal;
    force[threadIdx.x] = r.force;
    torque_a[threadIdx.x] = r.torque_a;
  }
  __syncthreads();
  if (k >= rows.count) return;
  const std::int64_t a = rows.id_a[k];
  if (k > 0 && rows.id_a[k - 1] == a) return;  // not the first row of its body's run
  Vec3<double> f{0, 0, 0}, tau{0, 0, 0};
  for (std::size_t j = k; j < rows.count && rows.id_a[j] == a; ++j) {
    if (j < end) {
      f = f + force[j - first];
      tau = tau + torque_a[j - first];
    } else {
      const dem::ContactResult r = dem::contact_result(j, rows, b, c, t.old_xi, t.old_normal);
      f = f + r.force;
      tau = tau + r.torque_a;
    }
  }
  a_force[a] = f;
  a_torque[a] = tau;
}

}  // namespace cg::cuda

namespace cg::detail {

// The rows of the engine's view.
template <class Real>
dem::ContactRows<Real> contact_rows(const DeviceContactsView<Real>& v) {
  return {v.id_a,        v.id_b,     v.position_on_a, v.position_on_b,
          v.normal_on_b, v.distance, v.previous_row,  v.count};
}

// The contact stage's outputs for this step's rows (reserved; the flags of what is stored set) and
// where the kernels write them; dem_contact_done: this step's springs become the last step's.
template <class Real>
struct DemContactOutputs {
  dem::ContactTerms t;
  Vec3<Real>* normal = nullptr;
  const Vec3<Real>* old_normal = nullptr;
  bool normals_as_detected = false;
};

// last: the energies may be asked after this step (a run's last step, the forces of the start); in
// rows mode (the default) only then is each row's energy stored.
template <class Real>
DemContactOutputs<Real> dem_contact_outputs(CudaDem& d, const dem::ContactRows<Real>& rows,
                                            const dem::StepConstants& c, bool last) {
  const std::size_t k = rows.count;
  const int next = 1 - d.current;
  // rows (default): only what a later stage reads; no torque without rolling resistance (the body
  // stage's from the points), in fp32 the normals as detected
  const bool narrow = !d.a_sums && !d.store_all;
  d.torques_from_points = narrow && dem::torques_from_points(c);
  DemContactOutputs<Real> o;
  o.normals_as_detected = narrow && std::is_same_v<Real, float>;
  const bool energy = last || !narrow;
  for (DemBuffer<Vec3<double>>* b : {&d.contact_force, &d.xi[next]}) b->reserve(k, true);
  if (!d.torques_from_points) d.torque_b.reserve(k, true);
  if (!d.a_sums && !d.torques_from_points) d.torque_a.reserve(k, true);
  if (energy) d.contact_energy.reserve(k, true);
  if constexpr (std::is_same_v<Real, float>) {
    if (o.normals_as_detected) {
      d.normal_f[next].reserve(k, true);
      o.normal = d.normal_f[next].data();
      o.old_normal = d.normal_f[d.current].data();
    }
  }
  if (!o.normals_as_detected) d.normal[next].reserve(k, true);
  o.t = dem::ContactTerms{d.contact_force.data(),
                          d.a_sums || d.torques_from_points ? nullptr : d.torque_a.data(),
                          d.torques_from_points ? nullptr : d.torque_b.data(),
                          energy ? d.contact_energy.data() : nullptr,
                          d.xi[next].data(),
                          o.normals_as_detected ? nullptr : d.normal[next].data(),
                          d.xi[d.current].data(),
                          o.normals_as_detected ? nullptr : d.normal[d.current].data()};
  return o;
}

template <class Real>
void dem_contact_done(CudaDem& d, const DemContactOutputs<Real>& o) {
  d.current = 1 - d.current;
  d.normals_f = o.normals_as_detected;
}

// dem_contact_kernel over the rows of `pass` (edge: the rows' edge flags) on the legacy stream.
template <class Real>
void dem_contact_launch(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                        const DemContactOutputs<Real>& o, dem::Pass pass, const std::uint8_t* edge) {
  const std::size_t k = rows.count;
  if (k == 0) return;
  const unsigned blocks = cuda::blocks_for(k);
  if (d.min_blocks >= 3)
    cuda::dem_contact_kernel<Real, 3>
        <<<blocks, cuda::kBlock>>>(rows, d.arrays(), c, o.t, o.normal, o.old_normal, edge, pass);
  else if (d.min_blocks == 2)
    cuda::dem_contact_kernel<Real, 2>
        <<<blocks, cuda::kBlock>>>(rows, d.arrays(), c, o.t, o.normal, o.old_normal, edge, pass);
  else
    cuda::dem_contact_kernel<Real, 1>
        <<<blocks, cuda::kBlock>>>(rows, d.arrays(), c, o.t, o.normal, o.old_normal, edge, pass);
  CG_CUDA_CHECK_LAUNCH("dem_contact");
}

template <class Real>
void dem_contact_stage(CudaDem& d, const dem::ContactRows<Real>& rows, const dem::StepConstants& c,
                       bool last) {
  const std::size_t k = rows.count;
  const DemContactOutputs<Real> o = dem_contact_outputs(d, rows, c, last);
  if (k > 0 && d.a_sums) {
    d.a_force.reserve(std::max<std::size_t>(d.count, 1), true);
    d.a_torque.reserve(std::max<std::size_t>(d.count, 1), true);
    cuda::dem_contact_a_kernel<Real><<<cuda::blocks_for(k), cuda::kBlock>>>(
        rows, d.arrays(), c, o.t, d.a_force.data(), d.a_torque.data());
    CG_CUDA_CHECK_LAUNCH("dem_contact_a");
  } else {
    dem_contact_launch(d, rows, c, o, dem::Pass::all, nullptr);
  }
  dem_contact_done(d, o);
}

}  // namespace cg::detail
