#pragma once
// history: the contact identity of one call on the device (EngineOptions::history, device bodies;
// core/history.hpp states the rule). Each contact row's key (the global ids of its bodies, or its
// local ids) is searched in the previous step's sorted keys (ws.hist_keys[hist_current], hist_count
// rows); the position gives the row's age and previous_row, and the row's key and age become the next
// step's history (the other hist buffer; the two swap). The search (Tuning::history_search): one
// kernel searching from the row's own place among the keys (near, the default: lower_bound_key_near),
// one kernel searching all the keys (kernel), or Thrust's vectorised lower_bound followed by one kernel
// that turns positions into the fields (thrust): the same fields every way (BENCHMARKS.md compares
// them).
#include <thrust/binary_search.h>
#include <thrust/execution_policy.h>
#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include "core/history.hpp"
#include "cuda/run_state.cuh"
#include "cuda/thrust_alloc.cuh"

namespace cg::cuda {

// The key of contact row i (DEVICE arrays).
struct RowKey {
  const std::int64_t* a;
  const std::int64_t* b;
  const std::int64_t* global;  // null: the rows' ids are the keys
  __host__ __device__ PairKey operator()(std::uint32_t i) const { return pair_key(a[i], b[i], global); }
};

// The previous step (read) and the one being made (written), DEVICE.
struct HistorySteps {
  const PairKey* old_keys;
  const std::int64_t* old_age;
  unsigned long long old_count;
  PairKey* new_keys;
  std::int64_t* new_age;
};

// How history_kernel finds a row's lower bound: read from previous_row[i] (where Thrust left it),
// searched over all the keys, or searched from the row's own place (i scaled by the steps' row counts).
enum class RowSearch { given, all, near };

// Row i's fields from its lower bound, and its key and age into the next step.
template <RowSearch kSearch>
__global__ void history_kernel(RowKey key_of, std::uint32_t rows, HistorySteps h, std::int64_t* previous_row,
                               std::int64_t* age) {
  const std::uint32_t i = blockIdx.x * kBlock + threadIdx.x;
  if (i >= rows) return;
  const PairKey key = key_of(i);
  const std::size_t m = static_cast<std::size_t>(h.old_count);
  std::size_t p = 0;
  if constexpr (kSearch == RowSearch::given)
    p = static_cast<std::size_t>(previous_row[i]);
  else if constexpr (kSearch == RowSearch::all)
    p = lower_bound_key(h.old_keys, m, key);
  else
    p = lower_bound_key_near(h.old_keys, m, key, std::size_t((std::uint64_t(i) * m) / rows));
  const RowHistory r = history_of(h.old_keys, h.old_age, m, p, key);
  previous_row[i] = r.previous_row;
  age[i] = r.age;
  h.new_keys[i] = key;
  h.new_age[i] = r.age;
}

}  // namespace cg::cuda

namespace cg::detail {

// The history stage: after narrow, before download (the rows' count must be known on the host: a
// rejecting narrow that leaves its rows on the device is waited for here).
template <class Real, class Key, class Narrow>
void history_stage(RunState<Real, Key, Narrow>& r, ThrustAllocator& alloc) {
  if (!r.history) return;
  if (r.rows_pending) {  // the row count of a rejecting narrow with device output
    CG_CUDA_CHECK(cudaStreamSynchronize(r.st));
    r.take_narrow_counters();
  }
  Workspace& ws = r.ws;
  const std::uint32_t k = r.n_rows;
  const int next = 1 - ws.hist_current;
  ws.reserve({{&ws.hist_keys[next], k * sizeof(PairKey)}, {&ws.hist_age[next], k * sizeof(std::int64_t)}},
             "history");
  const cuda::HistorySteps h{ws.hist_keys[ws.hist_current].template span_as<PairKey>(0).data(),
                             ws.hist_age[ws.hist_current].template span_as<std::int64_t>(0).data(),
                             ws.hist_count, ws.hist_keys[next].template span_as<PairKey>(k).data(),
                             ws.hist_age[next].template span_as<std::int64_t>(k).data()};
  if (k > 0) {
    const cuda::RowKey key_of{r.cp.id_a, r.cp.id_b, r.job.device_bodies ? r.job.device_bodies->id : nullptr};
    if (r.tuning.history_search == HistorySearch::thrust) {
      const auto keys = thrust::make_transform_iterator(thrust::counting_iterator<std::uint32_t>(0), key_of);
      thrust::lower_bound(thrust::cuda::par_nosync(alloc).on(r.st), h.old_keys, h.old_keys + h.old_count,
                          keys, keys + k, r.cp.previous_row);
      cuda::history_kernel<cuda::RowSearch::given>
          <<<cuda::blocks_for(k), cuda::kBlock, 0, r.st>>>(key_of, k, h, r.cp.previous_row, r.cp.age);
    } else if (r.tuning.history_search == HistorySearch::kernel) {
      cuda::history_kernel<cuda::RowSearch::all>
          <<<cuda::blocks_for(k), cuda::kBlock, 0, r.st>>>(key_of, k, h, r.cp.previous_row, r.cp.age);
    } else {
      cuda::history_kernel<cuda::RowSearch::near>
          <<<cuda::blocks_for(k), cuda::kBlock, 0, r.st>>>(key_of, k, h, r.cp.previous_row, r.cp.age);
    }
    CG_CUDA_CHECK_LAUNCH("history");
  }
  ws.hist_current = next;
  ws.hist_count = k;
  r.events.mark(EngineStage::history, r.st);
}

}  // namespace cg::detail
