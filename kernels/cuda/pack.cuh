#pragma once
// CUDA stage pack: world double → local Real spheres; the renumbering of the bodies by z layer of
// cells (a one-pass radix sort, for locality of the pair stage only, when the spheres outgrow the L2);
// control bytes, per-block entry totals and their scan; the host reads the entries total and the
// bad-data status (the first synchronisation of a call).
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>

#include "cuda/bounds.cuh"
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"
#include "cuda/shapes.cuh"

namespace cg::cuda {

// Locality key of a body: the layer of cells along z (the slowest axis of the cell key) holding its
// lowest cell, coarsened by `shift` to at most 256 layers so that the renumbering sort is one radix
// pass. The pair stage walks the cells in key order, z slowest, so the bodies it reads at any moment
// lie in a few consecutive layers, a few MiB that stay in L2 (the order within a layer matters
// little then: a 4x4x4-cell block key with its two-pass sort gains no time overall, BENCHMARKS.md §3,
// BENCHMARKS.md §11). It changes no result:
// decisions are symmetric in the two bodies, and pairs are emitted and sorted by their original
// indices.
template <class Key>
__device__ __forceinline__ Key home_layer_key(const BodyCells& bc, int shift) {
  return Key(bc.lo[2] >> shift);
}

// Body i as pack makes it: the local Real sphere Real(p - origin), radius Real(r) + g.radius_margin
// (mixed's enlarged spheres; + 0 otherwise); an invalid body → c->bad. fp32 with `floats` (the
// 16-byte upload, upload_pack.hpp): the host made Real(p - origin) and Real(r) and checked the bodies
// (compute_bounds); the margin is added here.
template <class Real>
__device__ __forceinline__ Sphere<Real> packed_sphere(const double* __restrict__ pos,
                                                      const double* __restrict__ rad,
                                                      const Sphere<float>* __restrict__ floats,
                                                      std::uint32_t i, std::uint32_t n,
                                                      const Vec3<double>& origin, const GridParams<Real>& g,
                                                      Counters* __restrict__ c) {
  if constexpr (std::is_same_v<Real, float>) {
    if (floats) {
      Sphere<float> s = floats[i];
      s.r = s.r + g.radius_margin;
      return s;
    }
  }
  const std::uint64_t i3 = 3 * std::uint64_t(i);
  const double px = pos[i3], py = pos[i3 + 1], pz = pos[i3 + 2], r = rad[i];
  if (body_is_bad(px, py, pz, r)) atomicMax(&c->bad, static_cast<unsigned long long>(n - i));
  return {static_cast<Real>(px - origin.x), static_cast<Real>(py - origin.y),
          static_cast<Real>(pz - origin.z), static_cast<Real>(r) + g.radius_margin};
}

// pack (renumbered bodies, and the spheres alone of a skin's reuse step): the packed spheres in input
// order, and the (locality key, index) pairs of the renumbering sort (home_key null: none).
template <class Real, class Key>
__global__ void __launch_bounds__(kBlock)
    pack_kernel(const double* __restrict__ pos, const double* __restrict__ rad,
                const Sphere<float>* __restrict__ floats, std::uint32_t n, Vec3<double> origin,
                GridParams<Real> g, Sphere<Real>* __restrict__ spheres, int layer_shift,
                Key* __restrict__ home_key, std::uint32_t* __restrict__ home_index,
                Counters* __restrict__ c) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= n) return;
  const Sphere<Real> s = packed_sphere(pos, rad, floats, i, n, origin, g, c);
  spheres[i] = s;
  if (!home_key) return;
  home_key[i] = home_layer_key<Key>(body_cells(s, g), layer_shift);
  home_index[i] = i;
}

// What reorder packs itself where the bodies keep their input order (kPack): the world rows, and the
// shape rows of scenes with ellipsoids (shapes.cuh) — one pass over the bodies instead of three
// (pack, pack_shapes, reorder; BENCHMARKS.md §3).
template <class Packed>
struct PackInput {
  const double* pos = nullptr;
  const double* rad = nullptr;
  Vec3<double> origin{};
  ShapeInput<Packed> shape;
  const Sphere<float>* floats = nullptr;  // fp32's 16-byte upload (packed_sphere)
};

// reorder: cell-ordered copy of the spheres (body j = input body perm[j] = sorted_index[j]; radii +
// `inflation`, the pair stage's spheres: 0 without a skin; cell_spheres null: the input-order spheres
// are those, no copy), control bytes, and per block the sum of the entry counts
// (block_entries[blockIdx.x]; total added to c->entries). kPack (the bodies keep their order, body j is
// input body j): the spheres and packed shapes are made here from `in` (written to `spheres` and
// in.shape.out), not read.
// Single sort (lo_key != nullptr): the key of the body's lowest cell, from which the entries stage
// makes its cells' keys with the control byte (spilled_cell_key).
// Type-pass path (base != nullptr): also the super-cell index of the body's lowest even cell
// (cell_key of lo & ~1, type bits 0) and per block the number of bodies having a cell of each
// type (type_blocks[t * gridDim.x + blockIdx.x]; totals added to c->type_entries[t]).
// CandidateFilter::centre_cut (cut != null): the cut shape of each body (core/centre_cut.hpp) from its
// packed shape (gathered, or with kPack the one just made), in cell order, and (`boxes`: no skin) its
// cells from the box of its shape (cut_cells).
template <class Real, class Key, class Packed, bool kPack>
__global__ void __launch_bounds__(kBlock)
    reorder_kernel(Sphere<Real>* __restrict__ spheres, std::uint32_t n, GridParams<Real> g,
                   const std::uint32_t* __restrict__ sorted_index, Sphere<Real>* __restrict__ cell_spheres,
                   std::uint8_t* __restrict__ ctrl, std::uint32_t* __restrict__ perm,
                   std::uint32_t* __restrict__ block_entries, Counters* __restrict__ c,
                   Key* __restrict__ base, std::uint32_t* __restrict__ type_blocks,
                   const std::uint8_t* __restrict__ report, Real inflation,
                   const PackedShape<Packed>* __restrict__ shapes, CutShape* __restrict__ cut, bool boxes,
                   Key* __restrict__ lo_key, PackInput<Packed> in) {
  using Reduce = cub::BlockReduce<std::uint32_t, kBlock>;
  __shared__ typename Reduce::TempStorage tmp;
  __shared__ std::uint32_t s_types[8];
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  if (base && threadIdx.x < 8) s_types[threadIdx.x] = 0;
  std::uint32_t count = 0, cb = 0;
  bool live = false;
  if (j < n) {
    std::uint32_t i = j;
    Sphere<Real> s;
    PackedShape<Packed> shape{};  // (the cut's)
    if constexpr (kPack) {
      s = packed_sphere(in.pos, in.rad, in.floats, j, n, in.origin, g, c);
      spheres[j] = s;
      if (in.shape.kind) {
        shape = packed_shape_of(in.shape, in.rad, j, n, c);
        in.shape.out[j] = shape;
      }
    } else {
      i = sorted_index[j];
      s = spheres[i];
      if (cut) shape = shapes[i];
    }
    s.r += inflation;  // a skin (EngineOptions::skin): cells and pair test of the inflated sphere
    if (cell_spheres) cell_spheres[j] = s;
    perm[j] = i;
    BodyCells bc;
    if (cut) {
      const CutShape cs = cut_shape(shape);
      cut[j] = cs;
      bc = boxes ? cut_cells(s, cs, g) : body_cells(s, g);
    } else {
      bc = body_cells(s, g);
    }
    const std::uint32_t m = report ? report[i] : 0u;
    cb = control_bits(bc) | ((m & kReportedBit) ? kReportBit : 0u) | ((m & kPairedBit) ? kPairedCtrlBit : 0u);
    ctrl[j] = static_cast<std::uint8_t>(cb);
    count = entry_count(bc);
    live = true;
    if (base) base[j] = cell_key<Key>(bc.lo[0] & ~1u, bc.lo[1] & ~1u, bc.lo[2] & ~1u, g);
    if (lo_key) lo_key[j] = cell_key<Key>(bc.lo[0], bc.lo[1], bc.lo[2], g);
  }
  const std::uint32_t total = Reduce(tmp).Sum(count);
  if (base) {
    __syncthreads();  // s_types zeroed
    if (live)
      for (std::uint32_t t = 0; t < 8; ++t)
        if (has_type(cb, t)) atomicAdd(&s_types[t], 1u);
    __syncthreads();
    if (threadIdx.x < 8) {
      type_blocks[threadIdx.x * gridDim.x + blockIdx.x] = s_types[threadIdx.x];
      atomicAdd(&c->type_entries[threadIdx.x], static_cast<unsigned long long>(s_types[threadIdx.x]));
    }
  }
  if (threadIdx.x == 0) {
    block_entries[blockIdx.x] = total;
    atomicAdd(&c->entries, static_cast<unsigned long long>(total));
  }
}

}  // namespace cg::cuda

namespace cg::detail {

// Sizes of the call and the workspace of the stages up to entries (before the first event).
template <class Real, class Key, class Narrow>
void reserve_pack(RunState<Real, Key, Narrow>& r) {
  r.nb = cuda::blocks_for(r.n);
  // Block totals and their scan: of the entry counts (single sort), or, in the type-pass path, the
  // entry totals then [8][nb] bodies-per-type totals and their scan.
  r.body_block_words = r.type_passes ? 17 * std::size_t(r.nb) : 2 * std::size_t(r.nb);
  if (r.n64 >= (std::uint64_t(1) << 31))
    throw ResourceError("more than 2^31 - 1 bodies on one GPU; use more MPI ranks");
  const std::uint64_t n64 = r.n64;
  Workspace& ws = r.ws;
  // The renumbering sort's four arrays are the entry buffers, not yet live (ws.home_keys/home_index).
  ws.reserve({{&ws.pos, r.device_in ? 0 : n64 * sizeof(Vec3<double>)},
              {&ws.rad, r.device_in ? 0 : n64 * sizeof(double)},
              {&ws.report, r.device_in || r.job.bodies.report.empty() ? 0 : n64},
              {&ws.spheres, n64 * sizeof(Sphere<Real>)},
              {&ws.cell_spheres, n64 * sizeof(Sphere<Real>)},
              {&ws.perm, n64 * sizeof(std::uint32_t)},
              {&ws.ctrl, n64},
              {&ws.keys[0], n64 * sizeof(Key)},
              {&ws.keys[1], n64 * sizeof(Key)},
              {&ws.bodies[0], n64 * sizeof(std::uint32_t)},
              {&ws.bodies[1], n64 * sizeof(std::uint32_t)},
              {&ws.body_blocks, r.body_block_words * sizeof(std::uint32_t)},
              {&ws.base, n64 * sizeof(Key)},  // type passes: base keys; else the lowest cells' keys
              {&ws.counters, sizeof(cuda::Counters)}},
             "pack");
  if (!r.device_in && r.job.ellipsoids > 0)  // host shape rows, uploaded with the bodies (upload_stage)
    ws.reserve({{&ws.shape_kind, n64 * sizeof(Shape)},
                {&ws.shape_semi, n64 * sizeof(Vec3<double>)},
                {&ws.shape_orient, n64 * sizeof(Quat<double>)}},
               "pack");
}

// spheres_only: the spheres in input order alone (the reuse of candidates kept with a skin needs no
// cells, renumbering or entry totals).
template <class Real, class Key, class Narrow>
void pack_stage(RunState<Real, Key, Narrow>& r, bool spheres_only) {
  using cuda::kBlock;
  Workspace& ws = r.ws;
  const std::uint32_t n = r.n, nb = r.nb;
  cudaStream_t st = r.st;
  r.d_spheres = ws.spheres.span_as<Sphere<Real>>(n).data();
  r.d_cell_spheres = ws.cell_spheres.span_as<Sphere<Real>>(n).data();
  r.d_perm = ws.perm.span_as<std::uint32_t>(n).data();
  r.d_ctrl = ws.ctrl.span_as<std::uint8_t>(n).data();
  r.d_body_totals = ws.body_blocks.span_as<std::uint32_t>(r.body_block_words).data();
  r.d_body_offsets = r.d_body_totals + nb;
  r.d_type_totals = r.d_body_totals + nb;
  r.d_type_offsets = r.d_type_totals + 8 * std::size_t(nb);
  r.d_base = r.type_passes ? ws.base.span_as<Key>(n).data() : nullptr;
  r.d_lo_key = r.type_passes ? nullptr : ws.base.span_as<Key>(n).data();
  r.d_counters = ws.counters.span_as<cuda::Counters>(1).data();
  CG_CUDA_CHECK(cudaMemsetAsync(r.d_counters, 0, sizeof(cuda::Counters), st));
  // The renumbering pays only when the spheres do not stay in L2 anyway (the pair stage's gathers hit
  // it either way): when they outgrow the L2 (Tuning::renumber forces it). Scenes of the centre cut pay
  // it for the cut shapes too (their gather into cell order): with float spheres (fp32, mixed) it then
  // costs more than the pair stage's locality saves, with fp64's 32-byte spheres less (BENCHMARKS.md §3)
  // — but for a skin's build (cut_skin), whose cells are the inflated bounding spheres' and whose walk
  // tests more pairs a body than the shapes' boxes give a fresh call (§34).
  // Without it the bodies keep their input order (no result changes).
  const bool worth = r.n64 * sizeof(Sphere<Real>) > r.l2_bytes &&
                     (r.filter != CandidateFilter::centre_cut || sizeof(Real) == 8 || r.cut_skin > 0);
  const bool renumber = !spheres_only && tuned(r.tuning.renumber, worth);
  r.renumbered = renumber;
  // input order is cell order and no skin inflates them: the pair stage reads the spheres themselves
  if (!renumber && r.job.inflation == 0) r.d_cell_spheres = r.d_spheres;
  r.d_cell_cut = nullptr;
  if (r.filter == CandidateFilter::centre_cut && !spheres_only) {  // the pair stage's cut shapes
    ws.reserve({{&ws.cell_cut, r.n64 * sizeof(CutShape)}}, "pack");
    r.d_cell_cut = ws.cell_cut.span_as<CutShape>(n).data();
  }
  // Where the bodies keep their order reorder packs them (spheres and shapes) in its one pass; else
  // pack and pack_shapes do, and reorder gathers them into cell order.
  const bool pack_here = !renumber && !spheres_only;
  // scenes with ellipsoids: the shape rows, their packed shapes (and the device rows' check; shapes.cuh)
  const cuda::ShapeInput<Narrow> shape_in = shapes_stage(r, !pack_here);
  // Renumbering sort of the bodies by z layer of cells (locality only; see home_layer_key): at most
  // 8 key bits, one radix pass.
  const int z_bits = std::max(1, bits_for(std::uint64_t(r.g.dims[2])));
  const int layer_shift = std::max(0, z_bits - 8);
  const int home_bits = z_bits - layer_shift;
  cub::DoubleBuffer<Key> home_key = ws.home_keys<Key>(n);
  cub::DoubleBuffer<std::uint32_t> home_index = ws.home_index(n);
  if (!pack_here) {
    cuda::pack_kernel<Real, Key>
        <<<nb, kBlock, 0, st>>>(r.d_pos, r.d_rad, r.d_packed_in, n, r.origin, r.g, r.d_spheres, layer_shift,
                                renumber ? home_key.Current() : nullptr, home_index.Current(), r.d_counters);
    CG_CUDA_CHECK_LAUNCH("pack");
  }
  if (spheres_only) {
    r.events.mark(EngineStage::pack, st);
    return;
  }
  if (renumber)
    cub_run(ws, "pack", [&](void* t, std::size_t& b) {
      return cub::DeviceRadixSort::SortPairs(t, b, home_key, home_index, int(n), 0, home_bits, st);
    });
  auto reorder = [&](auto kernel, const std::uint32_t* sorted, const cuda::PackInput<Narrow>& in) {
    kernel<<<nb, kBlock, 0, st>>>(
        r.d_spheres, n, r.g, sorted, r.d_cell_spheres == r.d_spheres ? nullptr : r.d_cell_spheres, r.d_ctrl,
        r.d_perm, r.d_body_totals, r.d_counters, r.d_base, r.type_passes ? r.d_type_totals : nullptr,
        r.d_report, static_cast<Real>(r.job.inflation), r.d_shapes, r.d_cell_cut, r.box_cut() != nullptr,
        r.d_lo_key, in);
  };
  if (pack_here)
    reorder(cuda::reorder_kernel<Real, Key, Narrow, true>, nullptr,
            cuda::PackInput<Narrow>{r.d_pos, r.d_rad, r.origin, shape_in, r.d_packed_in});
  else
    reorder(cuda::reorder_kernel<Real, Key, Narrow, false>, home_index.Current(), cuda::PackInput<Narrow>{});
  CG_CUDA_CHECK_LAUNCH("reorder");
  r.events.mark(EngineStage::pack, st);
}

// After the counters were read: the InputError of compute_bounds for an invalid body, and the device
// rows' shape check (pack_shapes).
template <class Real, class Key, class Narrow>
void check_packed(RunState<Real, Key, Narrow>& r) {
  if (r.h_counters->bad) {
    const std::uint64_t i = r.n64 - r.h_counters->bad;
    const std::int64_t id = !r.device_in && !r.job.bodies.id.empty() ? r.job.bodies.id[i] : std::int64_t(i);
    throw_bad_body(r.d_pos, r.d_rad, i, id);
  }
  check_shapes_read(r);
}

// The scan of the block totals (timed with the entries stage) and the host's read of the entries
// total and the bad-data status (throws the InputError of compute_bounds for an invalid body).
template <class Real, class Key, class Narrow>
void scan_body_blocks(RunState<Real, Key, Narrow>& r) {
  cudaStream_t st = r.st;
  const int nb = int(r.nb);
  if (r.type_passes) {
    cub_run(r.ws, "entries", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, r.d_type_totals, r.d_type_offsets, 8 * nb, st);
    });
  } else {
    cub_run(r.ws, "entries", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::ExclusiveSum(t, b, r.d_body_totals, r.d_body_offsets, nb, st);
    });
  }
  r.read_counters();  // host needs the entries total and the status
  check_packed(r);
  r.n_entries = r.h_counters->entries;
  r.stats.entries = r.n_entries;
  if (!r.type_passes && r.n_entries >= (std::uint64_t(1) << 31)) {
    std::ostringstream m;
    m << r.n_entries << " (cell, body) entries exceed the 2^31 - 1 items one CUB sort handles; "
      << "use fewer bodies per rank (more MPI ranks)";
    throw ResourceError(m.str());
  }
  std::copy(r.h_counters->type_entries, r.h_counters->type_entries + 8, r.type_entries);
}

}  // namespace cg::detail
