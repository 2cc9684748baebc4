#pragma once
// CUDA stage entries: (cell key, body) of the cell-ordered bodies in body order, from the scanned
// block totals of pack (the type-pass path's per-type fill is here too; type_passes.cuh runs it).
#include "cuda/common.cuh"
#include "cuda/run_state.cuh"

namespace cg::cuda {

// entries of one cell type (type-pass path): (super-cell index, body) of the cell-ordered bodies that
// overlap a cell of type `type`, body-ascending, at block_offset[blockIdx.x] - start + the body's rank
// among its block's such bodies (same block layout as reorder_kernel). The key is the lin part of
// cell_key (type bits dropped): base + one super-cell step along each axis where lo is odd and the
// type's parity even (the cell lo + 1 then starts the next super-cell).
template <class Key>
__global__ void __launch_bounds__(kBlock)
    fill_type_entries_kernel(const std::uint8_t* __restrict__ ctrl, const Key* __restrict__ base,
                             std::uint32_t n, std::uint32_t type, Key step_y, Key step_z,
                             const std::uint32_t* __restrict__ block_offset, std::uint32_t start,
                             Key* __restrict__ keys, std::uint32_t* __restrict__ body) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  const std::uint32_t j = blockIdx.x * kBlock + threadIdx.x;
  std::uint32_t has = 0;
  Key key{};
  if (j < n) {
    const std::uint32_t cb = ctrl[j];
    if (has_type(cb, type)) {
      has = 1;
      const std::uint32_t d = cb & ~type & 7u;
      key = base[j] + Key(d & 1u) + ((d & 2u) ? step_y : Key(0)) + ((d & 4u) ? step_z : Key(0));
    }
  }
  std::uint32_t rank;
  Scan(tmp).ExclusiveSum(has, rank);
  if (has) {
    const std::uint32_t w = block_offset[blockIdx.x] - start + rank;
    keys[w] = key;
    body[w] = j;
  }
}

// entries: (cell key, body) of the cell-ordered bodies, body-ascending; body j's entries start at
// its block's scanned total plus its exclusive rank in the block (same block layout as
// reorder_kernel). Each body's cells from the key of its lowest cell and its control byte, both
// written by reorder (spilled_cell_key: the keys of body_cell_key, 5 bytes a body read instead of its
// sphere and, in centre-cut scenes, its cut shape). Staged in shared memory so that the block writes
// its entries coalesced.
template <class Key, class Real>
__global__ void __launch_bounds__(kBlock)
    fill_entries_kernel(const Key* __restrict__ lo_key, const std::uint8_t* __restrict__ ctrl,
                        std::uint32_t n, GridParams<Real> g, const std::uint32_t* __restrict__ block_offset,
                        Key* __restrict__ keys, std::uint32_t* __restrict__ body) {
  using Scan = cub::BlockScan<std::uint32_t, kBlock>;
  __shared__ typename Scan::TempStorage tmp;
  __shared__ Key s_keys[8 * kBlock];
  __shared__ std::uint32_t s_body[8 * kBlock];
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  Key k0{};
  std::uint32_t cb = 0, count = 0;
  if (i < n) {
    k0 = lo_key[i];
    cb = ctrl[i];
    count = 1u << popcount3((cb >> 3) & 7u);  // entry_count: one cell, or two per spilled axis
  }
  std::uint32_t rank, total;
  Scan(tmp).ExclusiveSum(count, rank, total);
  for (std::uint32_t m = 0; m < count; ++m) {
    s_keys[rank + m] = spilled_cell_key<Key>(k0, cb, m, g);
    s_body[rank + m] = i;
  }
  __syncthreads();
  const std::uint64_t base = block_offset[blockIdx.x];
  for (std::uint32_t t = threadIdx.x; t < total; t += kBlock) {
    keys[base + t] = s_keys[t];
    body[base + t] = s_body[t];
  }
}

}  // namespace cg::cuda

namespace cg::detail {

template <class Real, class Key, class Narrow>
void entries_stage(RunState<Real, Key, Narrow>& r) {
  Workspace& ws = r.ws;
  const auto ne = static_cast<std::uint32_t>(r.n_entries);
  const std::uint32_t neb = cuda::blocks_for(ne);
  ws.reserve({{&ws.keys[0], ne * sizeof(Key)},
              {&ws.keys[1], ne * sizeof(Key)},
              {&ws.bodies[0], ne * sizeof(std::uint32_t)},
              {&ws.bodies[1], ne * sizeof(std::uint32_t)},
              {&ws.entry_blocks, 2 * std::size_t(neb) * sizeof(std::uint32_t)}},
             "entries");
  r.keys = ws.entry_keys<Key>(ne);
  r.body = ws.entry_bodies(ne);
  cuda::fill_entries_kernel<Key><<<r.nb, cuda::kBlock, 0, r.st>>>(
      r.d_lo_key, r.d_ctrl, r.n, r.g, r.d_body_offsets, r.keys.Current(), r.body.Current());
  CG_CUDA_CHECK_LAUNCH("fill_entries");
  r.events.mark(EngineStage::entries, r.st);
}

}  // namespace cg::detail
