#pragma once
// CUDA stage narrow: narrow_decide() (kernels/core/narrow.hpp) on each ordered candidate pair and the
// contact rows of the requested fields, world frame, laid out in ws.out (16-byte aligned fields).
// With the default filter (spheres_touch) every candidate is a contact (narrow_may_reject() false):
// each candidate's row is written at its own index, no scan. A filter that may reject (cells, forced
// by Tuning::candidates; bounding_spheres, scenes with ellipsoids or a skin; centre_cut) takes count →
// scan → fill as the CPU backend's narrow: an accept flag per candidate, an exclusive scan, the host
// reads the row count (one more synchronisation), the accepted rows written compacted.
//
// The rejecting kernels take a decider (core/shape_narrow.hpp): SphereDecide, or ShapeDecide when the
// scene has ellipsoids (r.d_shapes set by shapes.cuh); the host backend uses the same structs. mixed
// (fp32 broad phase, enlarged spheres): on sphere scenes its pair stage already takes fp64's decision
// (Fp64Touch), so one row per candidate; with ellipsoids or a skin the fp64 narrow stage decides.
//
// Scenes with ellipsoids count in passes: narrow_shapes.cuh (narrow_shapes_count and its kernels).
//
// Flags and offsets live in the candidates' dead alternate buffers (pair_a / pair_b .Alternate()).
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/tabulate_output_iterator.h>

#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>
#include <type_traits>

#include "core/narrow.hpp"
#include "core/shape_narrow.hpp"
#include "cuda/common.cuh"
#include "cuda/narrow_shapes.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// narrow: contact data of each sorted pair, world frame as the host (core/narrow.hpp: fp32 from the
// local floats, Real(double(origin) + double(v)), its unresolved normals and fp64 from the world
// doubles). fp32 rows recomputed in fp64 are added to c->fp64_rows.
template <class Real>
__global__ void __launch_bounds__(kBlock)
    narrow_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                  std::uint32_t n_pairs, NarrowBodies<Real> bodies, ContactPtrs<Real> out, bool full,
                  Counters* __restrict__ c) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= n_pairs) return;
  const std::uint32_t a = pair_a[k], b = pair_b[k];
  NarrowFlags flags;
  ContactRow<Real> row = narrow_decide(bodies, a, b, full, flags).row;  // core/narrow.hpp
  row.id_a = a;
  row.id_b = b;
  store_row(out, k, row, full);  // core/contact_fields.hpp: the one row store
  if (flags.fp64_rows) atomicAdd(&c->fp64_rows, static_cast<unsigned long long>(flags.fp64_rows));
}

// narrow, rejecting path, count: accept[k] = 1 when candidate k is a contact. Decide: SphereDecide or
// ShapeDecide (core/shape_narrow.hpp; one thread per candidate: in mixed scenes the warps diverge
// between sphere pairs, sphere–ellipsoid root finds and ellipsoid solves, a known cost); the solver's
// flags are added to c->fallbacks / c->unconverged.
template <class Real, class Decide>
__global__ void __launch_bounds__(kBlock)
    narrow_accept_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                         std::uint32_t n_pairs, Decide decide, std::uint32_t* __restrict__ accept,
                         Counters* __restrict__ c) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  NarrowFlags flags;
  if (k < n_pairs) accept[k] = decide.accept(pair_a[k], pair_b[k], flags) ? 1u : 0u;
  add_flags(flags, c);
}

// narrow, rejecting path, fill: the row of each accepted candidate k at offset[k] (exclusive scan of
// accept): the accepted rows in candidate order; `normal` (shapes: the kept minimisers, else null)
// spares the ellipsoid pairs a second solve.
template <class Real, class Decide>
__global__ void __launch_bounds__(kBlock)
    narrow_fill_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                       std::uint32_t n_pairs, Decide decide, const std::uint32_t* __restrict__ accept,
                       const std::uint32_t* __restrict__ offset, const Vec3<Real>* __restrict__ normal,
                       ContactPtrs<Real> out, bool full, Counters* __restrict__ c) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k == n_pairs - 1) c->rows = offset[k] + accept[k];  // the row count, read with the counters
  if (k >= n_pairs || !accept[k]) return;
  Vec3<Real> n{};
  if (normal) {
    n = normal[k];
    if (n.x != n.x) return;  // fp32's pair in fp64: narrow_fill_fp64_kernel
  }
  const std::uint32_t a = pair_a[k], b = pair_b[k], w = offset[k];
  ContactRow<Real> row = decide.template row_from<false>(a, b, n, full);
  row.id_a = a;
  row.id_b = b;
  store_row(out, w, row, full);  // core/contact_fields.hpp: the one row store
}

// The one-pass compaction of sphere candidates (narrow_select): the select of cub::DeviceSelect::If
// over the candidate indices (the decision alone), and the writer of the accepted candidate k's row at
// its output place i (a tabulate output iterator: CUB hands it the selected k with its place, after its
// decoupled look-back). The writer decides again to take the row and the flags: the pair and its two
// spheres were read by the select of the same tile a moment before (L1/L2, not DRAM).
template <class Real>
struct SphereTouchAt {
  const std::uint32_t* pair_a;
  const std::uint32_t* pair_b;
  SphereDecide<Real> decide;
  __device__ bool operator()(std::uint32_t k) const { return decide.touch(pair_a[k], pair_b[k]); }
};
template <class Real>
struct SphereRowAt {
  const std::uint32_t* pair_a;
  const std::uint32_t* pair_b;
  SphereDecide<Real> decide;
  ContactPtrs<Real> out;
  bool full;
  Counters* c;
  __device__ void operator()(std::ptrdiff_t i, std::uint32_t k) const {
    const std::uint32_t a = pair_a[k], b = pair_b[k];
    NarrowFlags flags;
    ContactRow<Real> row = decide.row_flags(a, b, full, flags);
    row.id_a = a;
    row.id_b = b;
    store_row(out, static_cast<std::size_t>(i), row, full);  // core/contact_fields.hpp: the one row store
    if (flags.fp64_rows)  // rare (centres closer than fp32 resolves): one atomic each
      atomicAdd(&c->fp64_rows, static_cast<unsigned long long>(flags.fp64_rows));
  }
};

}  // namespace cg::cuda

namespace cg::detail {

// The contact arrays of `rows` rows in the workspace's out buffer; returns their bytes.
template <class Real>
std::size_t layout_contacts(std::byte* o, std::size_t rows, FieldSet fields, cuda::ContactPtrs<Real>& cp) {
  const std::size_t v3 = cuda::align16(rows * sizeof(Vec3<Real>));
  const std::size_t ids = cuda::align16(rows * sizeof(std::int64_t));
  const std::size_t reals = cuda::align16(rows * sizeof(Real));
  std::size_t at = 0;
  auto take = [&](std::size_t bytes) {
    std::byte* p = o + at;
    at += bytes;
    return p;
  };
  cp = {};
  for_each_contact_field(cp, fields, [&](auto index, auto*& column) {
    const ContactField& f = kContactFields[index];
    using T = std::remove_reference_t<decltype(*column)>;
    column = reinterpret_cast<T*>(take(f.kind == FieldKind::integer  ? ids
                                       : f.kind == FieldKind::vector ? v3
                                                                     : reals));
  });
  return at;
}

// The rejecting path of sphere scenes with device output (the resident steps' path, a skin's builds
// and reuses): one pass over the candidates, cub::DeviceSelect::If (a stable compaction with decoupled
// look-back) whose output iterator writes each accepted candidate's row at its place (SphereRowAt), the
// row count into the counters (read after the call's last synchronisation, as narrow_compact's). Each
// candidate and its spheres are read from DRAM once, and no flag or offset array is written: against
// count → scan → fill, half the candidate and body reads and none of the scratch traffic.
template <class Real, class Key, class Narrow>
void narrow_select(RunState<Real, Key, Narrow>& r, const SphereDecide<Narrow>& decide) {
  cudaStream_t st = r.st;
  const std::uint32_t np = r.np;
  r.out_bytes = layout_contacts(r.ws.out.data(), np, r.fields(), r.cp);  // rows at their select places
  const std::uint32_t* a = r.pair_a.Current();
  const std::uint32_t* b = r.pair_b.Current();
  const cuda::SphereTouchAt<Narrow> touch{a, b, decide};
  const auto rows = thrust::make_tabulate_output_iterator(
      cuda::SphereRowAt<Narrow>{a, b, decide, r.cp, r.full, r.d_counters});
  cub_run(r.ws, "narrow", [&](void* t, std::size_t& bytes) {
    return cub::DeviceSelect::If(t, bytes, thrust::counting_iterator<std::uint32_t>(0), rows,
                                 &r.d_counters->rows, int(np), touch, st);
  });
  // the counters (the fp64 rows, the row count), read after the next wait
  CG_CUDA_CHECK(
      cudaMemcpyAsync(r.h_counters, r.d_counters, sizeof(cuda::Counters), cudaMemcpyDeviceToHost, st));
  r.rows_pending = true;
}

// The rejecting path: count → scan → fill (see the file comment). Rows that stay on the device
// (job.device_out) go where the scan puts them in an out buffer laid out for every candidate (np rows:
// ws.out holds them), so the fill follows the scan with no wait, and the counters — the row count
// among them — come back with the call's last synchronisation (download_stage): waiting here for the
// count would cost each call a round trip of the host. Rows for host memory are laid out tight for their
// one copy, so the host reads the count first.
template <class Real, class Key, class Narrow, class Decide>
void narrow_compact(RunState<Real, Key, Narrow>& r, const Decide& decide) {
  using cuda::blocks_for;
  using cuda::kBlock;
  cudaStream_t st = r.st;
  const std::uint32_t np = r.np;
  std::uint32_t* d_accept = r.pair_a.Alternate();  // dead after the order stage: >= np u32 each
  std::uint32_t* d_offset = r.pair_b.Alternate();
  const Vec3<Narrow>* d_normal = nullptr;
  if constexpr (std::is_same_v<Decide, ShapeDecide<Narrow>>) {
    d_normal = narrow_shapes_count(r, decide, d_accept, d_offset);
  } else {
    cuda::narrow_accept_kernel<Narrow, Decide><<<blocks_for(np), kBlock, 0, st>>>(
        r.pair_a.Current(), r.pair_b.Current(), np, decide, d_accept, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow_accept");
  }
  cub_run(r.ws, "narrow", [&](void* t, std::size_t& b) {
    return cub::DeviceScan::ExclusiveSum(t, b, d_accept, d_offset, int(np), st);
  });
  if (r.job.device_out) {
    r.out_bytes = layout_contacts(r.ws.out.data(), np, r.fields(), r.cp);  // rows at their scan offsets
  } else {
    std::uint32_t last[2] = {0, 0};  // offset and flag of the last candidate: the row count
    CG_CUDA_CHECK(
        cudaMemcpyAsync(&last[0], d_offset + np - 1, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, st));
    CG_CUDA_CHECK(
        cudaMemcpyAsync(&last[1], d_accept + np - 1, sizeof(std::uint32_t), cudaMemcpyDeviceToHost, st));
    CG_CUDA_CHECK(cudaStreamSynchronize(st));
    r.n_rows = last[0] + last[1];
    r.out_bytes = layout_contacts(r.ws.out.data(), r.n_rows, r.fields(), r.cp);  // <= np rows
  }
  cuda::narrow_fill_kernel<Narrow, Decide>
      <<<blocks_for(np), kBlock, 0, st>>>(r.pair_a.Current(), r.pair_b.Current(), np, decide, d_accept,
                                          d_offset, d_normal, r.cp, r.full, r.d_counters);
  CG_CUDA_CHECK_LAUNCH("narrow_fill");
  if constexpr (std::is_same_v<Decide, ShapeDecide<Narrow>> && std::is_same_v<Narrow, float>) {
    const std::uint32_t* d_fp64_list = r.ws.narrow_list.template span_as<std::uint32_t>(np).data();
    cuda::narrow_fill_fp64_kernel<Narrow>
        <<<cuda::kRareBlocks, kBlock, 0, st>>>(r.pair_a.Current(), r.pair_b.Current(), d_fp64_list, decide,
                                               d_accept, d_offset, r.cp, r.full, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow_fill_fp64");
  }
  // the counters (the solver's flags, the fp64 rows, the row count), read after the next wait
  CG_CUDA_CHECK(
      cudaMemcpyAsync(r.h_counters, r.d_counters, sizeof(cuda::Counters), cudaMemcpyDeviceToHost, st));
  r.rows_pending = true;
}

// The bodies the narrow stage reads (core/narrow.hpp): fp32 pack's local floats in input order,
// every mode the world doubles (the upload buffer ws.pos / ws.rad, or the caller's DeviceBodiesView:
// both live until the end of the call, see workspace.cuh).
// mixed: also the float spheres of its broad phase, which settle most decisions (touch_fp64).
template <class Real, class Key, class Narrow>
NarrowBodies<Narrow> narrow_bodies(const RunState<Real, Key, Narrow>& r) {
  NarrowBodies<Narrow> w{nullptr, r.d_pos, r.d_rad, r.origin};
  if constexpr (std::is_same_v<Real, Narrow>) {
    w.spheres = r.d_spheres;
  } else {
    w.broad = r.d_spheres;
    w.broad_margin = r.g.radius_margin;
  }
  return w;
}

template <class Real, class Key, class Narrow>
void narrow_stage(RunState<Real, Key, Narrow>& r) {
  r.stats.candidates = r.np;
  const NarrowBodies<Narrow> bodies = narrow_bodies(r);
  if (narrow_may_reject(r.filter) && r.np > 0) {
    if (r.d_shapes)  // scenes with ellipsoids (r.filter is then never spheres_touch)
      narrow_compact(r, ShapeDecide<Narrow>{bodies, r.d_shapes, r.job.solver, r.shape_rows,
                                            r.filter == CandidateFilter::centre_cut});
    else if (r.job.device_out && !r.tuning.narrow_two_pass)
      narrow_select(r, SphereDecide<Narrow>{bodies});
    else
      narrow_compact(r, SphereDecide<Narrow>{bodies});
    r.events.mark(EngineStage::narrow, r.st);
    return;
  }
  r.n_rows = r.np;
  r.out_bytes = layout_contacts(r.ws.out.data(), r.n_rows, r.fields(), r.cp);
  if (r.np > 0) {
    // every candidate is a contact: mixed's floats would only add reads to the row's world doubles
    NarrowBodies<Narrow> one_row = bodies;
    one_row.broad = nullptr;
    cuda::narrow_kernel<Narrow><<<cuda::blocks_for(r.np), cuda::kBlock, 0, r.st>>>(
        r.pair_a.Current(), r.pair_b.Current(), r.np, one_row, r.cp, r.full, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("narrow");
    // fp32's fp64 rows, read by the backend after the call's last synchronisation
    CG_CUDA_CHECK(
        cudaMemcpyAsync(r.h_counters, r.d_counters, sizeof(cuda::Counters), cudaMemcpyDeviceToHost, r.st));
  }
  r.events.mark(EngineStage::narrow, r.st);
}

}  // namespace cg::detail
