#pragma once
// The CUDA backend's persistent DEVICE workspace: named buffers that grow geometrically and never
// shrink (a caller that detects many frames allocates nothing after the first), the memory check of
// their growth, and the named views of the buffers that a later stage reuses once an earlier one is
// done with them.
//
// Buffers and who uses them (n bodies, ne entries, nb = blocks of n, neb = blocks of ne, np pairs):
//   pos, rad               upload → narrow     host-array path: the input copied to the device; the
//                                              narrow stage reads the world doubles by body index
//                                              (fp64, mixed, fp32's fp64 rows): never aliased.
//                                              fp32 spheres: pos holds the host-packed 16-byte
//                                              spheres (upload → pack), then, where rows need
//                                              them, the doubles (transfer.cuh: narrow_fp64_rows)
//   report                 upload → pack       host-array path: the report mask
//   spheres                pack → narrow       Real spheres in input order (narrow: fp32 only)
//   cell_spheres, perm,    pack → pairs        spheres, input index and control byte in cell order
//   ctrl
//   body_blocks            pack → entries      per block of bodies: entry totals, their scan (2 nb);
//                                              type passes: entry totals, [8][nb] type totals, scan
//   base                   pack → entries/     single sort: the key of each body's lowest cell (entries);
//                          pairs               type passes: super-cell index per body (pairs)
//   keys[2], bodies[2]     entries → pairs     the entries, double-buffered for the CUB sort
//   entry_blocks           pairs               per block of entries: pair totals and their scan
//   pairs                  pairs → narrow      candidate pairs when they are not in the entries'
//                                              dead buffer (see below); type passes, sweep and
//                                              brute: always
//   out                    narrow → download   the contact rows (ContactPtrs, 16-byte aligned fields)
//   temp                   any CUB call        CUB temporary storage (cub_run)
//   counters, partials     every stage         Counters of the call; bounds partials
//   shape_kind, shape_semi, upload → narrow    scenes with ellipsoids, host-array path: the shape rows
//   shape_orient                               (narrow: fp32's pairs solved in fp64 read semi, orient)
//   shapes                 pack → narrow       scenes with ellipsoids: PackedShape<Narrow> per body, input
//                                              order
//   cell_cut               pack → pairs        CandidateFilter::centre_cut: CutShape per body, cell
//                                              order (core/centre_cut.hpp)
//   normals                narrow              scenes with ellipsoids: the minimiser kept per candidate
//                                              (triage / hard pass → fill) and the hard count
//   narrow_list            narrow              scenes with ellipsoids: the settle pass's list of
//                                              candidates (the other lists are in dead pair buffers),
//                                              then fp32's pairs solved in fp64 (their rows' fill)
//   narrow_carry           narrow              scenes with ellipsoids: beside the settle pass's list, each
//                                              pair's first start (FirstStart), kept by the first pass
//   res_pos, res_rad,      between calls       resident bodies (Engine::set_resident); res_shape,
//   res_report, res_shape,                     res_semi, res_orient: their shape rows (empty for a
//   res_semi, res_orient                       sphere-only set); owned across calls, never aliased
//   broad_counts           pairs               BroadPhase levels, sweep, brute (broad.cuh): per item
//                                              (body, or tile pair) its candidates, then their scan
//   broad_pairs            pairs → narrow      levels: the candidates of one level and across levels
//                                              together (a, b and the order sort's second copies);
//                          sort → pairs        sweep: the spheres in the sweep's order
//   kept_pairs, ref_pos,   between calls       EngineOptions::skin: the kept candidate list (a then b,
//   ref_rad, ref_report                        kept_count each, kept_stride apart; a cell-order
//                                              build's pair stage writes it, cuda/pairs.cuh) and the
//                                              bodies' state it was built from (cuda/skin.cuh);
//                                              owned across calls, never aliased
//   ref_kind, ref_semi,    between calls       a kept list cut by the centre line (cuda/skin.cuh):
//   ref_orient                                 the shape rows it was built from; owned, never aliased
//   kept_perm, kept_inv    between calls       the kept list of a cell-order skin (cuda/cell_order.cuh):
//                                              the cell order's input indices and each input index's
//                                              cell place; owned, never aliased
//   canon_keys[2],         download            a cell-order call's rows sorted by (a, b) before they
//   canon_index[2],                            come down (cuda/cell_order.cuh: canonical_rows), and
//   canon_field                                one column gathered into that order
//   res_id                 between calls       resident bodies' global ids (the history's keys)
//   res_mark               between calls       the resident centres at Engine::mark_resident (the
//                                              step loop's rebuild check: cuda/resident_extent.cuh)
//   hist_keys[2],          between calls       EngineOptions::history on the device: the previous
//   hist_age[2]                                step's pair keys and ages (hist_current), and the
//                                              step being made (cuda/history.cuh); never aliased
//   row_lists[4]           between calls       Engine::set_row_list's lists (u32 rows; a halo's)
//   row_pack, row_selected a row call          gather/scatter's packed rows; rows_outside's rows
//
// Aliases (a buffer seen under another name once its first use is dead):
//   view                 storage                  when
//   home_keys()          keys[0], keys[1]         pack: the renumbering sort's keys (before entries)
//   home_index()         bodies[0], bodies[1]     pack: the renumbering sort's values
//   pair_masks(keys)     keys.Alternate()         pairs: a contact mask per entry (after the sort)
//   direct_pairs(body)   body.Alternate()         pairs: 4 u32 arrays of ne / 4 candidate pairs
//                                                 (a, b, and the order sort's second copies)
//   a_counts(), a_offsets()  keys[0], keys[1]     order (counting): per body pair count and offset
//   (narrow.cuh)         pair_a / pair_b          narrow (rejecting filter): accept flags (shapes: the
//                        .Alternate()             verdicts) and their scan (shapes: first the list of
//                                                 hard candidates), in the candidates' dead second copies
// Contents do not survive a call, except the resident bodies, the kept candidates and their state,
// and the contact rows of the last call (DeviceContactsView, valid until the next detection).
#include <cub/util_type.cuh>
#include <initializer_list>
#include <optional>
#include <sstream>

#include "cuda/common.cuh"
#include "cuda/device_buffer.cuh"

namespace cg::detail {

using Bytes = cuda::DeviceBuffer<std::byte>;

struct Workspace {
  Bytes pos, rad, report;
  Bytes spheres, cell_spheres, perm, ctrl, body_blocks, base;
  Bytes keys[2], bodies[2];
  Bytes entry_blocks, pairs, out, temp, counters, partials;
  Bytes res_pos, res_rad, res_report, res_shape, res_semi, res_orient;
  Bytes shape_kind, shape_semi, shape_orient, shapes, cell_cut, normals, narrow_list, narrow_carry;
  Bytes kept_pairs, ref_pos, ref_rad, ref_report, ref_kind, ref_semi, ref_orient;
  Bytes kept_perm, kept_inv, canon_keys[2], canon_index[2], canon_field;
  Bytes res_id, hist_keys[2], hist_age[2];
  Bytes res_mark;
  Bytes row_lists[4], row_pack, row_selected;  // Engine's row lists, packed rows, rows_outside's
  Bytes broad_counts, broad_pairs;
  std::size_t res_count = 0;
  bool res_ided = false;       // resident global ids present
  std::size_t hist_count = 0;  // rows of the previous step in hist_keys/hist_age[hist_current]
  int hist_current = 0;
  bool res_reported = false;     // resident report mask present
  bool res_shaped = false;       // resident shape rows present
  std::uint32_t kept_count = 0;  // kept candidate pairs
  std::uint64_t last_pairs = 0;  // the last broad phase's candidate count (a first skin build's room)
  std::size_t kept_stride = 0;   // the kept list's b array starts this many u32 after its a array
  bool kept_reported = false;    // the kept list was built with a report mask
  bool kept_cell_order = false;  // the kept list is in cell order (cuda/cell_order.cuh)
  bool kept_cut = false;         // the kept list is cut by the centre line (its check counts turns)
  bool skin_turning = false;     // a check of a cut list saw a body turn: builds keep the bounding
                                 // spheres from then on (core/skin.hpp: skin_cut_wanted)
  bool rows_cell_order = false;  // the last call's rows are in the kept cell order, not (a, b) order

  int device = 0;                           // for messages
  std::optional<std::size_t> memory_limit;  // Tuning::memory_limit
  std::uint64_t allocations = 0;            // cudaMalloc calls since the counter was reset

  std::uint64_t held_bytes() const {
    std::uint64_t s = 0;
    for (const Bytes* b : {&pos,         &rad,           &report,        &spheres,        &cell_spheres,
                           &perm,        &ctrl,          &body_blocks,   &base,           &keys[0],
                           &keys[1],     &bodies[0],     &bodies[1],     &entry_blocks,   &pairs,
                           &out,         &temp,          &counters,      &partials,       &res_pos,
                           &res_rad,     &res_report,    &res_shape,     &res_semi,       &res_orient,
                           &shape_kind,  &shape_semi,    &shape_orient,  &shapes,         &cell_cut,
                           &normals,     &narrow_list,   &narrow_carry,  &kept_pairs,     &ref_pos,
                           &ref_rad,     &ref_report,    &res_id,        &hist_keys[0],   &hist_keys[1],
                           &hist_age[0], &hist_age[1],   &broad_counts,  &broad_pairs,    &res_mark,
                           &kept_perm,   &canon_keys[0], &canon_keys[1], &canon_index[0], &canon_index[1],
                           &canon_field, &row_lists[0],  &row_lists[1],  &row_lists[2],   &row_lists[3],
                           &row_pack,    &row_selected,  &kept_inv,      &ref_kind,       &ref_semi,
                           &ref_orient})
      s += b->bytes();
    return s;
  }

  struct Request {
    Bytes* buffer;
    std::size_t bytes;
  };
  // Grows the buffers of `reqs` (contents discarded) after checking that the growth fits in the
  // device's free memory: geometric growth where it fits, exact sizes where only those fit, else
  // ResourceError naming the bytes needed and available. Synchronises the device when it allocates.
  void reserve(std::initializer_list<Request> reqs, const char* what) {
    std::size_t grow_geo = 0, grow_exact = 0;
    for (const Request& r : reqs) {
      grow_geo += r.buffer->capacity_for(r.bytes, true) - r.buffer->capacity();
      grow_exact += r.buffer->capacity_for(r.bytes, false) - r.buffer->capacity();
    }
    if (grow_exact == 0) return;
    std::size_t free_b = 0, total_b = 0;
    CG_CUDA_CHECK(cudaMemGetInfo(&free_b, &total_b));
    if (memory_limit) {
      const std::size_t limit = *memory_limit, held = held_bytes();
      free_b = std::min(free_b, limit > held ? limit - held : std::size_t(0));
    }
    const std::size_t margin = std::size_t(64) << 20;  // CUDA context, launch and allocator slack
    // Buffers that grow free their old storage first, so their current capacity is available too.
    std::size_t reclaim = 0;
    for (const Request& r : reqs)
      if (r.bytes > r.buffer->capacity()) reclaim += r.buffer->capacity();
    const std::size_t avail = free_b + reclaim > margin ? free_b + reclaim - margin : 0;
    bool geometric = true;
    if (grow_geo + reclaim > avail) geometric = false;
    if (grow_exact + reclaim > avail) {
      std::ostringstream m;
      m << "device memory: the " << what << " stage needs " << grow_exact << " more bytes (workspace "
        << held_bytes() + grow_exact << " bytes in all) but only " << free_b << " of " << total_b
        << " bytes are free on CUDA device " << device
        << "; use fewer bodies per rank (more MPI ranks) or a smaller scene";
      throw ResourceError(m.str());
    }
    for (const Request& r : reqs)
      if (r.buffer->reserve(r.bytes, geometric)) ++allocations;
  }

  // ---- named views (see the alias table above) ----
  template <class Key>
  cub::DoubleBuffer<Key> home_keys(std::size_t n) {
    return {keys[0].span_as<Key>(n).data(), keys[1].span_as<Key>(n).data()};
  }
  cub::DoubleBuffer<std::uint32_t> home_index(std::size_t n) {
    return {bodies[0].span_as<std::uint32_t>(n).data(), bodies[1].span_as<std::uint32_t>(n).data()};
  }
  template <class Key>
  cub::DoubleBuffer<Key> entry_keys(std::size_t ne) {
    return {keys[0].span_as<Key>(ne).data(), keys[1].span_as<Key>(ne).data()};
  }
  cub::DoubleBuffer<std::uint32_t> entry_bodies(std::size_t ne) {
    return {bodies[0].span_as<std::uint32_t>(ne).data(), bodies[1].span_as<std::uint32_t>(ne).data()};
  }
  template <class Key>
  static std::uint32_t* pair_masks(cub::DoubleBuffer<Key> sorted_keys) {
    return reinterpret_cast<std::uint32_t*>(sorted_keys.Alternate());
  }
  static std::uint32_t* direct_pairs(cub::DoubleBuffer<std::uint32_t> sorted_bodies) {
    return sorted_bodies.Alternate();
  }
  std::uint32_t* a_counts(std::size_t n) { return keys[0].span_as<std::uint32_t>(n).data(); }
  std::uint32_t* a_offsets(std::size_t n) { return keys[1].span_as<std::uint32_t>(n).data(); }
};

// CUB's two-phase calls, wrapped once: `call(temp, bytes)` is queried with temp == nullptr, the
// workspace's temp grows to the answer (memory-checked as `what`), then the call runs. The radix sorts
// stay CUB's (cub::DeviceRadixSort over begin_bit..end_bit with double buffers): measured faster than
// the alternatives for the entry and pair sorts (BENCHMARKS.md §11).
template <class F>
std::size_t cub_temp_bytes(F&& call) {
  std::size_t bytes = 0;
  CG_CUDA_CHECK(call(nullptr, bytes));
  return bytes;
}
template <class F>
void cub_run(Workspace& ws, const char* what, F&& call) {
  std::size_t bytes = cub_temp_bytes(call);
  ws.reserve({{&ws.temp, bytes}}, what);
  CG_CUDA_CHECK(call(ws.temp.data(), bytes));
}

}  // namespace cg::detail
