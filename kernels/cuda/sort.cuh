#pragma once
// CUDA stage sort: the entries by cell key, cub::DeviceRadixSort::SortPairs over bits [0, key_bits)
// (CUB's radix sort: measured faster than the alternatives, BENCHMARKS.md §11).
#include <cub/device/device_radix_sort.cuh>

#include "cuda/run_state.cuh"

namespace cg::detail {

template <class Real, class Key, class Narrow>
void sort_stage(RunState<Real, Key, Narrow>& r) {
  const int ne = int(r.n_entries), key_bits = r.job.plan.key_bits;
  cub_run(r.ws, "sort", [&](void* t, std::size_t& b) {
    return cub::DeviceRadixSort::SortPairs(t, b, r.keys, r.body, ne, 0, key_bits, r.st);
  });
  r.events.mark(EngineStage::sort, r.st);
}

}  // namespace cg::detail
