// The history stage on the host (core/history.hpp): one binary search per row of the new step in the
// previous step's keys, OpenMP over the rows; then the new keys and ages become the previous step.
#include "history.hpp"

#include <omp.h>

#include <algorithm>

#include "errors.hpp"
#include "host/stages.hpp"

namespace cg {

template <class Real>
void step_history(Contacts<Real>& c, ContactHistory& previous, std::span<const std::int64_t> global_ids,
                  int threads) {
  const std::size_t k = c.size(), m = previous.size();
  if (c.id_b.size() != k) throw Error("step_history: the contact arrays differ in length");
  c.age.resize(k);
  c.previous_row.resize(k);
  c.history = true;
  std::vector<PairKey> keys(k);
  const std::int64_t* global = global_ids.empty() ? nullptr : global_ids.data();
  const PairKey* old_keys = previous.keys.data();
  const std::int64_t* old_age = previous.age.data();
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  const std::ptrdiff_t rows = static_cast<std::ptrdiff_t>(k);
#pragma omp parallel for num_threads(nt) schedule(static) if (k > detail::host::k_parallel_min)
  for (std::ptrdiff_t i = 0; i < rows; ++i) {
    const PairKey key = pair_key(c.id_a[i], c.id_b[i], global);
    const RowHistory h = history_of(old_keys, old_age, m, lower_bound_key(old_keys, m, key), key);
    c.age[i] = h.age;
    c.previous_row[i] = h.previous_row;
    keys[i] = key;
  }
  previous.keys = std::move(keys);
  previous.age.assign(c.age.begin(), c.age.end());
}

template void step_history(Contacts<float>&, ContactHistory&, std::span<const std::int64_t>, int);
template void step_history(Contacts<double>&, ContactHistory&, std::span<const std::int64_t>, int);

}  // namespace cg
