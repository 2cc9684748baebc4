#pragma once
// The opt-in type-pass path (Tuning::type_passes, for memory-bound scenes): the entries, sort and
// pairs stages as Le Grand's 8 passes by cell type. Each body has at most one entry of a given cell
// type, so pass t holds n_t <= n entries, keyed by the super-cell index alone (half_bits bits: a radix
// pass fewer than key_bits where that crosses a digit), in the same four entry buffers as the
// renumbering sort. Pass t: fill (compaction of the bodies having a type-t cell) → sort →
// count_pairs with the pass's type (the exactly-once rule unchanged: test_in_cell with type t). All
// passes write their pairs at the one cursor c->pairs into ws.pairs (cap pairs); when the total
// exceeds cap, ws.pairs grows to the total and the passes run again (counters reset), writing them
// all. The stage times are those of the passes summed.
#include <cub/device/device_radix_sort.cuh>

#include "cuda/entries.cuh"
#include "cuda/pairs.cuh"

namespace cg::detail {

template <class Real, class Key, class Narrow>
void type_pass_stages(RunState<Real, Key, Narrow>& r) {
  using cuda::kBlock;
  Workspace& ws = r.ws;
  StageEvents& ev_all = r.events;
  cudaStream_t st = r.st;
  const std::uint32_t n = r.n, nb = r.nb;
  const GridParams<Real> g = r.g;
  std::uint32_t n_max = 0;
  std::uint64_t start[8];
  for (std::uint64_t t = 0, s = 0; t < 8; ++t) {
    start[t] = s;  // used modulo 2^32, as the u32 scan of the block totals
    s += r.type_entries[t];
    n_max = std::max(n_max, static_cast<std::uint32_t>(r.type_entries[t]));
  }
  const std::uint32_t neb_max = cuda::blocks_for(n_max);
  cub::DoubleBuffer<Key>& keys = r.keys;
  cub::DoubleBuffer<std::uint32_t>& body = r.body;
  std::uint64_t cap = std::max<std::uint64_t>(r.n64 / 2, ws.pairs.bytes() / (4 * sizeof(std::uint32_t)));
  ws.reserve({{&ws.entry_blocks, std::size_t(neb_max) * sizeof(std::uint32_t)},
              {&ws.pairs, 4 * std::size_t(cap) * sizeof(std::uint32_t)}},
             "entries");
  std::uint32_t* d_entry_totals = ws.entry_blocks.span_as<std::uint32_t>(neb_max).data();
  const Key step_y = Key(g.half[0]), step_z = Key(g.half[0]) * Key(g.half[1]);
  double pass_ms[3] = {0, 0, 0};  // entries, sort, pairs
  auto run_passes = [&](std::uint32_t* store, std::uint64_t cap_pairs) {
    CG_CUDA_CHECK(cudaEventRecord(ev_all.pass_event(0), st));
    for (std::uint32_t t = 0; t < 8; ++t) {
      const auto nt = static_cast<std::uint32_t>(r.type_entries[t]);
      const int ev = 1 + 3 * int(t);
      keys = ws.entry_keys<Key>(n);
      body = ws.entry_bodies(n);
      if (nt > 0) {
        cuda::fill_type_entries_kernel<Key><<<nb, kBlock, 0, st>>>(
            r.d_ctrl, r.d_base, n, t, step_y, step_z, r.d_type_offsets + std::size_t(t) * nb,
            static_cast<std::uint32_t>(start[t]), keys.Current(), body.Current());
        CG_CUDA_CHECK_LAUNCH("fill_type_entries");
      }
      CG_CUDA_CHECK(cudaEventRecord(ev_all.pass_event(ev), st));
      if (nt > 1 && g.half_bits > 0) {
        cub_run(ws, "sort", [&](void* tmp, std::size_t& b) {
          return cub::DeviceRadixSort::SortPairs(tmp, b, keys, body, int(nt), 0, g.half_bits, st);
        });
      }
      CG_CUDA_CHECK(cudaEventRecord(ev_all.pass_event(ev + 1), st));
      if (nt > 0) {
        launch_count_pairs(r, cuda::blocks_for(nt), keys.Current(), body.Current(), nt, r.d_ctrl,
                           r.d_cell_spheres, r.pair_perm(), r.d_report, g.half_bits, t,
                           Workspace::pair_masks(keys), d_entry_totals, r.d_counters, store,
                           store + cap_pairs, cap_pairs, false);
      }
      CG_CUDA_CHECK(cudaEventRecord(ev_all.pass_event(ev + 2), st));
    }
    r.read_counters();  // host needs the pairs total
    cudaEvent_t prev = ev_all.pass_event(0);
    for (int t = 0; t < 8; ++t)
      for (int s = 0; s < 3; ++s) {
        float ms = 0;
        CG_CUDA_CHECK(cudaEventElapsedTime(&ms, prev, ev_all.pass_event(1 + 3 * t + s)));
        pass_ms[s] += ms;
        prev = ev_all.pass_event(1 + 3 * t + s);
      }
  };
  std::uint32_t* d_pair_store = ws.pairs.span_as<std::uint32_t>(4 * std::size_t(cap)).data();
  run_passes(d_pair_store, cap);
  {
    float ms = 0;  // the scan and the host sync after pack, as in the single-sort path's entries stage
    CG_CUDA_CHECK(cudaEventElapsedTime(&ms, ev_all.end_event(EngineStage::pack), ev_all.pass_event(0)));
    pass_ms[0] += ms;
  }
  if (r.h_counters->pairs > cap) {
    check_pairs(r.h_counters->pairs);
    cap = r.h_counters->pairs;
    ws.reserve({{&ws.pairs, 4 * std::size_t(cap) * sizeof(std::uint32_t)}}, "pairs");
    cap = std::max<std::uint64_t>(cap, ws.pairs.bytes() / (4 * sizeof(std::uint32_t)));
    d_pair_store = ws.pairs.span_as<std::uint32_t>(4 * std::size_t(cap)).data();
    CG_CUDA_CHECK(cudaMemsetAsync(r.d_counters, 0, sizeof(cuda::Counters), st));  // pairs and tests again
    run_passes(d_pair_store, cap);
  }
  const std::uint64_t n_pairs = r.h_counters->pairs;
  r.stats.pair_tests = r.h_counters->tests;
  check_pairs(n_pairs);
  r.np = static_cast<std::uint32_t>(n_pairs);
  ws.reserve({{&ws.out, r.out_bytes_for(r.np)}}, "pairs");
  r.pair_a = cub::DoubleBuffer<std::uint32_t>(d_pair_store, d_pair_store + 2 * cap);
  r.pair_b = cub::DoubleBuffer<std::uint32_t>(d_pair_store + cap, d_pair_store + 3 * cap);
  // Stage times: the passes' fill / sort / count times, summed (the marks only close the chain).
  ev_all.mark(EngineStage::entries, st);
  ev_all.mark(EngineStage::sort, st);
  ev_all.mark(EngineStage::pairs, st);
  const EngineStage timed[3] = {EngineStage::entries, EngineStage::sort, EngineStage::pairs};
  for (int s = 0; s < 3; ++s) ev_all.set_time(timed[s], pass_ms[s]);
  ev_all.add_tail(EngineStage::pairs);  // + the host sync after the last pass, to the pairs mark
}

}  // namespace cg::detail
