#pragma once
// CUDA: the pair stage's estimate (pair_estimate.hpp) from the sorted entry keys, after the sort and
// before the pair stage, whose time it counts in. An inclusive max-scan of "e where a cell's run of
// entries starts" gives each entry the first entry of its cell (written into the keys' dead
// alternate buffer, which the pair stage overwrites with its masks afterwards); a reduction of
// e − start(e) (the earlier entries of e's cell) and of the run lengths gives Σ m·(m − 1)/2 and the
// fullest cell. One wait for the result: the host hands it to check_pair_estimate, which may refuse
// the scene before the pair stage runs. (The type passes, a measurement knob, make no estimate.)
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/device/device_reduce.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda/functional>

#include "cuda/run_state.cuh"
#include "pair_estimate.hpp"

namespace cg::cuda {

// e where entry e starts its cell's run, else 0 (so a max-scan gives each entry its run's start).
template <class Key>
struct RunStart {
  const Key* keys;
  __host__ __device__ std::uint32_t operator()(std::uint32_t e) const {
    return e == 0 || keys[e] != keys[e - 1] ? e : 0u;
  }
};

// Entry e's share: its earlier entries in the cell (pairs it closes), and its place in the cell + 1.
struct EarlierInCell {
  const std::uint32_t* start;
  __host__ __device__ CellWork operator()(std::uint32_t e) const {
    const unsigned long long before = e - start[e];
    return {before, before + 1};
  }
};

struct AddCellWork {
  __host__ __device__ CellWork operator()(const CellWork& a, const CellWork& b) const {
    return {a.tests + b.tests, a.largest > b.largest ? a.largest : b.largest};
  }
};

}  // namespace cg::cuda

namespace cg::detail {

// The pair tests and the largest count of `work` (one CellWork for each of its `count` items), reduced
// on the device and read back into `e` (one wait): the grid's estimate and the sweep's share it.
template <class Real, class Key, class Narrow, class Work>
void add_cell_work(RunState<Real, Key, Narrow>& r, Work work, std::uint32_t count, PairEstimate& e) {
  cub_run(r.ws, "pairs", [&](void* t, std::size_t& b) {
    return cub::DeviceReduce::Reduce(t, b, work, &r.d_counters->cell_work, int(count), cuda::AddCellWork{},
                                     cuda::CellWork{0, 0}, r.st);
  });
  r.read_counters();
  e.tests = r.h_counters->cell_work.tests;
  e.largest = r.h_counters->cell_work.largest;
}

// The grid's estimate (Σ m·(m − 1)/2 over the cells of the sorted keys, the fullest cell), unchecked.
template <class Real, class Key, class Narrow>
PairEstimate cell_estimate(RunState<Real, Key, Narrow>& r) {
  const auto ne = static_cast<std::uint32_t>(r.n_entries);
  PairEstimate e{0, r.n64, r.n_entries, r.n_entries > 0 ? 1u : 0u, kDevicePairTestsPerSecond};
  if (ne > 1) {
    std::uint32_t* d_start = Workspace::pair_masks(r.keys);
    const auto starts = thrust::make_transform_iterator(thrust::counting_iterator<std::uint32_t>(0),
                                                        cuda::RunStart<Key>{r.keys.Current()});
    cub_run(r.ws, "pairs", [&](void* t, std::size_t& b) {
      return cub::DeviceScan::InclusiveScan(t, b, starts, d_start, ::cuda::maximum<std::uint32_t>{}, int(ne),
                                            r.st);
    });
    add_cell_work(r,
                  thrust::make_transform_iterator(thrust::counting_iterator<std::uint32_t>(0),
                                                  cuda::EarlierInCell{d_start}),
                  ne, e);
  }
  return e;
}

// The estimate handed on and checked (may refuse the scene); whether the pair stage reports progress.
template <class Real, class Key, class Narrow>
void check_estimate(RunState<Real, Key, Narrow>& r, const PairEstimate& e) {
  check_pair_estimate(e, r.job.pair_limits);
  r.pair_progress = follows_progress(e, r.job.pair_limits);
}

template <class Real, class Key, class Narrow>
void estimate_stage(RunState<Real, Key, Narrow>& r) {
  check_estimate(r, cell_estimate(r));
}

}  // namespace cg::detail
