#pragma once
// CUDA stage cell order: the kept candidates of a skin (skin.cuh) in the bodies' cell order, for the
// calls whose rows the caller takes in any order (DetectJob::any_row_order: Engine::detect_resident,
// the resident steps). fp32 sphere scenes, grid broad phase, device output, no history; every other
// call keeps the (a, b) path of skin.cuh, as does every call under CONTACTGRID_STEP_ORDER=file.
//   keep_cell_candidates  at a build, instead of the order stage: the pair stage's candidates, in the
//                         order its cell walk wrote them, as cell-order indices (the walk writes them
//                         so into the kept list, pairs.cuh; or pack's permutation inverted maps its
//                         input indices), the permutation kept, and the spheres gathered into cell order
//   skin_pack_cell_stage  the check of a call whose kept list is in cell order, and a reuse's pack,
//                         in one pass over the bodies in input order (motion_pack_cell_kernel: the
//                         reads sequential, each sphere written at its cell place inv[i]); a build
//                         packs again (CONTACTGRID_STEP_PACK=separate: the check, then pack_cell_stage)
//   pack_cell_stage       at a reuse, instead of pack: the moved bodies packed straight into cell
//                         order (one pass; within a z layer the input indices ascend, so the reads of
//                         the world doubles are a few hundred sequential streams)
//   narrow_cell_stage     one pass over the kept list (cell_narrow_kernel: each block's accepted
//                         candidates written at a row cursor, their spheres read once; under
//                         CONTACTGRID_STEP_NARROW=select the one-pass select of narrow.cuh), reading
//                         the cell-ordered spheres: the two bodies of a candidate lie in nearby cells,
//                         so the reads stay in a few MiB of L2 instead of one random DRAM sector
//                         each; the row carries the input indices (a < b), computed as
//                         narrow_decide computes it (core/narrow.hpp: narrow_decide_floats)
//   canonical_rows        the rows come out in the walk's order, not in (a, b) order: the download
//                         (download_contacts in backend_copies.cuh) sorts them by (a, b) on the device
//                         first, so resident_contacts() gives the bytes of the (a, b) path
// The walk's order is fixed at the build; the set of rows of a call is that of the (a, b) path.
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/tabulate_output_iterator.h>

#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_select.cuh>
#include <type_traits>

#include "core/narrow.hpp"
#include "cuda/common.cuh"
#include "cuda/narrow.cuh"
#include "cuda/pack.cuh"
#include "cuda/run_state.cuh"
#include "cuda/skin.cuh"

namespace cg::cuda {

// inv[perm[j]] = j over the bodies.
__global__ void __launch_bounds__(kBlock)
    inverse_perm_kernel(const std::uint32_t* __restrict__ perm, std::uint32_t n,
                        std::uint32_t* __restrict__ inv) {
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  if (j < n) inv[perm[j]] = j;
}

// Candidate k of input indices (a < b) as cell-order indices (inv[a], inv[b]), in the same place.
__global__ void __launch_bounds__(kBlock)
    cell_pairs_kernel(const std::uint32_t* __restrict__ a_in, const std::uint32_t* __restrict__ b_in,
                      std::uint32_t np, const std::uint32_t* __restrict__ inv,
                      std::uint32_t* __restrict__ a_out, std::uint32_t* __restrict__ b_out) {
  const std::uint32_t k = blockIdx.x * kBlock + threadIdx.x;
  if (k >= np) return;
  a_out[k] = inv[a_in[k]];
  b_out[k] = inv[b_in[k]];
}

// pack of a reuse in cell order: out[j] = pack's sphere of input body perm[j] (packed_sphere: the
// same bits, an invalid body → c->bad as pack's).
template <class Real>
__global__ void __launch_bounds__(kBlock)
    pack_cell_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                     const std::uint32_t* __restrict__ perm, std::uint32_t n, Vec3<double> origin,
                     GridParams<Real> g, Sphere<Real>* __restrict__ out, Counters* __restrict__ c) {
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  if (j < n) out[j] = packed_sphere(pos, rad, nullptr, perm[j], n, origin, g, c);  // (a skin: the doubles)
}

// The check and a reuse's pack of a cell-order kept list in one pass in input order: body i's motion
// (motion_kernel's reduction) and its sphere (pack_cell_kernel's bits) written at its cell place
// inv[i]. The sequential reads cost less than pack_cell_kernel's gather through the permutation.
template <class Real>
__global__ void __launch_bounds__(kBlock)
    motion_pack_cell_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                            const std::uint8_t* __restrict__ report, const double* __restrict__ ref_pos,
                            const double* __restrict__ ref_rad, const std::uint8_t* __restrict__ ref_report,
                            const std::uint32_t* __restrict__ inv, std::uint32_t n, Vec3<double> origin,
                            GridParams<Real> g, Sphere<Real>* __restrict__ out, Counters* __restrict__ c) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  BodyMotion m{};
  if (i < n) {
    m = body_motion(pos, rad, report, ref_pos, ref_rad, ref_report, i);
    out[inv[i]] = packed_sphere(pos, rad, nullptr, i, n, origin, g, c);
  }
  record_motion(m, c);
}

// The select's decision of kept candidate k (cell-order indices) on the cell-ordered spheres:
// narrow_touch's fp32 test on the same floats.
template <class Real>
struct CellTouchAt {
  const std::uint32_t* pair_a;
  const std::uint32_t* pair_b;
  const Sphere<Real>* spheres;  // cell order
  __device__ bool operator()(std::uint32_t k) const {
    return spheres_touch(spheres[pair_a[k]], spheres[pair_b[k]]);
  }
};

// The row of accepted candidate k at its output place i: input indices a = perm[ja] < b = perm[jb],
// narrow_decide_floats on the cell-ordered spheres and the input-order world doubles.
template <class Real>
struct CellRowAt {
  const std::uint32_t* pair_a;
  const std::uint32_t* pair_b;
  const std::uint32_t* perm;
  NarrowBodies<Real> bodies;  // spheres: cell order; position, radius: input order
  ContactPtrs<Real> out;
  bool full;
  Counters* c;
  __device__ void operator()(std::ptrdiff_t i, std::uint32_t k) const {
    const std::uint32_t ja = pair_a[k], jb = pair_b[k];
    const std::uint32_t a = perm[ja], b = perm[jb];
    NarrowFlags flags;
    ContactRow<Real> row =
        narrow_decide_floats(bodies, bodies.spheres[ja], bodies.spheres[jb], a, b, full, flags).row;
    row.id_a = a;
    row.id_b = b;
    store_row(out, static_cast<std::size_t>(i), row, full);  // core/contact_fields.hpp: the one row store
    if (flags.fp64_rows) atomicAdd(&c->fp64_rows, static_cast<unsigned long long>(flags.fp64_rows));
  }
};

// The narrow stage over the kept cell-order list in one pass without a scan: block b tests the
// candidates [b·kBlock·kItems, (b + 1)·kBlock·kItems), item i of thread t being candidate
// b·kBlock·kItems + i·kBlock + t (each warp reads 32 consecutive candidates), keeps the spheres it
// read, takes the room of its accepted candidates at the row cursor c->rows (one atomicAdd a block)
// and writes each row (CellRowAt's) at the cursor's place + its rank among the block's accepted ones,
// warp by warp and item by item (the rows of a warp's item are consecutive: coalesced stores). The
// rows' order is the blocks' arrival order (the caller takes any order: canonical_rows sorts them
// when they come down); their set is narrow_select's. Reads each candidate and its spheres once
// (the select reads them again to write a row).
template <int kItems>
__global__ void __launch_bounds__(kBlock)
    cell_narrow_kernel(const std::uint32_t* __restrict__ pair_a, const std::uint32_t* __restrict__ pair_b,
                       std::uint32_t np, const std::uint32_t* __restrict__ perm, NarrowBodies<float> bodies,
                       ContactPtrs<float> out, bool full, Counters* __restrict__ c) {
  constexpr std::uint32_t kWarps = kBlock / 32;
  __shared__ unsigned long long s_warp_base[kWarps];
  const std::uint32_t lane = threadIdx.x & 31u, warp = threadIdx.x >> 5;
  const std::uint64_t first = std::uint64_t(blockIdx.x) * kBlock * kItems + threadIdx.x;
  std::uint32_t ja[kItems] = {}, jb[kItems] = {}, accepted[kItems] = {};
  Sphere<float> sa[kItems] = {}, sb[kItems] = {};
  std::uint32_t warp_count = 0;
#pragma unroll
  for (int i = 0; i < kItems; ++i) {
    const std::uint64_t k = first + std::uint64_t(i) * kBlock;
    bool touch = false;
    if (k < np) {
      ja[i] = pair_a[k];
      jb[i] = pair_b[k];
      sa[i] = bodies.spheres[ja[i]];
      sb[i] = bodies.spheres[jb[i]];
      touch = spheres_touch(sa[i], sb[i]);
    }
    accepted[i] = __ballot_sync(0xffffffffu, touch);
    warp_count += __popc(accepted[i]);
  }
  if (lane == 0) s_warp_base[warp] = warp_count;
  __syncthreads();
  if (threadIdx.x == 0) {  // the block's room at the cursor, then each warp's place in it
    unsigned long long total = 0;
    for (std::uint32_t w = 0; w < kWarps; ++w) total += s_warp_base[w];
    unsigned long long at = total ? atomicAdd(&c->rows, total) : 0ull;
    for (std::uint32_t w = 0; w < kWarps; ++w) {
      const unsigned long long count = s_warp_base[w];
      s_warp_base[w] = at;
      at += count;
    }
  }
  __syncthreads();
  unsigned long long place = s_warp_base[warp];
  const std::uint32_t below = (1u << lane) - 1u;
#pragma unroll
  for (int i = 0; i < kItems; ++i) {
    if ((accepted[i] >> lane) & 1u) {
      const std::uint32_t a = perm[ja[i]], b = perm[jb[i]];
      NarrowFlags flags;
      ContactRow<float> row = narrow_decide_floats(bodies, sa[i], sb[i], a, b, full, flags).row;
      row.id_a = a;
      row.id_b = b;
      store_row(out, static_cast<std::size_t>(place + __popc(accepted[i] & below)), row, full);
      if (flags.fp64_rows) atomicAdd(&c->fp64_rows, static_cast<unsigned long long>(flags.fp64_rows));
    }
    place += __popc(accepted[i]);
  }
}

// The sort key of row k: (a, b) as one 64-bit word, and k.
__global__ void __launch_bounds__(kBlock)
    row_keys_kernel(const std::int64_t* __restrict__ id_a, const std::int64_t* __restrict__ id_b,
                    std::size_t m, unsigned long long* __restrict__ keys, std::uint32_t* __restrict__ index) {
  const std::size_t k = std::size_t(blockIdx.x) * kBlock + threadIdx.x;
  if (k >= m) return;
  keys[k] = (static_cast<unsigned long long>(id_a[k]) << 32) | static_cast<unsigned long long>(id_b[k]);
  index[k] = static_cast<std::uint32_t>(k);
}

}  // namespace cg::cuda

namespace cg::detail {

// Whether this call keeps its candidates in cell order (see the file comment).
template <class Real, class Key, class Narrow>
bool cell_order_wanted(const RunState<Real, Key, Narrow>& r) {
  if constexpr (!std::is_same_v<Real, float> || !std::is_same_v<Narrow, float>) {
    return false;
  } else {
    return r.job.skin > 0 && r.job.any_row_order && !r.tuning.step_order_file && r.job.ellipsoids == 0 &&
           r.job.device_out != nullptr && !r.tuning.narrow_two_pass && !r.history &&
           r.job.broad == BroadPhase::grid && !r.type_passes && narrow_may_reject(r.filter);
  }
}

// At a build (after the pair stage, instead of order_stage and keep_candidates): the kept list in cell
// order, the permutation and the bodies' state it was built from; the cell-ordered spheres for this
// call's narrow stage. The pair stage has written the list itself (r.kept_written: cell-order indices
// in ws.kept_pairs); else (CONTACTGRID_STEP_BUILD=copy, or under CONTACTGRID_STEP_REBUILD=fill more
// candidates than the room it had) its input indices are mapped through the inverse permutation
// into the list. Timed as the order stage.
template <class Real, class Key, class Narrow>
void keep_cell_candidates(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  const std::size_t np = r.np, n = r.n64;
  ws.reserve({{&ws.kept_perm, n * sizeof(std::uint32_t)}}, "skin");
  std::uint32_t* perm = ws.kept_perm.span_as<std::uint32_t>(n).data();
  cuda::device_copy(perm, r.d_perm, n * sizeof(std::uint32_t), st);
  Sphere<Real>* cell = ws.cell_spheres.span_as<Sphere<Real>>(n).data();  // read by the pair stage: done
  if (n > 0) {
    cuda::gather_kernel<Sphere<Real>>
        <<<cuda::blocks_for(n), cuda::kBlock, 0, st>>>(r.d_spheres, perm, n, cell);
    CG_CUDA_CHECK_LAUNCH("gather_spheres");
  }
  // each input index's cell place: the next check's pack (skin_pack_cell_stage), and the mapping of a
  // list the pair stage wrote as input indices
  ws.reserve({{&ws.kept_inv, n * sizeof(std::uint32_t)}}, "skin");
  std::uint32_t* inv = ws.kept_inv.span_as<std::uint32_t>(n).data();
  if (n > 0) {
    cuda::inverse_perm_kernel<<<cuda::blocks_for(n), cuda::kBlock, 0, st>>>(perm, r.n, inv);
    CG_CUDA_CHECK_LAUNCH("inverse_perm");
  }
  std::size_t stride = ws.kept_stride;
  if (!r.kept_written) {
    ws.reserve({{&ws.kept_pairs, 2 * np * sizeof(std::uint32_t)}}, "skin");
    stride = np;
    std::uint32_t* kept = ws.kept_pairs.span_as<std::uint32_t>(2 * np).data();
    if (np > 0) {
      cuda::cell_pairs_kernel<<<cuda::blocks_for(np), cuda::kBlock, 0, st>>>(
          r.pair_a.Current(), r.pair_b.Current(), r.np, inv, kept, kept + np);
      CG_CUDA_CHECK_LAUNCH("cell_pairs");
    }
  }
  keep_reference(r, stride, true);
  std::uint32_t* kept = ws.kept_pairs.span_as<std::uint32_t>(stride + np).data();
  r.pair_a = cub::DoubleBuffer<std::uint32_t>(kept, kept);  // the narrow stage reads Current() alone
  r.pair_b = cub::DoubleBuffer<std::uint32_t>(kept + stride, kept + stride);
  r.events.mark(EngineStage::order, st);
}

// The check of a call whose kept list is in cell order (as skin_stage's: the same motion, the same
// decision), with the bodies packed into the kept cell order in the same pass: true when the list is
// reused, its spheres then ready (the pack stage empty); a build packs again (pack_stage).
template <class Real, class Key, class Narrow>
bool skin_pack_cell_stage(RunState<Real, Key, Narrow>& r) {
  if (!(r.job.skin > 0) || !r.job.check) return false;
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  r.d_counters = ws.counters.span_as<cuda::Counters>(1).data();
  CG_CUDA_CHECK(cudaMemsetAsync(r.d_counters, 0, sizeof(cuda::Counters), st));  // (c->rows: the narrow's)
  ws.reserve({{&ws.cell_spheres, r.n64 * sizeof(Sphere<Real>)}}, "pack");
  const bool both_reported = r.d_report && ws.kept_reported;
  if (r.n > 0) {
    cuda::motion_pack_cell_kernel<Real><<<r.nb, cuda::kBlock, 0, st>>>(
        r.d_pos, r.d_rad, both_reported ? r.d_report : nullptr, ws.ref_pos.span_as<double>(3 * r.n64).data(),
        ws.ref_rad.span_as<double>(r.n64).data(),
        both_reported ? ws.ref_report.span_as<std::uint8_t>(r.n64).data() : nullptr,
        ws.kept_inv.span_as<std::uint32_t>(r.n).data(), r.n, r.origin, r.g,
        ws.cell_spheres.span_as<Sphere<Real>>(r.n).data(), r.d_counters);
    CG_CUDA_CHECK_LAUNCH("motion_pack_cell");
  }
  const bool reuse = skin_decision(r);
  if (reuse) r.events.mark(EngineStage::pack, st);  // (packed with the check)
  return reuse;
}

// At a reuse (instead of pack_stage): the moved bodies packed into the kept cell order.
template <class Real, class Key, class Narrow>
void pack_cell_stage(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  cudaStream_t st = r.st;
  r.d_counters = ws.counters.span_as<cuda::Counters>(1).data();
  CG_CUDA_CHECK(cudaMemsetAsync(r.d_counters, 0, sizeof(cuda::Counters), st));
  ws.reserve({{&ws.cell_spheres, r.n64 * sizeof(Sphere<Real>)}}, "pack");
  Sphere<Real>* cell = ws.cell_spheres.span_as<Sphere<Real>>(r.n).data();
  if (r.n > 0) {
    cuda::pack_cell_kernel<Real>
        <<<r.nb, cuda::kBlock, 0, st>>>(r.d_pos, r.d_rad, ws.kept_perm.span_as<std::uint32_t>(r.n).data(),
                                        r.n, r.origin, r.g, cell, r.d_counters);
    CG_CUDA_CHECK_LAUNCH("pack_cell");
  }
  r.events.mark(EngineStage::pack, st);
}

// The narrow stage over the kept cell-order list (r.pair_a / pair_b: kept_cell_candidates' or
// reuse_candidates'): narrow_select's one pass with the cell-order reads.
template <class Real, class Key, class Narrow>
void narrow_cell_stage(RunState<Real, Key, Narrow>& r) {
  r.stats.candidates = r.np;
  const std::uint32_t np = r.np;
  r.out_bytes = layout_contacts(r.ws.out.data(), np, r.fields(), r.cp);  // rows at their select places
  if (np == 0) {
    r.n_rows = 0;
    r.events.mark(EngineStage::narrow, r.st);
    return;
  }
  if constexpr (std::is_same_v<Real, float> && std::is_same_v<Narrow, float>) {  // (cell_order_wanted)
    const Sphere<float>* cell = r.ws.cell_spheres.template span_as<Sphere<float>>(r.n).data();
    const NarrowBodies<float> bodies{cell, r.d_pos, r.d_rad, r.origin};
    const std::uint32_t* a = r.pair_a.Current();
    const std::uint32_t* b = r.pair_b.Current();
    const std::uint32_t* perm = r.ws.kept_perm.template span_as<std::uint32_t>(r.n).data();
    if (r.tuning.step_narrow_select) {
      const cuda::CellTouchAt<float> touch{a, b, cell};
      const auto rows = thrust::make_tabulate_output_iterator(
          cuda::CellRowAt<float>{a, b, perm, bodies, r.cp, r.full, r.d_counters});
      cub_run(r.ws, "narrow", [&](void* t, std::size_t& bytes) {
        return cub::DeviceSelect::If(t, bytes, thrust::counting_iterator<std::uint32_t>(0), rows,
                                     &r.d_counters->rows, int(np), touch, r.st);
      });
    } else {                           // (c->rows: zeroed with the counters at pack, untouched since)
      auto launch = [&](auto items) {  // candidates a thread: 4 (about 104 registers), or 2 (80: more warps)
        constexpr int kItems = decltype(items)::value;
        const std::uint64_t per_block = std::uint64_t(cuda::kBlock) * kItems;
        cuda::cell_narrow_kernel<kItems>
            <<<static_cast<std::uint32_t>((np + per_block - 1) / per_block), cuda::kBlock, 0, r.st>>>(
                a, b, np, perm, bodies, r.cp, r.full, r.d_counters);
      };
      if (r.tuning.step_narrow_items == 2)
        launch(std::integral_constant<int, 2>{});
      else
        launch(std::integral_constant<int, 4>{});
      CG_CUDA_CHECK_LAUNCH("cell_narrow");
    }
  }
  // the counters (the fp64 rows, the row count), read after the next wait
  CG_CUDA_CHECK(
      cudaMemcpyAsync(r.h_counters, r.d_counters, sizeof(cuda::Counters), cudaMemcpyDeviceToHost, r.st));
  r.rows_pending = true;
  r.events.mark(EngineStage::narrow, r.st);
}

// The m rows of `cp` (device) in (a, b) order: the sort's index (kept in ws.canon_index, valid until
// the next call) for gather_rows; returns it. Synchronous with `st`'s work before it.
inline const std::uint32_t* canonical_rows(Workspace& ws, cudaStream_t st, const std::int64_t* id_a,
                                           const std::int64_t* id_b, std::size_t m, int id_bits) {
  using cuda::blocks_for;
  ws.reserve({{&ws.canon_keys[0], m * sizeof(unsigned long long)},
              {&ws.canon_keys[1], m * sizeof(unsigned long long)},
              {&ws.canon_index[0], m * sizeof(std::uint32_t)},
              {&ws.canon_index[1], m * sizeof(std::uint32_t)}},
             "download");
  cub::DoubleBuffer<unsigned long long> keys(ws.canon_keys[0].span_as<unsigned long long>(m).data(),
                                             ws.canon_keys[1].span_as<unsigned long long>(m).data());
  cub::DoubleBuffer<std::uint32_t> index(ws.canon_index[0].span_as<std::uint32_t>(m).data(),
                                         ws.canon_index[1].span_as<std::uint32_t>(m).data());
  cuda::row_keys_kernel<<<blocks_for(m), cuda::kBlock, 0, st>>>(id_a, id_b, m, keys.Current(),
                                                                index.Current());
  CG_CUDA_CHECK_LAUNCH("row_keys");
  cub_run(ws, "download", [&](void* t, std::size_t& b) {
    return cub::DeviceRadixSort::SortPairs(t, b, keys, index, int(m), 0, 32 + id_bits, st);
  });
  return index.Current();
}

}  // namespace cg::detail
